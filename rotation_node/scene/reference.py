"""
A scene's reference stream: the same motion seen by a second system, and its truth file.

``q_ref(t) = q_W (x) q(t + dt) (x) q_M (x) exp(v)``: the convention of ``rotation_bag
compare`` (``R_ref(t) = W R_est(t + dt) M``, README "A second stream of the same motion")
with the reference's own body-frame noise ``v``. :class:`ReferenceStream` computes it block by
block of the sensor's stamps, so that both streams are written interleaved in bounded memory;
:func:`truth_record` is what ``<bag>.truth.json`` (:func:`truth_path`) holds.
"""
from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, TYPE_CHECKING

import numpy as np
from rotation_node.conversions import (
    quaternion_conjugate, quaternion_from_rotation_vector, quaternion_product, rotate_vector)
from rotation_node.wire.stamps import NS_PER_S as _NS_PER_S

from .effects import effect_rng
from .motions import MotionStream
from .spec import GyroNoise, OrientationNoise, Reference, Scene, stamps_ns, start_stamp_ns

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

#: The truth file's name: the bag's path with this appended.
TRUTH_SUFFIX = '.truth.json'

#: Message type of each ``reference.message``.
REFERENCE_TYPES = {'pose': 'geometry_msgs/msg/PoseStamped', 'imu': 'sensor_msgs/msg/Imu'}

#: The truth file's statement of the convention.
CONVENTION = ('R_ref(t) = W . R_est(t + time_offset_s) . M; R body-to-world; '
              'W = world_alignment, M = mounting; quaternions [x, y, z, w]')

_PRE_ROLL_SAMPLES = 20_000


def truth_path(bag_path: StrPath) -> str:
    """Return the truth file of a bag: ``<bag>.truth.json`` beside it (a directory's too)."""
    return os.fspath(bag_path).rstrip('/') + TRUTH_SUFFIX


def reference_index_range(scene: Scene) -> tuple[int, int]:
    """Return ``(first, stop)``: the samples ``k`` with ``k / rate`` and ``+ dt`` in the scene."""
    reference = _reference(scene)
    dt, rate, duration = reference.time_offset, reference.rate, scene.duration
    low, high = max(0.0, -dt), min(duration, duration - dt)
    first = math.ceil(low * rate - 1e-9 * max(1.0, low * rate))
    last = math.floor(high * rate + 1e-9 * max(1.0, high * rate))
    return first, max(first, last + 1)


def _reference(scene):
    if scene.reference is None:
        raise ValueError('the scene has no reference stream')
    return scene.reference


def reference_stamps_ns(scene: Scene, start: int, stop: int) -> np.ndarray:
    """Return the stamps of reference samples ``start .. stop-1``, ns since the epoch."""
    return stamps_ns(scene.start_time, _reference(scene).rate, start, stop)


@dataclasses.dataclass(frozen=True)
class ReferenceBlock:
    """Consecutive samples of the reference stream."""

    stamp_ns: np.ndarray                # (n,) header.stamp and log time
    motion_time: np.ndarray             # (n,) s since start_time, plus time_offset
    orientation: np.ndarray             # (n, 4) q_W (x) q(motion_time) (x) q_M (x) exp(noise)
    angular_velocity: np.ndarray        # (n, 3) the reference body's, M^T w(motion_time)
    orientation_covariance: np.ndarray  # (9,) std^2 I row-major

    def __len__(self) -> int:
        return len(self.stamp_ns)


class ReferenceStream:
    """A scene's reference stream in blocks; its noise has its own generator (``seed``)."""

    def __init__(self, scene: Scene, seed: int) -> None:
        self.reference: Reference = _reference(scene)
        self._scene = scene
        self._next, self._stop = reference_index_range(scene)
        self._first_ns = start_stamp_ns(scene.start_time)
        self._motion = MotionStream(scene.motion, scene.duration, 1.0 / self.reference.rate)
        self._rng = effect_rng(seed, 'reference.orientation_noise')
        self._started = False

    def until(self, limit_ns: int) -> ReferenceBlock:
        """Return the next samples stamped at or before ``limit_ns`` (at most all remaining)."""
        reference = self.reference
        start = self._next
        # Every stamp up to limit_ns, and at least one more unless the stream ends first.
        ahead = math.floor((limit_ns - self._first_ns) * reference.rate / _NS_PER_S) + 2
        candidates = reference_stamps_ns(self._scene, start, max(start, min(ahead, self._stop)))
        stop = start + int(np.searchsorted(candidates, limit_ns, side='right'))
        stamp_ns = candidates[:stop - start]
        self._next = stop
        motion_time = (stamp_ns - self._first_ns) / _NS_PER_S + reference.time_offset
        n = len(stamp_ns)
        if n == 0:
            return ReferenceBlock(stamp_ns, motion_time, np.zeros((0, 4)), np.zeros((0, 3)),
                                  np.zeros(9))
        if not self._started:   # run the motion from 0 (where the integrator starts) up to it
            self._started = True
            times = np.arange(0.0, float(motion_time[0]), 1.0 / reference.rate)
            for first in range(0, len(times), _PRE_ROLL_SAMPLES):
                self._motion.truth(times[first:first + _PRE_ROLL_SAMPLES])
        q, w = self._motion.truth(motion_time)
        std = reference.orientation_noise
        q = quaternion_product(quaternion_product(reference.world_alignment, q),
                               reference.mounting)
        noise = std * self._rng.standard_normal((n, 3))
        if std > 0:
            q = quaternion_product(q, quaternion_from_rotation_vector(noise))
        w = rotate_vector(quaternion_conjugate(reference.mounting), w)
        covariance = (std * std * np.eye(3)).ravel()
        return ReferenceBlock(stamp_ns, motion_time, q, w, covariance)


def truth_record(scene: Scene, seed: int, reference_messages: int,
                 estimate_messages: int) -> dict[str, Any]:
    """Return ``<bag>.truth.json``, keyed as ``rotation_bag compare --json`` writes estimates."""
    reference = _reference(scene)
    noise = scene.effects.get('orientation_noise')
    gyro = scene.effects.get('gyro_noise')
    assert noise is None or isinstance(noise, OrientationNoise)
    assert gyro is None or isinstance(gyro, GyroNoise)
    return {
        'convention': CONVENTION,
        'reference': {'topic': reference.topic, 'type': REFERENCE_TYPES[reference.message],
                      'frame_id': reference.frame_id, 'rate_hz': reference.rate,
                      'messages': reference_messages},
        'estimate': {'topic': scene.topic, 'type': 'sensor_msgs/msg/Imu',
                     'frame_id': scene.frame_id, 'rate_hz': scene.rate,
                     'messages': estimate_messages},
        'time_offset_s': reference.time_offset,
        'mounting': {'quaternion': list(reference.mounting)},
        'world_alignment': {'quaternion': list(reference.world_alignment)},
        'noise': {
            'reference_orientation_std_rad': reference.orientation_noise,
            'estimate_orientation_std_rad': 0.0 if noise is None else noise.std,
            'estimate_gyro_std_rad_s': 0.0 if gyro is None else gyro.std,
        },
        'motion': scene.motion.type,
        'duration_s': scene.duration,
        'seed': seed,
    }
