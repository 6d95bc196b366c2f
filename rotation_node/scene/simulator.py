"""
Simulate a scene: truth and sensor arrays (:func:`simulate`), then an MCAP bag (:func:`write_bag`).

:func:`write_scene_bag` does both in blocks of samples (:func:`simulate_blocks`),
so that a scene of any length is written in bounded memory, byte for byte as
the two steps would write it.

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
zero padding, see :mod:`rotation_node.wire.cdr`).

A scene with a ``reference`` also gets its second stream
(:mod:`rotation_node.scene.reference`) on the reference's topic, with the
reference's ``frame_id``, log time = its stamp, interleaved in stamp order
(a sensor sample first on a tie), and its truth in ``<bag>.truth.json``,
which :func:`write_scene_bag` writes beside the bag when the bag is complete.
"""
from __future__ import annotations

import dataclasses
import json
from typing import Iterator, Mapping, Optional, TYPE_CHECKING

from geometry_msgs.msg import PoseStamped, QuaternionStamped, Vector3Stamped
import numpy as np
from rotation_node.bag.writing.atomic_file import AtomicFile
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.command_line.stop_signal import raise_if_stopped
from rotation_node.wire.stamps import NS_PER_S as _NS_PER_S
from rotation_node.wire.stamps import time_message as _time_message
from sensor_msgs.msg import Imu

from .effects import EffectsStream, SensorStream, UNKNOWN_COVARIANCE
from .motions import longest_interval, MotionStream
from .reference import ReferenceBlock, ReferenceStream, truth_path, truth_record
from .spec import (
    Scene, stamps_ns, start_stamp_ns, TRUTH_ANGULAR_VELOCITY_TOPIC, TRUTH_ORIENTATION_TOPIC)

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
    reference : ReferenceBlock or None
        The reference stream's samples stamped up to this block's last stamp
        (after the previous block's), to the end of the stream in the last
        block; None when the scene has no reference.

    """

    scene: Scene
    seed: int
    stamp_ns: np.ndarray
    time: np.ndarray
    truth_orientation: np.ndarray
    truth_angular_velocity: np.ndarray
    sensor: SensorStream
    effect_masks: Mapping[str, np.ndarray]
    reference: Optional[ReferenceBlock] = None


#: Samples simulated and written at a time by :func:`write_scene_bag` (memory is bounded by it).
BLOCK_SAMPLES = 20_000


def sample_stamps_ns(scene: Scene) -> IntArray:
    """Return the nominal stamps ``start_time + k / rate``, k = 0 .. n-1, in ns since the epoch."""
    return stamps_ns(scene.start_time, scene.rate, 0, scene.sample_count)


def _block_bounds(scene, block_samples):
    n = scene.sample_count
    return [(start, min(start + block_samples, n)) for start in range(0, n, block_samples)]


def _longest_interval(scene, bounds):
    """Return the longest interval between consecutive sample times, s, computed block by block."""
    first_ns = start_stamp_ns(scene.start_time)
    longest, previous = 0.0, None
    for start, stop in bounds:
        time = (stamps_ns(scene.start_time, scene.rate, start, stop) - first_ns) / _NS_PER_S
        linked = time if previous is None else np.concatenate(([previous], time))
        longest = max(longest, longest_interval(linked))
        previous = time[-1]
    return longest


def _check_seed(seed):
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f'seed must be a non-negative integer, got {seed!r}')
    return int(seed)


def simulate_blocks(scene: Scene, seed: int = 0,
                    block_samples: int = BLOCK_SAMPLES) -> Iterator[Simulation]:
    """
    Yield the simulation of a scene in consecutive blocks of samples.

    Each block is a :class:`Simulation` of up to ``block_samples`` consecutive
    samples; taken together they are bit for bit what :func:`simulate`
    returns (the motion's and the effects' state carries over from block to
    block), so memory does not depend on the scene's length.

    Parameters
    ----------
    scene : Scene
        A validated scene.
    seed : int, optional
        Seed of the effects' random draws, >= 0. Default 0.
    block_samples : int, optional
        Samples per block (the last block may be shorter).

    Yields
    ------
    Simulation

    Raises
    ------
    ValueError
        If ``seed`` is not a non-negative integer.

    """
    seed = _check_seed(seed)
    bounds = _block_bounds(scene, max(int(block_samples), 1))
    longest = _longest_interval(scene, bounds) if len(bounds) > 1 else None
    first_ns = start_stamp_ns(scene.start_time)
    motion: Optional[MotionStream] = None
    effects: Optional[EffectsStream] = None
    reference = None if scene.reference is None else ReferenceStream(scene, seed)
    for start, stop in bounds:
        stamp_ns = stamps_ns(scene.start_time, scene.rate, start, stop)
        time = (stamp_ns - first_ns) / _NS_PER_S
        if motion is None or effects is None:
            motion = MotionStream(scene.motion, scene.duration,
                                  longest_interval(time) if longest is None else longest)
            effects = EffectsStream(scene.effects, seed)
        q, w = motion.truth(time)
        sensor, masks = effects.apply(SensorStream.from_truth(time, stamp_ns, q, w))
        reference_block = None
        if reference is not None:
            reference_block = reference.until(
                int(stamp_ns[-1]) if stop < bounds[-1][1] else np.iinfo(np.int64).max)
        yield Simulation(scene=scene, seed=seed, stamp_ns=stamp_ns, time=time,
                         truth_orientation=q, truth_angular_velocity=w,
                         sensor=sensor, effect_masks=masks, reference=reference_block)


def simulate(scene: Scene, seed: int = 0) -> Simulation:
    """
    Return the truth and the sensor stream of a whole scene, as arrays.

    :func:`simulate_blocks` in one block: ``scene`` validated
    (:func:`rotation_node.scene.spec.load_scene`), ``seed`` (>= 0, else ValueError)
    seeding the effects' random draws.
    """
    simulation, = simulate_blocks(scene, seed, block_samples=scene.sample_count)
    return simulation


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
        What :func:`simulate` returned.
    path : str or os.PathLike
        A rosbag2 directory, or a single MCAP file if it ends in ``.mcap``;
        it appears only once completely written.
    overwrite : bool, optional
        Replace an existing file. Default False.

    Raises
    ------
    BagError
        If ``path`` exists (and not ``overwrite``) or cannot be written.

    """
    _write_simulations(simulation.scene, [simulation], path, overwrite)


def write_scene_bag(scene: Scene, path: StrPath, *, seed: int = 0, overwrite: bool = False,
                    block_samples: int = BLOCK_SAMPLES) -> tuple[int, int]:
    """
    Simulate a scene and write it as a bag, streaming: memory does not grow with its length.

    The bag is byte for byte what ``write_bag(simulate(scene, seed), path)`` writes.

    Parameters
    ----------
    scene : Scene
        A validated scene.
    path : str or os.PathLike
        A rosbag2 directory, or a single MCAP file if it ends in ``.mcap``;
        it appears only once completely written.
    seed : int, optional
        Seed of the effects' random draws, >= 0. Default 0.
    overwrite : bool, optional
        Replace an existing bag. Default False.
    block_samples : int, optional
        Samples simulated at a time.

    A scene with a ``reference`` also gets its stream in the bag and its truth
    in ``<path>.truth.json`` (:func:`rotation_node.scene.reference.truth_path`),
    which appears once the bag is complete.

    Returns
    -------
    samples : int
        Samples simulated (messages on each truth topic).
    published : int
        Sensor messages written.

    Raises
    ------
    BagError
        If ``path`` (or the truth file) exists (and not ``overwrite``) or
        cannot be written (``DiskFullError`` when the disk fills); nothing is
        left behind.
    ValueError
        If ``seed`` is not a non-negative integer.

    """
    return _write_simulations(scene, simulate_blocks(scene, _check_seed(seed), block_samples),
                              path, overwrite)


def _write_simulations(scene, simulations, path, overwrite):
    """Write the blocks ``simulations`` as one bag, and its truth file if it has a reference."""
    truth = (None if scene.reference is None
             else AtomicFile(truth_path(path), overwrite=overwrite))
    samples = published = references = 0
    seed = 0
    try:
        with BagWriter(path, overwrite=overwrite) as writer:
            for simulation in simulations:
                _write_samples(writer, simulation)
                seed = simulation.seed
                samples += len(simulation.time)
                published += int(simulation.sensor.published.sum())
                references += 0 if simulation.reference is None else len(simulation.reference)
            raise_if_stopped()   # the last chance before the bag is committed
        if truth is not None:
            record = truth_record(scene, seed, references, published)
            truth.stream.write((json.dumps(record, indent=2) + '\n').encode())
            truth.commit()
    finally:
        if truth is not None and not truth.closed:
            truth.discard()
    return samples, published


def _reference_message(scene, block, j):
    """Return sample ``j`` of a reference block as its message type."""
    reference = scene.reference
    if reference.message == 'imu':
        msg = Imu()
        _set_quaternion(msg.orientation, block.orientation[j])
        msg.orientation_covariance = block.orientation_covariance
        _set_vector(msg.angular_velocity, block.angular_velocity[j])
        msg.linear_acceleration_covariance[0] = UNKNOWN_COVARIANCE
    else:
        msg = PoseStamped()
        _set_quaternion(msg.pose.orientation, block.orientation[j])
    msg.header.stamp = _time_message(block.stamp_ns[j])
    msg.header.frame_id = reference.frame_id
    return msg


def _write_samples(writer, simulation):
    """
    Write every sample of ``simulation`` (one block or all) in sample order.

    With a block of the reference stream, its messages are interleaved by
    stamp, each before the first sensor sample stamped later than it.
    """
    sensor = simulation.sensor
    scene = simulation.scene
    frame_id = scene.frame_id
    topic = scene.topic
    reference = simulation.reference
    pending = [] if reference is None else reference.stamp_ns.tolist()
    j = 0
    for k, stamp_ns in enumerate(simulation.stamp_ns.tolist()):
        raise_if_stopped()
        while j < len(pending) and pending[j] < stamp_ns:
            writer.write(scene.reference.topic, _reference_message(scene, reference, j),
                         pending[j])
            j += 1
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
    for j in range(j, len(pending)):
        writer.write(scene.reference.topic, _reference_message(scene, reference, j), pending[j])
