"""
Simulate a scene: truth and sensor arrays (:func:`simulate`), then an MCAP bag (:func:`write_bag`).

:func:`write_scene_bag` does both in blocks of samples (:func:`simulate_blocks`), in bounded
memory and byte for byte as the two steps would. The bag's contents are the README's "Bag
contents": per sample the ``sensor_msgs/Imu`` (unless dropped) and the truth, log time the
nominal stamp; with a reference, its stream interleaved in stamp order (a sensor sample first
on a tie) and ``<bag>.truth.json`` once the bag is complete. The same scene and seed give a
byte-identical bag (``BagWriter.write`` encodes with zero padding).
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
    """A simulated scene (or a block of it): the truth, the sensor, what each effect changed."""

    scene: Scene
    seed: int
    stamp_ns: np.ndarray                   # (n,) int64 nominal stamps, ns since the epoch
    time: np.ndarray                       # (n,) (stamp_ns - first stamp) / 1e9, s
    truth_orientation: np.ndarray          # (n, 4) unit, continuous in sign
    truth_angular_velocity: np.ndarray     # (n, 3) body, rad/s
    sensor: SensorStream
    effect_masks: Mapping[str, np.ndarray]  # (n,) bool per effect: the samples it changed
    # The reference samples stamped up to this block's last stamp (all remaining in the last).
    reference: Optional[ReferenceBlock] = None


#: Samples simulated and written at a time by :func:`write_scene_bag` (memory is bounded by it).
BLOCK_SAMPLES = 20_000


def sample_stamps_ns(scene: Scene) -> IntArray:
    """Return the nominal stamps ``start_time + k / rate``, k = 0 .. n-1, in ns since the epoch."""
    return stamps_ns(scene.start_time, scene.rate, 0, scene.sample_count)


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
    Yield the :class:`Simulation` of a scene in blocks of up to ``block_samples`` samples.

    Together they are bit for bit what :func:`simulate` returns (the motion's and effects'
    state carries over), in memory independent of the scene's length. ``seed`` (>= 0, else
    ValueError) seeds the effects' random draws.
    """
    seed = _check_seed(seed)
    n, block_samples = scene.sample_count, max(int(block_samples), 1)
    bounds = [(start, min(start + block_samples, n)) for start in range(0, n, block_samples)]
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
    """Return the truth and the sensor stream of a whole scene: :func:`simulate_blocks` in one."""
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
    Write a simulation as a bag: a rosbag2 directory, or one MCAP file if ``path`` ends in .mcap.

    It appears only once complete; a BagError if it exists (unless ``overwrite``) or cannot
    be written.
    """
    _write_simulations(simulation.scene, [simulation], path, overwrite)


def write_scene_bag(scene: Scene, path: StrPath, *, seed: int = 0, overwrite: bool = False,
                    block_samples: int = BLOCK_SAMPLES) -> tuple[int, int]:
    """
    Simulate a scene and write it as a bag in blocks: ``write_bag(simulate(scene, seed), path)``.

    Returns the samples simulated (messages on each truth topic) and the sensor messages
    written. A BagError if the bag or its truth file exists (unless ``overwrite``) or cannot
    be written (``DiskFullError``), nothing left behind; a ValueError for a bad ``seed``.
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
    """Write a block's samples in order, each reference message before the next later sample."""
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
