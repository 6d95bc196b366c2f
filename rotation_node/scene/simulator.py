"""
Simulate a scene: truth and sensor arrays (:func:`simulate`), then an MCAP bag (:func:`write_bag`).

The bag holds, for every sample ``k`` at the nominal stamp
``start_time + k / rate`` (rounded to ns):

- ``sensor_msgs/Imu`` on the scene's topic, unless ``dropped_messages``
  dropped it: orientation, body angular velocity and their covariances from
  the sensor stream; ``header.stamp`` is the sensor stamp (jittered by
  ``timestamp_jitter``); linear acceleration is not simulated: zeros with
  ``linear_acceleration_covariance[0] = -1`` ("no estimate").
- ``geometry_msgs/QuaternionStamped`` on ``/truth/orientation`` and
  ``geometry_msgs/Vector3Stamped`` (body angular velocity, rad/s) on
  ``/truth/angular_velocity``, always, with the nominal stamp.

Every message has ``header.frame_id`` = the scene's ``frame_id`` and log time
= the nominal stamp, so a bag replays in sample order; the same scene and
seed give a byte-identical bag (``BagWriter.write`` encodes these types with
zero padding, see :mod:`rotation_node.bag.cdr`).
"""
from __future__ import annotations

import dataclasses
from typing import Mapping, TYPE_CHECKING

import numpy as np
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from sensor_msgs.msg import Imu

from rotation_node.bag.mcap_io import BagWriter
from rotation_node.stamps import NS_PER_S as _NS_PER_S
from rotation_node.stamps import time_message as _time_message

from .effects import UNKNOWN_COVARIANCE, SensorStream, apply_effects
from .motions import motion_truth
from .spec import TRUTH_ANGULAR_VELOCITY_TOPIC, TRUTH_ORIENTATION_TOPIC, Scene

if TYPE_CHECKING:
    from rotation_node.type_aliases import IntArray, StrPath


@dataclasses.dataclass(frozen=True)
class Simulation:
    """
    A simulated scene: the truth, what the sensor reports, and what each effect changed.

    Attributes
    ----------
    scene : Scene
    seed : int
    stamp_ns : ndarray of int64, shape (n,)
        Nominal sample stamps, ns since the Unix epoch: the truth's
        ``header.stamp`` and every message's log time.
    time : ndarray, shape (n,)
        ``(stamp_ns - stamp_ns[0]) / 1e9``, s: the times the motion was evaluated at.
    truth_orientation : ndarray, shape (n, 4)
        Unit quaternions (x, y, z, w), body-to-world, continuous in sign.
    truth_angular_velocity : ndarray, shape (n, 3)
        Body angular velocity, rad/s.
    sensor : SensorStream
        The sensor's stamps, orientation, angular velocity, covariances and
        ``published`` mask; equal to the truth when the scene has no effects.
    effect_masks : Mapping[str, ndarray of bool, shape (n,)]
        For each effect of the scene, the samples it changed.
    """

    scene: Scene
    seed: int
    stamp_ns: np.ndarray
    time: np.ndarray
    truth_orientation: np.ndarray
    truth_angular_velocity: np.ndarray
    sensor: SensorStream
    effect_masks: Mapping[str, np.ndarray]


def sample_stamps_ns(scene: Scene) -> IntArray:
    """
    Return the nominal stamps ``start_time + k / rate``, k = 0 .. n-1, in ns since the epoch.

    ``start_time`` is read as whole seconds plus a fraction rounded to ns.

    Returns
    -------
    ndarray of int64, shape (n,)
    """
    whole_seconds = int(scene.start_time // 1)
    start_ns = whole_seconds * _NS_PER_S + round((scene.start_time - whole_seconds) * _NS_PER_S)
    offsets = np.round(np.arange(scene.sample_count) * (_NS_PER_S / scene.rate))
    return start_ns + offsets.astype(np.int64)


def simulate(scene: Scene, seed: int = 0) -> Simulation:
    """
    Return the truth and the sensor stream of a scene, as arrays.

    Parameters
    ----------
    scene : Scene
        A validated scene (:func:`rotation_node.scene.spec.load_scene`).
    seed : int, optional
        Seed of the effects' random draws, >= 0. Default 0.

    Returns
    -------
    Simulation

    Raises
    ------
    ValueError
        If ``seed`` is not a non-negative integer.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f'seed must be a non-negative integer, got {seed!r}')
    stamp_ns = sample_stamps_ns(scene)
    time = (stamp_ns - stamp_ns[0]) / _NS_PER_S
    q, w = motion_truth(scene.motion, time, scene.duration)
    sensor, masks = apply_effects(SensorStream.from_truth(time, stamp_ns, q, w),
                                  scene.effects, int(seed))
    return Simulation(scene=scene, seed=int(seed), stamp_ns=stamp_ns, time=time,
                      truth_orientation=q, truth_angular_velocity=w,
                      sensor=sensor, effect_masks=masks)


def _set_quaternion(message, q):
    message.x, message.y, message.z, message.w = (float(c) for c in q)


def _set_vector(message, v):
    message.x, message.y, message.z = (float(c) for c in v)


def _imu_message(sensor, k, frame_id):
    """Return sample ``k`` of the sensor stream as a ``sensor_msgs/Imu``."""
    msg = Imu()
    msg.header.stamp = _time_message(sensor.stamp_ns[k])
    msg.header.frame_id = frame_id
    _set_quaternion(msg.orientation, sensor.orientation[k])
    msg.orientation_covariance = sensor.orientation_covariance[k]
    _set_vector(msg.angular_velocity, sensor.angular_velocity[k])
    msg.angular_velocity_covariance = sensor.angular_velocity_covariance[k]
    msg.linear_acceleration_covariance[0] = UNKNOWN_COVARIANCE
    return msg


def write_bag(simulation: Simulation, path: StrPath, *, overwrite: bool = False) -> None:
    """
    Write a simulation as a ROS 2 MCAP bag (the layout in this module's docstring).

    Parameters
    ----------
    simulation : Simulation
    path : str or os.PathLike
        The ``.mcap`` file; it appears only once completely written.
    overwrite : bool, optional
        Replace an existing file. Default False.

    Raises
    ------
    BagError
        If ``path`` exists (and not ``overwrite``) or cannot be written.
    """
    sensor = simulation.sensor
    frame_id = simulation.scene.frame_id
    topic = simulation.scene.topic
    with BagWriter(path, overwrite=overwrite) as writer:
        for k, stamp_ns in enumerate(simulation.stamp_ns.tolist()):
            if sensor.published[k]:
                writer.write(topic, _imu_message(sensor, k, frame_id), stamp_ns)
            orientation = QuaternionStamped()
            orientation.header.stamp = _time_message(stamp_ns)
            orientation.header.frame_id = frame_id
            _set_quaternion(orientation.quaternion, simulation.truth_orientation[k])
            writer.write(TRUTH_ORIENTATION_TOPIC, orientation, stamp_ns)
            angular_velocity = Vector3Stamped()
            angular_velocity.header = orientation.header
            _set_vector(angular_velocity.vector, simulation.truth_angular_velocity[k])
            writer.write(TRUTH_ANGULAR_VELOCITY_TOPIC, angular_velocity, stamp_ns)
