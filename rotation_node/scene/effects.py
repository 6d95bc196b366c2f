"""
Sensor effects: what a simulated IMU gets wrong, one small function per effect.

The sensor starts as the truth (:meth:`SensorStream.from_truth`); each effect of the scene is
a function ``(stream, params, rng, state) -> (stream, changed)`` returning a new stream in
which only the fields it owns differ, and the ``(n,)`` mask of the samples it changed.
``state`` carries what an effect needs across consecutive blocks (a random walk's position, a
burst running on), so :class:`EffectsStream` gives bit for bit the same result block by block.
Effects apply in the order of :data:`EFFECTS` whatever the scene file's, each drawing a fixed
number of values from its own generator (:func:`effect_rng`): enabling one never changes
another's draws. Covariances are row-major 3x3 as in ``sensor_msgs/Imu``.
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
    from numpy.random import Generator
    from rotation_node.type_aliases import BoolArray, FloatArray, IntArray

    #: What an effect returns: the new stream, and the samples it changed.
    Changed = tuple['SensorStream', BoolArray]

#: ``sensor_msgs/Imu``: covariance element 0 set to -1 means "no estimate".
UNKNOWN_COVARIANCE = -1.0


@dataclasses.dataclass(frozen=True)
class SensorStream:
    """What the simulated sensor reports, one row per sample of the truth."""

    time: np.ndarray                         # (n,) s since the first sample; never changed
    stamp_ns: np.ndarray                     # (n,) int64 header.stamp, ns since the epoch
    orientation: np.ndarray                  # (n, 4)
    angular_velocity: np.ndarray             # (n, 3) body, rad/s
    orientation_covariance: np.ndarray       # (n, 9)
    angular_velocity_covariance: np.ndarray  # (n, 9)
    published: np.ndarray                    # (n,) bool: the sensor message is written

    @classmethod
    def from_truth(cls, time: FloatArray, stamp_ns: IntArray, orientation: FloatArray,
                   angular_velocity: FloatArray) -> SensorStream:
        """Return a perfect sensor: copies of the truth, zero covariances, all published."""
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


def add_gyro_bias(stream: SensorStream, params: GyroBias, rng: Generator,
                  state: dict[str, Any]) -> Changed:
    """Add ``constant`` plus a walk from 0 stepping by N(0, random_walk^2 dt) per axis."""
    later = 'time' in state   # a later block: the walk goes on from its last sample
    time = np.concatenate(([state['time']], stream.time)) if later else stream.time
    steps = rng.standard_normal((len(time) - 1, 3))
    steps *= params.random_walk * np.sqrt(np.diff(time))[:, np.newaxis]
    walk = np.cumsum(np.concatenate((state.get('walk', np.zeros((1, 3))), steps)), axis=0)
    walk = walk[1:] if later else walk
    state['time'], state['walk'] = stream.time[-1], walk[-1:].copy()
    bias = np.asarray(params.constant) + walk
    changed = np.any(bias != 0, axis=1)
    return dataclasses.replace(stream, angular_velocity=stream.angular_velocity + bias), changed


def add_gyro_noise(stream: SensorStream, params: GyroNoise, rng: Generator,
                   state: dict[str, Any]) -> Changed:
    """Add N(0, std^2) white noise to each gyro axis; set its covariance."""
    noise = params.std * rng.standard_normal((len(stream), 3))
    return dataclasses.replace(
        stream, angular_velocity=stream.angular_velocity + noise,
        angular_velocity_covariance=_isotropic_covariance(len(stream), params.std),
    ), np.full(len(stream), params.std > 0)


def add_orientation_noise(stream: SensorStream, params: OrientationNoise, rng: Generator,
                          state: dict[str, Any]) -> Changed:
    """Turn ``q`` into ``q (x) exp(v)``, ``v ~ N(0, std^2 I)`` in the body; set the covariance."""
    v = params.std * rng.standard_normal((len(stream), 3))
    return dataclasses.replace(
        stream, orientation=quaternion_product(stream.orientation,
                                               quaternion_from_rotation_vector(v)),
        orientation_covariance=_isotropic_covariance(len(stream), params.std),
    ), np.full(len(stream), params.std > 0)


def flip_quaternion_signs(stream: SensorStream, params: QuaternionSignFlips, rng: Generator,
                          state: dict[str, Any]) -> Changed:
    """Replace each orientation by ``-q`` with ``probability``."""
    flipped = rng.random(len(stream)) < params.probability
    sign = np.where(flipped, -1.0, 1.0)[:, np.newaxis]
    return dataclasses.replace(stream, orientation=stream.orientation * sign), flipped


def scale_quaternions(stream: SensorStream, params: NonUnitQuaternions, rng: Generator,
                      state: dict[str, Any]) -> Changed:
    """Multiply each orientation by a factor uniform in ``scale``."""
    low, high = params.scale
    factor = rng.uniform(low, high, len(stream))
    return (dataclasses.replace(stream, orientation=stream.orientation * factor[:, np.newaxis]),
            factor != 1.0)


def insert_nan_bursts(stream: SensorStream, params: NanBursts, rng: Generator,
                      state: dict[str, Any]) -> Changed:
    """Set ``fields`` to NaN in bursts of ``length`` samples (overlapping bursts merge)."""
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


def hide_orientation(stream: SensorStream, params: OrientationUnknown, rng: Generator,
                     state: dict[str, Any]) -> Changed:
    """
    Hide the orientation with ``probability``: covariance ``[-1, 0, ...]``, quaternion zero.

    The ``sensor_msgs/Imu`` "no estimate"; a consumer ignoring it fails on the zero quaternion
    rather than use a wrong attitude.
    """
    unknown = rng.random(len(stream)) < params.probability
    orientation = stream.orientation.copy()
    orientation[unknown] = 0.0
    covariance = stream.orientation_covariance.copy()
    covariance[unknown] = 0.0
    covariance[unknown, 0] = UNKNOWN_COVARIANCE
    return dataclasses.replace(stream, orientation=orientation,
                               orientation_covariance=covariance), unknown


def jitter_timestamps(stream: SensorStream, params: TimestampJitter, rng: Generator,
                      state: dict[str, Any]) -> Changed:
    """Offset each stamp by N(0, std^2) s, rounded to ns (may go backwards; order stays)."""
    offset_ns = np.round(params.std * _NS_PER_S * rng.standard_normal(len(stream)))
    offset_ns = offset_ns.astype(np.int64)
    return dataclasses.replace(stream, stamp_ns=stream.stamp_ns + offset_ns), offset_ns != 0


def drop_messages(stream: SensorStream, params: DroppedMessages, rng: Generator,
                  state: dict[str, Any]) -> Changed:
    """Leave each sample unpublished with ``probability``."""
    dropped = rng.random(len(stream)) < params.probability
    return dataclasses.replace(stream, published=stream.published & ~dropped), dropped


#: Effect functions by scene name, in the order they apply.
EFFECTS: dict[str, Callable[..., Changed]] = {
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
    """Return effect ``name``'s generator: independent per name, stable (no Python ``hash``)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=tuple(name.encode())))


class EffectsStream:
    """The scene's effects (``Scene.effects``, seed >= 0) on consecutive blocks of one stream."""

    def __init__(self, effects: Mapping[str, object], seed: int) -> None:
        self._effects: list[tuple[str, Callable[..., Changed], object, np.random.Generator,
                                  dict[str, Any]]] = [
            (name, effect, effects[name], effect_rng(seed, name), {})
            for name, effect in EFFECTS.items() if name in effects]

    def apply(self, stream: SensorStream) -> tuple[SensorStream, dict[str, BoolArray]]:
        """Return the next block with the effects applied, and what each changed in it."""
        changed = {}
        for name, effect, params, rng, state in self._effects:
            stream, changed[name] = effect(stream, params, rng, state)
        return stream, changed
