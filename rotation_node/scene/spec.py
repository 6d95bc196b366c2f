"""
Scene files: load a YAML scene and validate it into frozen dataclasses.

A scene says what moves (``motion``), how the sensor sees it (``effects``),
and when and where it is published (``duration``, ``rate``, ``topic``,
``frame_id``, ``start_time``). The format is documented in the README; the
dataclasses below are its schema: each field's metadata holds the check that
turns the YAML value into the stored value, so the accepted keys, their
defaults and their checks live in one place.

Every problem raises :class:`~rotation_node.errors.SceneError` naming the key
path (``motion.half_angle``, ``effects.nan_bursts.length``): unknown keys
first, then missing fields, then invalid values.

Conventions: quaternions (x, y, z, w), scalar last, active, body-to-world;
angular velocities in the body frame, rad/s; angles in radians.
"""
from __future__ import annotations

import dataclasses
import math
import re
from typing import ClassVar, Mapping, Tuple, TYPE_CHECKING, Union

from rotation_node.conversions import parse_sequence
from rotation_node.errors import SceneError
from rotation_node.ros_yaml import load_ros_yaml
from rotation_node.validation import describe_value, did_you_mean

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

#: Default ``start_time``: 2025-01-01T00:00:00Z, in seconds since the Unix epoch.
DEFAULT_START_TIME = 1735689600.0

#: Largest number of samples a scene may ask for (``duration * rate + 1``).
MAX_SAMPLES = 10_000_000

#: A scene's orientation must have unit norm to within this (it is then normalised).
UNIT_NORM_TOLERANCE = 1e-6

# builtin_interfaces/Time.sec is an int32.
_MAX_STAMP_SECONDS = 2**31 - 1

_TOPIC_PATTERN = re.compile(r'(/[A-Za-z_][A-Za-z0-9_]*)+')

#: Topics the simulator writes the truth on; the sensor topic must differ.
TRUTH_ORIENTATION_TOPIC = '/truth/orientation'
TRUTH_ANGULAR_VELOCITY_TOPIC = '/truth/angular_velocity'


# --- value checks: (value, path) -> stored value, SceneError otherwise -----------

def _number(value, path):
    # bool is an int subclass: `rate: true` must not mean 1 Hz.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f'{path}: expected a number, got {describe_value(value)}')
    try:
        x = float(value)
    except OverflowError:   # an integer beyond the float range
        x = math.inf
    if not math.isfinite(x):
        raise SceneError(f'{path}: expected a finite number, got {value!r}')
    return x


def _real(minimum=None, maximum=None, *, positive=False):
    """Check: a finite number in [minimum, maximum] (bounds optional), > 0 if ``positive``."""
    def check(value, path):
        x = _number(value, path)
        if positive and not x > 0:
            raise SceneError(f'{path}: must be > 0, got {x!r}')
        below = minimum is not None and x < minimum
        above = maximum is not None and x > maximum
        if below or above:
            if minimum is not None and maximum is not None:
                expected = f'in [{minimum:g}, {maximum:g}]'
            else:
                expected = f'>= {minimum:g}' if below else f'<= {maximum:g}'
            raise SceneError(f'{path}: must be {expected}, got {x!r}')
        return x
    return check


def _integer(minimum):
    """Check: an integer >= minimum (``3.0`` and ``true`` are not integers)."""
    def check(value, path):
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f'{path}: expected an integer, got {describe_value(value)}')
        if value < minimum:
            raise SceneError(f'{path}: must be >= {minimum}, got {value}')
        return value
    return check


def _vector(size):
    """Check: a list of ``size`` finite numbers, stored as a tuple of float."""
    def check(value, path):
        if not isinstance(value, (list, tuple)) or len(value) != size:
            raise SceneError(
                f'{path}: expected a list of {size} numbers, got {describe_value(value)}')
        return tuple(_number(x, f'{path}[{i}]') for i, x in enumerate(value))
    return check


def _unit_quaternion(value, path):
    """Check: [x, y, z, w] of unit norm within UNIT_NORM_TOLERANCE; stored normalised."""
    q = _vector(4)(value, path)
    norm = math.sqrt(math.fsum(c * c for c in q))
    if abs(norm - 1.0) > UNIT_NORM_TOLERANCE:
        raise SceneError(
            f'{path}: expected a unit quaternion [x, y, z, w], got norm {norm!r} '
            f'(tolerance {UNIT_NORM_TOLERANCE})')
    return tuple(c / norm for c in q)


def _inertia(value, path):
    """Check: principal moments [I1, I2, I3] > 0 obeying the triangle inequality."""
    moments = _vector(3)(value, path)
    if not all(m > 0 for m in moments):
        raise SceneError(f'{path}: principal moments must be > 0, got {list(moments)}')
    if 2 * max(moments) > sum(moments):
        raise SceneError(
            f'{path}: principal moments of a rigid body obey I_i + I_j >= I_k, '
            f'got {list(moments)}')
    return moments


def _scale_range(value, path):
    """Check: [low, high] with 0 < low <= high."""
    low, high = _vector(2)(value, path)
    if not 0 < low <= high:
        raise SceneError(f'{path}: expected [low, high] with 0 < low <= high, got {[low, high]}')
    return low, high


def _euler_sequence(value, path):
    """Check: an Euler sequence accepted by :func:`rotation_node.conversions.parse_sequence`."""
    if not isinstance(value, str):
        raise SceneError(
            f'{path}: expected an Euler sequence such as ZYX, got {describe_value(value)}')
    try:
        return parse_sequence(value).name
    except ValueError as exc:
        raise SceneError(f'{path}: {exc}') from None


def _subset(choices):
    """Check: a non-empty list of distinct names from ``choices``, stored as a tuple."""
    def check(value, path):
        if not isinstance(value, (list, tuple)) or not value:
            raise SceneError(f'{path}: expected a non-empty list from {list(choices)}, '
                             f'got {describe_value(value)}')
        for name in value:
            if name not in choices:
                raise SceneError(f'{path}: unknown entry {name!r}{did_you_mean(name, choices)}; '
                                 f'expected one of {list(choices)}')
        if len(set(value)) != len(value):
            raise SceneError(f'{path}: entries must be distinct, got {list(value)}')
        return tuple(value)
    return check


def _topic(value, path):
    if not isinstance(value, str) or not _TOPIC_PATTERN.fullmatch(value):
        raise SceneError(f'{path}: expected an absolute ROS topic name such as /imu, '
                         f'got {describe_value(value)}')
    if value in (TRUTH_ORIENTATION_TOPIC, TRUTH_ANGULAR_VELOCITY_TOPIC):
        raise SceneError(f'{path}: {value} is reserved for the truth')
    return value


def _frame_id(value, path):
    if not isinstance(value, str) or not value or value.startswith('/') \
            or any(c.isspace() for c in value):
        raise SceneError(f'{path}: expected a tf2 frame id such as imu_link (non-empty, '
                         f'no leading /, no spaces), got {describe_value(value)}')
    return value


def _param(check, default=dataclasses.MISSING):
    """Declare a scene key: its check, and its default unless it is required."""
    return dataclasses.field(default=default, metadata={'check': check})


def _checked_values(cls, data, path, *, skip=()):
    """
    Return the values of the dataclass ``cls``'s scene keys found in the mapping ``data``.

    ``path`` is where ``data`` sits in the scene (``''`` at the top). Unknown
    keys are reported before missing ones, and those before bad values, so a
    misspelt key reads as what it is. Keys in ``skip`` are the caller's (the
    motion ``type``, the top-level ``motion`` and ``effects``). Absent optional
    keys are left out: the dataclass supplies their defaults.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise SceneError(f'{path}: expected a mapping, got {describe_value(data)}')
    fields = {f.name: f for f in dataclasses.fields(cls) if 'check' in f.metadata}
    for key in data:
        if key not in fields and key not in skip:
            expected = [*skip, *fields]
            raise SceneError(f'{_join(path, key)}: unknown key{did_you_mean(key, expected)}; '
                             f'expected {", ".join(expected) or "no keys"}')
    for name, f in fields.items():
        if name not in data and f.default is dataclasses.MISSING:
            raise SceneError(f'{_join(path, name)}: missing')
    return {name: f.metadata['check'](data[name], _join(path, name))
            for name, f in fields.items() if name in data}


def _build(cls, data, path, *, skip=()):
    """Return the dataclass ``cls`` built from the mapping ``data`` at ``path``."""
    return cls(**_checked_values(cls, data, path, skip=skip))


def _join(path, key):
    return f'{path}.{key}' if path else str(key)


# --- motions ------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ConstantRate:
    """
    Rotation at a constant body angular velocity: ``q(t) = q0 (x) exp(w t)``.

    Attributes
    ----------
    orientation : tuple of float, shape (4,)
        Initial orientation ``q0`` (x, y, z, w), unit, body-to-world.
    angular_velocity : tuple of float, shape (3,)
        Body angular velocity ``w``, rad/s.

    """

    type: ClassVar[str] = 'constant_rate'  # noqa: A003
    orientation: Tuple[float, ...] = _param(_unit_quaternion)
    angular_velocity: Tuple[float, ...] = _param(_vector(3))


@dataclasses.dataclass(frozen=True)
class Coning:
    """
    Classical coning motion, analytic (docs/numerics.md, phase 0 at the first sample).

    The body z axis sweeps a cone of half angle ``half_angle`` about the world
    z axis at ``frequency`` rad/s.

    Attributes
    ----------
    half_angle : float
        Cone half angle ``a`` in [0, pi], rad.
    frequency : float
        Cone rate ``W``, rad/s (negative reverses the sense).

    """

    type: ClassVar[str] = 'coning'  # noqa: A003
    half_angle: float = _param(_real(0.0, math.pi))
    frequency: float = _param(_real())


@dataclasses.dataclass(frozen=True)
class TorqueFree:
    """
    Free rigid body: Euler's equations ``I w' = (I w) x w`` with attitude.

    Attributes
    ----------
    inertia : tuple of float, shape (3,)
        Principal moments of inertia (I1, I2, I3) about the body x, y, z axes,
        kg m^2 (only their ratios matter).
    orientation : tuple of float, shape (4,)
        Initial orientation (x, y, z, w), unit, body-to-world.
    angular_velocity : tuple of float, shape (3,)
        Initial body angular velocity, rad/s.

    """

    type: ClassVar[str] = 'torque_free'  # noqa: A003
    inertia: Tuple[float, ...] = _param(_inertia)
    orientation: Tuple[float, ...] = _param(_unit_quaternion)
    angular_velocity: Tuple[float, ...] = _param(_vector(3))


@dataclasses.dataclass(frozen=True)
class EulerSweep:
    """
    Euler angles moving linearly in time from ``start`` (first sample) to ``end`` (t = duration).

    Attributes
    ----------
    sequence : str
        Euler sequence (``'ZYX'`` intrinsic, ``'xyz'`` extrinsic, ...).
    start, end : tuple of float, shape (3,)
        First, second, third angle of ``sequence``, rad. Put the middle
        angles on both sides of its singular value (+-pi/2 Tait-Bryan, 0 or pi
        proper Euler) to sweep through gimbal lock.

    """

    type: ClassVar[str] = 'euler_sweep'  # noqa: A003
    sequence: str = _param(_euler_sequence)
    start: Tuple[float, ...] = _param(_vector(3))
    end: Tuple[float, ...] = _param(_vector(3))


#: Motion classes by their scene ``type``.
#: What a scene's ``motion`` is.
Motion = Union[ConstantRate, Coning, TorqueFree, EulerSweep]

MOTIONS = {cls.type: cls for cls in (ConstantRate, Coning, TorqueFree, EulerSweep)}


# --- effects ------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class GyroNoise:
    """White noise on the angular velocity, each axis N(0, std^2), rad/s."""

    name: ClassVar[str] = 'gyro_noise'
    std: float = _param(_real(0.0))


@dataclasses.dataclass(frozen=True)
class GyroBias:
    """
    Gyro bias ``b_k = constant + random walk``, added to the angular velocity.

    Attributes
    ----------
    constant : tuple of float, shape (3,)
        Initial bias, rad/s.
    random_walk : float
        Rate random walk density, rad/s/sqrt(s): each axis steps by
        N(0, random_walk^2 dt) between samples dt apart.

    """

    name: ClassVar[str] = 'gyro_bias'
    constant: Tuple[float, ...] = _param(_vector(3), (0.0, 0.0, 0.0))
    random_walk: float = _param(_real(0.0), 0.0)


@dataclasses.dataclass(frozen=True)
class OrientationNoise:
    """Orientation error ``q (x) exp(v)``, body rotation vector v ~ N(0, std^2 I), rad."""

    name: ClassVar[str] = 'orientation_noise'
    std: float = _param(_real(0.0))


@dataclasses.dataclass(frozen=True)
class QuaternionSignFlips:
    """Each orientation replaced by ``-q`` (the same rotation) with ``probability``."""

    name: ClassVar[str] = 'quaternion_sign_flips'
    probability: float = _param(_real(0.0, 1.0))


@dataclasses.dataclass(frozen=True)
class NonUnitQuaternions:
    """Each orientation multiplied by a factor uniform in ``scale`` = [low, high]."""

    name: ClassVar[str] = 'non_unit_quaternions'
    scale: Tuple[float, float] = _param(_scale_range)


@dataclasses.dataclass(frozen=True)
class DroppedMessages:
    """Each sensor message left out of the bag with ``probability`` (the truth stays)."""

    name: ClassVar[str] = 'dropped_messages'
    probability: float = _param(_real(0.0, 1.0))


@dataclasses.dataclass(frozen=True)
class TimestampJitter:
    """Sensor ``header.stamp`` offset by N(0, std^2) s, independently per sample."""

    name: ClassVar[str] = 'timestamp_jitter'
    std: float = _param(_real(0.0))


@dataclasses.dataclass(frozen=True)
class OrientationUnknown:
    """With ``probability`` (default 1: always), no orientation: covariance[0] = -1, zeros."""

    name: ClassVar[str] = 'orientation_unknown'
    probability: float = _param(_real(0.0, 1.0), 1.0)


NAN_BURST_FIELDS = ('orientation', 'angular_velocity')


@dataclasses.dataclass(frozen=True)
class NanBursts:
    """
    Bursts of NaN: each sample starts a burst of ``length`` samples with ``probability``.

    Attributes
    ----------
    probability : float
        Probability that a burst starts at a sample, in [0, 1].
    length : int
        Samples per burst, >= 1 (overlapping bursts merge).
    fields : tuple of str
        Which of ``orientation``, ``angular_velocity`` turn NaN (all components).

    """

    name: ClassVar[str] = 'nan_bursts'
    probability: float = _param(_real(0.0, 1.0))
    length: int = _param(_integer(1))
    fields: Tuple[str, ...] = _param(_subset(NAN_BURST_FIELDS), NAN_BURST_FIELDS)


#: Effect parameter classes by their scene name.
EFFECT_PARAMETERS = {cls.name: cls for cls in (
    GyroNoise, GyroBias, OrientationNoise, QuaternionSignFlips, NonUnitQuaternions,
    DroppedMessages, TimestampJitter, OrientationUnknown, NanBursts)}


# --- the scene ----------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Scene:
    """
    A validated scene.

    Attributes
    ----------
    duration : float
        Length of the scene, s (> 0): samples at ``k / rate`` up to and including it.
    rate : float
        Samples per second (> 0).
    motion : ConstantRate or Coning or TorqueFree or EulerSweep
        What moves.
    effects : Mapping[str, object]
        Effect parameters by effect name; only these effects are simulated.
    topic : str
        Absolute topic of the ``sensor_msgs/Imu`` stream.
    frame_id : str
        ``header.frame_id`` of every message.
    start_time : float
        Stamp of the first sample, seconds since the Unix epoch.

    """

    duration: float = _param(_real(positive=True))
    rate: float = _param(_real(positive=True))
    # Required, as are duration and rate: mypy takes any `_param(...)` for a default.
    motion: Motion  # type: ignore[misc]
    effects: Mapping[str, object] = dataclasses.field(default_factory=dict)
    topic: str = _param(_topic, '/imu')
    frame_id: str = _param(_frame_id, 'imu_link')
    start_time: float = _param(_real(0.0), DEFAULT_START_TIME)

    @property
    def sample_count(self) -> int:
        """Return the number of samples: one at ``k / rate`` for each ``k / rate <= duration``."""
        return sample_count(self.duration, self.rate)


def sample_count(duration: float, rate: float) -> int:
    """
    Return the number of samples ``t_k = k / rate`` with ``t_k <= duration``.

    ``duration * rate`` within 1e-9 (relative) of an integer counts as that
    integer, so 4 s at 100 Hz gives 401 samples whatever the rounding.
    """
    n = duration * rate
    return math.floor(n + 1e-9 * max(1.0, n)) + 1


def scene_from_dict(data: object) -> Scene:
    """
    Validate a scene given as parsed YAML.

    Parameters
    ----------
    data : dict
        The scene's top-level mapping.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        Naming the key path of the first unknown key, missing field or bad value.

    """
    if not isinstance(data, dict):
        raise SceneError(f'scene: expected a mapping of keys, got {describe_value(data)}')
    values = _checked_values(Scene, data, '', skip=('motion', 'effects'))
    if 'motion' not in data:
        raise SceneError('motion: missing')
    scene = Scene(motion=_motion(data['motion']), effects=_effects(data.get('effects')), **values)
    n = scene.sample_count
    if n > MAX_SAMPLES:
        raise SceneError(f'duration: duration * rate gives {n} samples, more than {MAX_SAMPLES}')
    if scene.start_time + scene.duration + 1 > _MAX_STAMP_SECONDS:
        raise SceneError(f'start_time: stamps must stay below {_MAX_STAMP_SECONDS} s '
                         f'(builtin_interfaces/Time.sec is an int32)')
    return scene


def _motion(data):
    if not isinstance(data, dict):
        raise SceneError(f'motion: expected a mapping with a type, got {describe_value(data)}')
    if 'type' not in data:
        raise SceneError(f'motion.type: missing; expected one of {", ".join(MOTIONS)}')
    kind = data['type']
    if not isinstance(kind, str) or kind not in MOTIONS:
        raise SceneError(
            f'motion.type: unknown motion {kind!r}{did_you_mean(kind, MOTIONS)}; '
            f'expected one of {", ".join(MOTIONS)}')
    return _build(MOTIONS[kind], data, 'motion', skip=('type',))


def _effects(data):
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise SceneError(
            f'effects: expected a mapping of effect names, got {describe_value(data)}')
    for name in data:
        if name not in EFFECT_PARAMETERS:
            raise SceneError(f'effects.{name}: unknown effect'
                             f'{did_you_mean(name, EFFECT_PARAMETERS)}; '
                             f'expected one of {", ".join(EFFECT_PARAMETERS)}')
    return {name: _build(EFFECT_PARAMETERS[name], params, f'effects.{name}')
            for name, params in data.items()}


def load_scene(path: StrPath) -> Scene:
    """
    Load and validate a YAML scene file.

    Parameters
    ----------
    path : str or os.PathLike
        The scene file.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        If the file cannot be read, is not YAML, or is not a valid scene; the
        message starts with the file name and names the key that is wrong.

    """
    data = load_ros_yaml(path, str(path), SceneError)
    try:
        return scene_from_dict(data)
    except SceneError as exc:
        raise SceneError(f'{path}: {exc}') from None
