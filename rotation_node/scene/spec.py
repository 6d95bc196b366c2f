"""
Scene files: a YAML scene validated into frozen dataclasses (the README's "Scene file").

The dataclasses are the schema: each field declares its kind of value
(:mod:`rotation_node.validation`) and what the domain adds (a unit quaternion, the moments
of inertia of a rigid body), so keys, defaults and checks live in one place. Every problem
is a :class:`~rotation_node.errors.SceneError` naming the key path (``motion.half_angle``):
unknown keys first, then missing fields, then invalid values. Quaternions (x, y, z, w),
body-to-world; angular velocities in the body frame, rad/s; angles in radians.
"""
from __future__ import annotations

import dataclasses
import math
import re
from typing import ClassVar, Mapping, Optional, Tuple, TYPE_CHECKING, Union

import numpy as np
from rotation_node.conversions import parse_sequence
from rotation_node.errors import SceneError
from rotation_node.mounting import IDENTITY, normalised_unit_quaternion
from rotation_node.ros_yaml import load_ros_yaml
from rotation_node.validation import (
    checked_field, Choice, ChoiceList, dataclass_from_mapping, DataclassByTag, DataclassesByName,
    Integer, KeyPath, NestedDataclass, Real, Text, type_and_repr, Vector)
from rotation_node.wire.stamps import NS_PER_S

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

#: Default ``start_time``: 2025-01-01T00:00:00Z, in seconds since the Unix epoch.
DEFAULT_START_TIME = 1735689600.0

#: Largest number of samples a scene may ask for (``duration * rate + 1``).
MAX_SAMPLES = 10_000_000

# builtin_interfaces/Time.sec is an int32.
_MAX_STAMP_SECONDS = 2**31 - 1

#: Topics the simulator writes the truth on; the sensor topic must differ.
TRUTH_ORIENTATION_TOPIC = '/truth/orientation'
TRUTH_ANGULAR_VELOCITY_TOPIC = '/truth/angular_velocity'


# What the domain adds to the kinds: (value, where) -> stored value.

def _unit_quaternion(q, where):
    """Check: [x, y, z, w] of unit norm within the mountings' tolerance; stored normalised."""
    try:
        return normalised_unit_quaternion(q)
    except ValueError as error:
        raise where.error(str(error)) from None


def _principal_moments(moments, where):
    """Check: principal moments [I1, I2, I3] > 0 obeying the triangle inequality."""
    if not all(m > 0 for m in moments):
        raise where.error(f'principal moments must be > 0, got {list(moments)}')
    if 2 * max(moments) > sum(moments):
        raise where.error(f'principal moments of a rigid body obey I_i + I_j >= I_k, '
                          f'got {list(moments)}')
    return moments


def _scale_range(scale, where):
    """Check: [low, high] with 0 < low <= high."""
    low, high = scale
    if not 0 < low <= high:
        raise where.error(f'expected [low, high] with 0 < low <= high, got {[low, high]}')
    return scale


def _not_truth_topic(topic, where):
    if topic in (TRUTH_ORIENTATION_TOPIC, TRUTH_ANGULAR_VELOCITY_TOPIC):
        raise where.error(f'{topic} is reserved for the truth')
    return topic


_SCENE = KeyPath(error_type=SceneError)
_EULER_SEQUENCE = Text('an Euler sequence', parser=parse_sequence)
_TOPIC = Text('an absolute ROS topic name such as /imu',
              re.compile(r'(/[A-Za-z_][A-Za-z0-9_]*)+'))
_FRAME_ID = Text('a tf2 frame id such as imu_link (non-empty, no leading /, no spaces)',
                 re.compile(r'[^/\s]\S*'))
_PROBABILITY = Real(0.0, 1.0)
_VECTOR = Vector(3)


@dataclasses.dataclass(frozen=True)
class ConstantRate:
    """A constant body angular velocity: ``q(t) = orientation (x) exp(angular_velocity t)``."""

    type: ClassVar[str] = 'constant_rate'  # noqa: A003
    orientation: Tuple[float, ...] = checked_field(Vector(4), check=_unit_quaternion)
    angular_velocity: Tuple[float, ...] = checked_field(_VECTOR)


@dataclasses.dataclass(frozen=True)
class Coning:
    """
    Coning (docs/numerics.md): the body z axis sweeps a cone about the world z axis.

    ``half_angle`` in [0, pi] rad, ``frequency`` the cone rate in rad/s (negative reverses it).
    """

    type: ClassVar[str] = 'coning'  # noqa: A003
    half_angle: float = checked_field(Real(0.0, math.pi))
    frequency: float = checked_field(Real())


@dataclasses.dataclass(frozen=True)
class TorqueFree:
    """A free rigid body, ``I w' = (I w) x w``: principal moments (only their ratios matter)."""

    type: ClassVar[str] = 'torque_free'  # noqa: A003
    inertia: Tuple[float, ...] = checked_field(_VECTOR, check=_principal_moments)
    orientation: Tuple[float, ...] = checked_field(Vector(4), check=_unit_quaternion)
    angular_velocity: Tuple[float, ...] = checked_field(_VECTOR)


@dataclasses.dataclass(frozen=True)
class EulerSweep:
    """Euler angles of ``sequence`` going linearly from ``start`` (t = 0) to ``end``."""

    type: ClassVar[str] = 'euler_sweep'  # noqa: A003
    sequence: str = checked_field(_EULER_SEQUENCE)
    start: Tuple[float, ...] = checked_field(_VECTOR)
    end: Tuple[float, ...] = checked_field(_VECTOR)


#: What a scene's ``motion`` is.
Motion = Union[ConstantRate, Coning, TorqueFree, EulerSweep]

#: Motion classes by their scene ``type``.
MOTIONS = {cls.type: cls for cls in (ConstantRate, Coning, TorqueFree, EulerSweep)}


@dataclasses.dataclass(frozen=True)
class GyroNoise:
    """White noise on the angular velocity, each axis N(0, std^2), rad/s."""

    name: ClassVar[str] = 'gyro_noise'
    std: float = checked_field(Real(0.0))


@dataclasses.dataclass(frozen=True)
class GyroBias:
    """Gyro bias: ``constant`` (rad/s) plus a random walk, ``random_walk`` in rad/s/sqrt(s)."""

    name: ClassVar[str] = 'gyro_bias'
    constant: Tuple[float, ...] = checked_field(_VECTOR, (0.0, 0.0, 0.0))
    random_walk: float = checked_field(Real(0.0), 0.0)


@dataclasses.dataclass(frozen=True)
class OrientationNoise:
    """Orientation error ``q (x) exp(v)``, body rotation vector v ~ N(0, std^2 I), rad."""

    name: ClassVar[str] = 'orientation_noise'
    std: float = checked_field(Real(0.0))


@dataclasses.dataclass(frozen=True)
class QuaternionSignFlips:
    """Each orientation replaced by ``-q`` (the same rotation) with ``probability``."""

    name: ClassVar[str] = 'quaternion_sign_flips'
    probability: float = checked_field(_PROBABILITY)


@dataclasses.dataclass(frozen=True)
class NonUnitQuaternions:
    """Each orientation multiplied by a factor uniform in ``scale`` = [low, high]."""

    name: ClassVar[str] = 'non_unit_quaternions'
    scale: Tuple[float, float] = checked_field(Vector(2), check=_scale_range)


@dataclasses.dataclass(frozen=True)
class DroppedMessages:
    """Each sensor message left out of the bag with ``probability`` (the truth stays)."""

    name: ClassVar[str] = 'dropped_messages'
    probability: float = checked_field(_PROBABILITY)


@dataclasses.dataclass(frozen=True)
class TimestampJitter:
    """Sensor ``header.stamp`` offset by N(0, std^2) s, independently per sample."""

    name: ClassVar[str] = 'timestamp_jitter'
    std: float = checked_field(Real(0.0))


@dataclasses.dataclass(frozen=True)
class OrientationUnknown:
    """With ``probability`` (default 1: always), no orientation: covariance[0] = -1, zeros."""

    name: ClassVar[str] = 'orientation_unknown'
    probability: float = checked_field(_PROBABILITY, 1.0)


NAN_BURST_FIELDS = ('orientation', 'angular_velocity')


@dataclasses.dataclass(frozen=True)
class NanBursts:
    """Each sample starts a burst of ``length`` samples of NaN ``fields`` with ``probability``."""

    name: ClassVar[str] = 'nan_bursts'
    probability: float = checked_field(_PROBABILITY)
    length: int = checked_field(Integer(1))
    fields: Tuple[str, ...] = checked_field(ChoiceList(NAN_BURST_FIELDS, item='field'),
                                            NAN_BURST_FIELDS)


#: Effect parameter classes by their scene name.
EFFECT_PARAMETERS = {cls.name: cls for cls in (
    GyroNoise, GyroBias, OrientationNoise, QuaternionSignFlips, NonUnitQuaternions,
    DroppedMessages, TimestampJitter, OrientationUnknown, NanBursts)}


@dataclasses.dataclass(frozen=True)
class Reference:
    """
    A second stream of the scene's motion, as a reference system (mocap, an INS) sees it.

    ``R_ref(t) = W R(t + time_offset) M`` at its own stamps ``t`` (``W = world_alignment``,
    ``M = mounting``, ``R`` the truth): the convention of ``rotation_bag compare`` with the
    sensor stream as the estimate; ``orientation_noise`` (rad) turns each sample by
    ``exp(v)`` in its body frame. ``message`` ``pose`` is ``geometry_msgs/PoseStamped``,
    ``imu`` a ``sensor_msgs/Imu`` also carrying the body rate ``M^T w(t + time_offset)``.
    """

    rate: float = checked_field(Real(positive=True))
    topic: str = checked_field(_TOPIC, '/reference/pose')
    frame_id: str = checked_field(_FRAME_ID, 'mocap')
    message: str = checked_field(Choice(('pose', 'imu')), 'pose')
    time_offset: float = checked_field(Real(), 0.0)
    mounting: Tuple[float, ...] = checked_field(Vector(4), IDENTITY, check=_unit_quaternion)
    world_alignment: Tuple[float, ...] = checked_field(Vector(4), IDENTITY,
                                                       check=_unit_quaternion)
    orientation_noise: float = checked_field(Real(0.0), 0.0)


@dataclasses.dataclass(frozen=True)
class Scene:
    """
    A validated scene: samples at ``start_time + k / rate`` (s since the epoch) up to ``duration``.

    ``effects`` holds the parameters of the effects to simulate, by name; ``reference`` is
    None unless the scene asks for a second stream.
    """

    duration: float = checked_field(Real(positive=True))
    rate: float = checked_field(Real(positive=True))
    motion: Motion = checked_field(DataclassByTag(MOTIONS, 'motion'))
    effects: Mapping[str, object] = checked_field(
        DataclassesByName(EFFECT_PARAMETERS, 'effect'), default_factory=dict)
    topic: str = checked_field(_TOPIC, '/imu', check=_not_truth_topic)
    frame_id: str = checked_field(_FRAME_ID, 'imu_link')
    start_time: float = checked_field(Real(0.0), DEFAULT_START_TIME)
    reference: Optional[Reference] = checked_field(NestedDataclass(Reference), None)

    @property
    def sample_count(self) -> int:
        """Return the number of samples: one at ``k / rate`` for each ``k / rate <= duration``."""
        return sample_count(self.duration, self.rate)


def sample_count(duration: float, rate: float) -> int:
    """
    Return the number of samples ``t_k = k / rate`` with ``t_k <= duration``.

    ``duration * rate`` within 1e-9 of an integer counts as it: 4 s at 100 Hz gives 401.
    """
    n = duration * rate
    return math.floor(n + 1e-9 * max(1.0, n)) + 1


def start_stamp_ns(start_time: float) -> int:
    """Return ``start_time`` in ns since the epoch: whole seconds plus a fraction rounded to ns."""
    whole_seconds = int(start_time // 1)
    return whole_seconds * NS_PER_S + round((start_time - whole_seconds) * NS_PER_S)


def stamps_ns(start_time: float, rate: float, start: int, stop: int) -> np.ndarray:
    """Return the stamps ``start_time + k / rate`` of samples ``k = start .. stop-1``, in ns."""
    offsets = np.round(np.arange(start, stop) * (NS_PER_S / rate))
    return start_stamp_ns(start_time) + offsets.astype(np.int64)


def scene_from_dict(data: object) -> Scene:
    """Validate a scene's parsed YAML mapping; a SceneError names the key path of the problem."""
    if not isinstance(data, dict):
        raise SceneError(f'scene: expected a mapping of keys, got {type_and_repr(data)}')
    scene = dataclass_from_mapping(Scene, data, _SCENE)
    n = scene.sample_count
    if n > MAX_SAMPLES:
        raise SceneError(f'duration: duration * rate gives {n} samples, more than {MAX_SAMPLES}')
    reference = scene.reference
    if reference is not None:
        if reference.topic in (scene.topic, TRUTH_ORIENTATION_TOPIC, TRUTH_ANGULAR_VELOCITY_TOPIC):
            raise SceneError(f"reference.topic: {reference.topic} is already the sensor's or a "
                             'truth topic')
        if abs(reference.time_offset) >= scene.duration:
            raise SceneError(f'reference.time_offset: {reference.time_offset!r} s leaves no '
                             f"overlap with the scene's {scene.duration!r} s")
        m = sample_count(scene.duration, reference.rate)
        if m > MAX_SAMPLES:
            raise SceneError(f'reference.rate: duration * rate gives {m} samples, more than '
                             f'{MAX_SAMPLES}')
    if scene.start_time + scene.duration + 1 > _MAX_STAMP_SECONDS:
        raise SceneError(f'start_time: stamps must stay below {_MAX_STAMP_SECONDS} s '
                         f'(builtin_interfaces/Time.sec is an int32)')
    return scene


def load_scene(path: StrPath) -> Scene:
    """Load and validate a YAML scene file; a SceneError starts with the file name."""
    data = load_ros_yaml(path, str(path), SceneError)
    try:
        return scene_from_dict(data)
    except SceneError as exc:
        raise SceneError(f'{path}: {exc}') from None
