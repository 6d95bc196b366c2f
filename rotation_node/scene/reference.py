"""
A scene's reference stream: the same motion seen by a second system, and its truth file.

Convention (the one of ``rotation_bag compare``; R maps body to world)::

    R_ref(t) = W . R_est(t + time_offset_s) . M

``R_est`` is the scene's sensor stream without its effects (the truth at the
sensor's stamps), ``R_ref`` the reference stream at its own stamps ``t``
(seconds since the epoch), ``W = world_alignment`` (the sensor's world frame
in the reference's world frame) and ``M = mounting`` (the reference body in
the sensor's body frame). A positive ``time_offset_s`` means the reference's
stamps are late: the reference at ``t`` shows the motion the sensor shows at
``t + time_offset_s``. With quaternions (x, y, z, w):
``q_ref(t) = q_W (x) q(t + dt) (x) q_M``, then the reference's own
orientation noise ``q_ref (x) exp(v)``, ``v ~ N(0, std^2 I)`` in the
reference's body frame.

:class:`ReferenceStream` computes the stream block by block of the sensor's
stamps, so that the simulator writes both streams interleaved in stamp order in
bounded memory; :func:`truth_record` is what ``<bag>.truth.json`` holds
(:func:`truth_path`).
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
    """
    Return ``(first, stop)``: the reference samples ``k`` are ``first <= k < stop``.

    Sample ``k`` is stamped ``start_time + k / rate`` and shows the motion at
    ``k / rate + time_offset``; both lie in ``[0, duration]`` of the scene.
    """
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
    """
    Consecutive samples of the reference stream.

    Attributes
    ----------
    stamp_ns : ndarray of int64, shape (n,)
        ``header.stamp`` (and log time) of each message.
    motion_time : ndarray, shape (n,)
        The times the motion was evaluated at: stamp since ``start_time``, plus
        ``time_offset``, s.
    orientation : ndarray, shape (n, 4)
        ``q_W (x) q(motion_time) (x) q_M (x) exp(noise)``, (x, y, z, w).
    angular_velocity : ndarray, shape (n, 3)
        The reference body's angular velocity ``M^T w(motion_time)``, rad/s.
    orientation_covariance : ndarray, shape (9,)
        ``std^2 I`` row-major (zeros without noise).

    """

    stamp_ns: np.ndarray
    motion_time: np.ndarray
    orientation: np.ndarray
    angular_velocity: np.ndarray
    orientation_covariance: np.ndarray

    def __len__(self) -> int:
        return len(self.stamp_ns)


class ReferenceStream:
    """
    The reference stream of a scene, in blocks: ``until(stamp_ns)`` returns the next samples.

    Parameters
    ----------
    scene : Scene
        A validated scene with a ``reference``.
    seed : int
        The scene seed: the noise draws from its own generator
        (``effect_rng(seed, 'reference.orientation_noise')``).

    """

    def __init__(self, scene: Scene, seed: int) -> None:
        self.reference: Reference = _reference(scene)
        self._scene = scene
        self._next, self._stop = reference_index_range(scene)
        self._first_ns = start_stamp_ns(scene.start_time)
        self._motion = MotionStream(scene.motion, scene.duration, 1.0 / self.reference.rate)
        self._rng = effect_rng(seed, 'reference.orientation_noise')
        self._started = False

    def _pre_roll(self, first_time):
        """Run the motion from 0 to just before ``first_time`` (the integrator starts at 0)."""
        step = 1.0 / self.reference.rate
        times = np.arange(0.0, first_time, step)
        for start in range(0, len(times), _PRE_ROLL_SAMPLES):
            self._motion.truth(times[start:start + _PRE_ROLL_SAMPLES])

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
        if not self._started:
            self._started = True
            if motion_time[0] > 0.0:
                self._pre_roll(float(motion_time[0]))
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
    """
    Return what ``<bag>.truth.json`` holds: the convention, both streams, dt, W, M, noise.

    ``time_offset_s``, ``mounting.quaternion`` and ``world_alignment.quaternion``
    are keyed as ``rotation_bag compare --json`` writes its estimates.
    """
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
