"""
Sensor effects: what a simulated IMU gets wrong, one small function per effect.

The simulated sensor starts as the truth (:meth:`SensorStream.from_truth`).
Each effect listed in the scene is then a function ``(stream, params, rng,
state) -> (stream, changed)`` that returns a new stream in which only the
fields that effect owns differ, and the ``(n,)`` mask of the samples it
changed. ``state`` is a dict the effect keeps between calls on consecutive
blocks of one stream (a random walk's position, a burst running into the next
block): :class:`EffectsStream` applies the effects block by block with the
same result, bit for bit, as on the whole stream at once.

=========================  =============================================================
effect                     fields it changes
=========================  =============================================================
``gyro_bias``              ``angular_velocity``
``gyro_noise``             ``angular_velocity``, ``angular_velocity_covariance``
``orientation_noise``      ``orientation``, ``orientation_covariance``
``quaternion_sign_flips``  ``orientation``
``non_unit_quaternions``   ``orientation``
``nan_bursts``             ``orientation`` and/or ``angular_velocity``
``orientation_unknown``    ``orientation``, ``orientation_covariance``
``timestamp_jitter``       ``stamp_ns``
``dropped_messages``       ``published``
=========================  =============================================================

Effects apply in the order of this table (:data:`EFFECTS`), whatever the
order in the scene file. Every effect draws from its own generator, seeded by
the scene seed and the effect's name (:func:`effect_rng`), and always draws the
same number of values, so enabling one effect never changes another's draws.

Conventions: quaternions (x, y, z, w), body-to-world; angular velocity in the
body frame, rad/s; covariances row-major 3x3 as in ``sensor_msgs/Imu``.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping, TYPE_CHECKING

import numpy as np
from rotation_node.conversions import quaternion_from_rotation_vector, quaternion_product
from rotation_node.wire.stamps import NS_PER_S as _NS_PER_S

from .spec import (
    DroppedMessages, GyroBias, GyroNoise, NanBursts, NonUnitQuaternions, OrientationNoise,
    OrientationUnknown, QuaternionSignFlips, TimestampJitter)

if TYPE_CHECKING:
    from rotation_node.type_aliases import BoolArray, FloatArray, IntArray

#: ``sensor_msgs/Imu``: covariance element 0 set to -1 means "no estimate".
UNKNOWN_COVARIANCE = -1.0


@dataclasses.dataclass(frozen=True)
class SensorStream:
    """
    What the simulated sensor reports: one row per sample of the truth.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Nominal sample times since the first sample, s (no effect changes it).
    stamp_ns : ndarray of int64, shape (n,)
        ``header.stamp`` of each sensor message, ns since the Unix epoch.
    orientation : ndarray, shape (n, 4)
        Quaternions (x, y, z, w), body-to-world.
    angular_velocity : ndarray, shape (n, 3)
        Body angular velocity, rad/s.
    orientation_covariance, angular_velocity_covariance : ndarray, shape (n, 9)
        Row-major 3x3 covariances (rad^2, (rad/s)^2). All zeros is what
        ``sensor_msgs/Imu`` calls "covariance unknown"; element 0 = -1 means
        "no estimate".
    published : ndarray of bool, shape (n,)
        Whether the sample's sensor message is written.

    """

    time: np.ndarray
    stamp_ns: np.ndarray
    orientation: np.ndarray
    angular_velocity: np.ndarray
    orientation_covariance: np.ndarray
    angular_velocity_covariance: np.ndarray
    published: np.ndarray

    @classmethod
    def from_truth(cls, time: FloatArray, stamp_ns: IntArray, orientation: FloatArray,
                   angular_velocity: FloatArray) -> SensorStream:
        """
        Return a perfect sensor: the truth, zero covariances, every sample published.

        The arrays are copied, so effects never alias the truth.
        """
        n = len(time)
        return cls(time=np.array(time, dtype=np.float64),
                   stamp_ns=np.array(stamp_ns, dtype=np.int64),
                   orientation=np.array(orientation, dtype=np.float64),
                   angular_velocity=np.array(angular_velocity, dtype=np.float64),
                   orientation_covariance=np.zeros((n, 9)),
                   angular_velocity_covariance=np.zeros((n, 9)),
                   published=np.ones(n, dtype=bool))

    def __len__(self) -> int:
        return len(self.time)


def _isotropic_covariance(n, std):
    """Return ``n`` rows of the row-major covariance ``std^2 I3``, shape (n, 9)."""
    return np.tile((std * std * np.eye(3)).ravel(), (n, 1))


def add_gyro_bias(stream: SensorStream, params: GyroBias,
                  rng: np.random.Generator,
                  state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """
    Return the stream with ``b_k = constant + random walk`` added to the angular velocity.

    The walk starts at 0 on the first sample and steps by
    ``N(0, random_walk^2 dt)`` per axis over each nominal interval ``dt``.
    """
    if 'time' in state:   # a later block: the walk goes on from the last sample
        time = np.concatenate(([state['time']], stream.time))
    else:
        time = stream.time
    steps = rng.standard_normal((len(time) - 1, 3))
    steps *= params.random_walk * np.sqrt(np.diff(time))[:, np.newaxis]
    walk = np.cumsum(np.concatenate((state.get('walk', np.zeros((1, 3))), steps)), axis=0)
    if 'time' in state:
        walk = walk[1:]
    state['time'], state['walk'] = stream.time[-1], walk[-1:].copy()
    bias = np.asarray(params.constant) + walk
    changed = np.any(bias != 0, axis=1)
    return dataclasses.replace(stream, angular_velocity=stream.angular_velocity + bias), changed


def add_gyro_noise(stream: SensorStream, params: GyroNoise,
                   rng: np.random.Generator,
                   state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """Return the stream with N(0, std^2) white noise on each gyro axis, and its covariance."""
    noise = params.std * rng.standard_normal((len(stream), 3))
    return dataclasses.replace(
        stream, angular_velocity=stream.angular_velocity + noise,
        angular_velocity_covariance=_isotropic_covariance(len(stream), params.std),
    ), np.full(len(stream), params.std > 0)


def add_orientation_noise(stream: SensorStream, params: OrientationNoise,
                          rng: np.random.Generator,
                          state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """
    Return the stream with orientation ``q (x) exp(v)``, and its covariance ``std^2 I``.

    ``v ~ N(0, std^2 I)`` is a rotation vector in the body frame.

    ``exp(v)`` has a positive scalar part, so the sign of ``q`` is kept.
    """
    v = params.std * rng.standard_normal((len(stream), 3))
    return dataclasses.replace(
        stream, orientation=quaternion_product(stream.orientation,
                                               quaternion_from_rotation_vector(v)),
        orientation_covariance=_isotropic_covariance(len(stream), params.std),
    ), np.full(len(stream), params.std > 0)


def flip_quaternion_signs(stream: SensorStream, params: QuaternionSignFlips,
                          rng: np.random.Generator,
                          state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """Return the stream with each orientation replaced by ``-q`` with ``probability``."""
    flipped = rng.random(len(stream)) < params.probability
    sign = np.where(flipped, -1.0, 1.0)[:, np.newaxis]
    return dataclasses.replace(stream, orientation=stream.orientation * sign), flipped


def scale_quaternions(stream: SensorStream, params: NonUnitQuaternions,
                      rng: np.random.Generator,
                      state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """Return the stream with each orientation multiplied by a factor uniform in ``scale``."""
    low, high = params.scale
    factor = rng.uniform(low, high, len(stream))
    return (dataclasses.replace(stream, orientation=stream.orientation * factor[:, np.newaxis]),
            factor != 1.0)


def insert_nan_bursts(stream: SensorStream, params: NanBursts,
                      rng: np.random.Generator,
                      state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """
    Return the stream with NaN in every component of ``fields`` during bursts.

    Each sample starts a burst of ``length`` samples with ``probability``;
    overlapping bursts merge.
    """
    starts = rng.random(len(stream)) < params.probability
    # Starts of the previous block whose bursts reach into this one.
    earlier = state.get('starts', np.zeros(0, dtype=np.int64))
    linked = np.concatenate((earlier, starts.astype(np.int64)))
    in_burst = np.convolve(linked, np.ones(params.length, dtype=np.int64))
    in_burst = in_burst[len(earlier):len(earlier) + len(stream)] > 0
    state['starts'] = linked[max(len(linked) - (params.length - 1), 0):]
    changes = {}
    for field in params.fields:
        values = getattr(stream, field).copy()
        values[in_burst] = np.nan
        changes[field] = values
    return dataclasses.replace(stream, **changes), in_burst


def hide_orientation(stream: SensorStream, params: OrientationUnknown,
                     rng: np.random.Generator,
                     state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """
    Return the stream with the orientation hidden, each sample with ``probability``.

    A hidden orientation has ``orientation_covariance[0] = -1`` (the rest 0)
    and orientation (0, 0, 0, 0).

    This is how ``sensor_msgs/Imu`` says "no orientation estimate"; the zero
    quaternion is not a rotation, so a consumer that ignores the covariance
    fails loudly rather than using a wrong attitude.
    """
    unknown = rng.random(len(stream)) < params.probability
    orientation = stream.orientation.copy()
    orientation[unknown] = 0.0
    covariance = stream.orientation_covariance.copy()
    covariance[unknown] = 0.0
    covariance[unknown, 0] = UNKNOWN_COVARIANCE
    return dataclasses.replace(stream, orientation=orientation,
                               orientation_covariance=covariance), unknown


def jitter_timestamps(stream: SensorStream, params: TimestampJitter,
                      rng: np.random.Generator,
                      state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """
    Return the stream with each ``header.stamp`` offset by N(0, std^2) s, rounded to ns.

    Offsets are independent, so stamps can go backwards when ``std`` is not
    small against the sample period; the messages stay in sample order.
    """
    offset_ns = np.round(params.std * _NS_PER_S * rng.standard_normal(len(stream)))
    offset_ns = offset_ns.astype(np.int64)
    return dataclasses.replace(stream, stamp_ns=stream.stamp_ns + offset_ns), offset_ns != 0


def drop_messages(stream: SensorStream, params: DroppedMessages,
                  rng: np.random.Generator,
                  state: dict[str, Any]) -> tuple[SensorStream, BoolArray]:
    """Return the stream with each sample unpublished with ``probability``."""
    dropped = rng.random(len(stream)) < params.probability
    return dataclasses.replace(stream, published=stream.published & ~dropped), dropped


#: Effect functions by scene name, in the order they apply.
EFFECTS: dict[str, Callable[..., tuple[SensorStream, BoolArray]]] = {
    'gyro_bias': add_gyro_bias,
    'gyro_noise': add_gyro_noise,
    'orientation_noise': add_orientation_noise,
    'quaternion_sign_flips': flip_quaternion_signs,
    'non_unit_quaternions': scale_quaternions,
    'nan_bursts': insert_nan_bursts,
    'orientation_unknown': hide_orientation,
    'timestamp_jitter': jitter_timestamps,
    'dropped_messages': drop_messages,
}


def effect_rng(seed: int, name: str) -> np.random.Generator:
    """
    Return the generator of effect ``name`` for scene seed ``seed``.

    ``SeedSequence(seed, spawn_key=<bytes of name>)``: independent streams per
    effect, stable across runs and processes (no Python ``hash``).
    """
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=tuple(name.encode())))


class EffectsStream:
    """
    The scene's effects, applied to consecutive blocks of one sensor stream.

    ``apply(block)`` on consecutive pieces of a stream returns, piece by
    piece, exactly what ``apply`` of a new ``EffectsStream`` returns for the
    whole stream: each effect keeps its generator and its state across blocks.

    Parameters
    ----------
    effects : Mapping[str, object]
        Effect parameters by name (``Scene.effects``).
    seed : int
        Scene seed, >= 0.

    """

    def __init__(self, effects: Mapping[str, object], seed: int) -> None:
        self._effects: list[tuple[str, Callable[..., tuple[SensorStream, BoolArray]], object,
                                  np.random.Generator, dict[str, Any]]] = [
            (name, effect, effects[name], effect_rng(seed, name), {})
            for name, effect in EFFECTS.items() if name in effects]

    def apply(self, stream: SensorStream) -> tuple[SensorStream, dict[str, BoolArray]]:
        """Return the next block with the effects applied, and what each changed in it."""
        changed = {}
        for name, effect, params, rng, state in self._effects:
            stream, changed[name] = effect(stream, params, rng, state)
        return stream, changed
