"""
Scene files: load a YAML scene and validate it into frozen dataclasses.

A scene says what moves (``motion``), how the sensor sees it (``effects``),
and when and where it is published (``duration``, ``rate``, ``topic``,
``frame_id``, ``start_time``). The format is documented in the README; the
dataclasses below are its schema: each field is declared with its kind of value
(:mod:`rotation_node.validation`) and what the domain adds (a unit quaternion,
moments of inertia of a rigid body), so the accepted keys, their defaults and
their checks live in one place.

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
from typing import ClassVar, Mapping, Optional, Tuple, TYPE_CHECKING, Union

import numpy as np
from rotation_node.conversions import parse_sequence
from rotation_node.errors import SceneError
from rotation_node.mounting import normalised_unit_quaternion
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


# --- what the domain adds to the kinds: (value, where) -> stored value -----------

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
    orientation: Tuple[float, ...] = checked_field(Vector(4), check=_unit_quaternion)
    angular_velocity: Tuple[float, ...] = checked_field(_VECTOR)


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
    half_angle: float = checked_field(Real(0.0, math.pi))
    frequency: float = checked_field(Real())


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
    inertia: Tuple[float, ...] = checked_field(_VECTOR, check=_principal_moments)
    orientation: Tuple[float, ...] = checked_field(Vector(4), check=_unit_quaternion)
    angular_velocity: Tuple[float, ...] = checked_field(_VECTOR)


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
    sequence: str = checked_field(_EULER_SEQUENCE)
    start: Tuple[float, ...] = checked_field(_VECTOR)
    end: Tuple[float, ...] = checked_field(_VECTOR)


#: What a scene's ``motion`` is.
Motion = Union[ConstantRate, Coning, TorqueFree, EulerSweep]

#: Motion classes by their scene ``type``.
MOTIONS = {cls.type: cls for cls in (ConstantRate, Coning, TorqueFree, EulerSweep)}


# --- effects ------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class GyroNoise:
    """White noise on the angular velocity, each axis N(0, std^2), rad/s."""

    name: ClassVar[str] = 'gyro_noise'
    std: float = checked_field(Real(0.0))


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
    probability: float = checked_field(_PROBABILITY)
    length: int = checked_field(Integer(1))
    fields: Tuple[str, ...] = checked_field(ChoiceList(NAN_BURST_FIELDS, item='field'),
                                            NAN_BURST_FIELDS)


#: Effect parameter classes by their scene name.
EFFECT_PARAMETERS = {cls.name: cls for cls in (
    GyroNoise, GyroBias, OrientationNoise, QuaternionSignFlips, NonUnitQuaternions,
    DroppedMessages, TimestampJitter, OrientationUnknown, NanBursts)}


# --- the reference stream -----------------------------------------------------

#: Message types of a reference stream: ``geometry_msgs/PoseStamped`` or ``sensor_msgs/Imu``.
REFERENCE_MESSAGES = ('pose', 'imu')

_IDENTITY_QUATERNION = (0.0, 0.0, 0.0, 1.0)


@dataclasses.dataclass(frozen=True)
class Reference:
    """
    A second stream of the scene's motion, as a reference system (mocap, an INS) sees it.

    Its orientation at its own stamp ``t`` is
    ``R_ref(t) = W . R(t + time_offset) . M`` (body-to-world matrices), with
    ``R`` the scene's truth, ``W = world_alignment`` and ``M = mounting``: the
    convention of ``rotation_bag compare`` with the scene's sensor stream as
    the estimate (``R_est = R`` without its effects). Samples are at
    ``start_time + k / rate`` for every ``k`` whose ``t + time_offset`` lies in
    ``[0, duration]`` of the scene.

    Attributes
    ----------
    rate : float
        Samples per second (> 0).
    topic : str
        Absolute topic of the stream; not the sensor's or a truth topic.
    frame_id : str
        ``header.frame_id`` of its messages (the reference's world frame for a pose).
    message : str
        ``pose`` (``geometry_msgs/PoseStamped``, position zero) or ``imu``
        (``sensor_msgs/Imu`` with the body angular velocity ``M^T w(t + time_offset)``).
    time_offset : float
        ``dt``, s: the reference at ``t`` shows the motion at ``t + dt``.
    mounting : tuple of float, shape (4,)
        ``M`` (x, y, z, w), unit: the reference body's orientation in the sensor's body frame.
    world_alignment : tuple of float, shape (4,)
        ``W`` (x, y, z, w), unit: the sensor's world frame's orientation in the
        reference's world frame.
    orientation_noise : float
        Standard deviation (rad) of a body-frame rotation vector ``v``: each
        orientation is ``q_ref (x) exp(v)``.

    """

    rate: float = checked_field(Real(positive=True))
    topic: str = checked_field(_TOPIC, '/reference/pose')
    frame_id: str = checked_field(_FRAME_ID, 'mocap')
    message: str = checked_field(Choice(REFERENCE_MESSAGES), 'pose')
    time_offset: float = checked_field(Real(), 0.0)
    mounting: Tuple[float, ...] = checked_field(Vector(4), _IDENTITY_QUATERNION,
                                                check=_unit_quaternion)
    world_alignment: Tuple[float, ...] = checked_field(Vector(4), _IDENTITY_QUATERNION,
                                                       check=_unit_quaternion)
    orientation_noise: float = checked_field(Real(0.0), 0.0)


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
    reference : Reference or None
        A second stream of the same motion, only when the scene asks for one.

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

    ``duration * rate`` within 1e-9 (relative) of an integer counts as that
    integer, so 4 s at 100 Hz gives 401 samples whatever the rounding.
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
