"""
Record live topics into an MCAP bag (``rotation_bag record``).

A topic is subscribed once it has a publisher, with a QoS every publisher is compatible
with; messages are stored as received, with the node clock at reception as log time and the
DDS source timestamp as publish time, as rosbag2 does. The bag is crash-safe and closed
with what fitted when the disk fills.
"""
from __future__ import annotations

import functools
import math
import time
from typing import Any, Dict, Iterable, List, Optional, Sequence, TYPE_CHECKING

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing.writer import BagWriter, CHUNK_PERIOD_S, DEFAULT_COMPRESSION
from rotation_node.command_line.stop_signal import StopSignal
from rotation_node.command_line.topic_arguments import checked_topic_names
from rotation_node.errors import BagError, DiskFullError
from rotation_node.wire.message_types import message_class
from rotation_node.wire.qos import qos_profiles_yaml, recording_qos

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

NODE_NAME = 'rotation_bag_record'
DISCOVERY_PERIOD_S = 0.1
DRAIN_LIMIT_S = 0.5   # longest time spent writing what was received, once stopped
_SPIN_PERIOD_S = 0.05


class BagRecorder(Node):
    """
    A node that subscribes to topics as they appear and writes them to ``writer``.

    Relative names are resolved in the node's namespace, remappings apply; ``counts`` is
    ``{topic: messages written}`` of the subscribed topics, ``pending_topics`` the others.
    """

    def __init__(self, writer: BagWriter, topics: Iterable[str], *, node_name: str = NODE_NAME,
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)   # kwargs: rclpy Node's (context, namespace...)
        self._writer = writer
        self.pending_topics = [self.resolve_topic_name(topic) for topic in topics]
        self.counts: Dict[str, int] = {}
        self._discovery = self.create_timer(DISCOVERY_PERIOD_S, self._discover)
        self._discover()

    def _discover(self):
        types = dict(self.get_topic_names_and_types())
        for topic in [t for t in self.pending_topics if t in types]:
            offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
            if not offered:
                continue   # only subscribers so far: wait for a publisher's QoS
            type_name = types[topic][0]
            if len(types[topic]) > 1:
                self.get_logger().warning(
                    f'{topic} has several types {types[topic]}; recording {type_name}')
            self._writer.add_topic(TopicMetadata(topic, type_name, qos_profiles_yaml(offered)))
            self.create_subscription(
                message_class(type_name), topic, functools.partial(self._write, topic, type_name),
                recording_qos(offered), raw=True)
            self.counts[topic] = 0
            self.pending_topics.remove(topic)
            self.get_logger().info(f'recording {topic} ({type_name})')
        if not self.pending_topics:
            self._discovery.cancel()

    def _write(self, topic, type_name, data, info):
        log_time_ns = self.get_clock().now().nanoseconds
        self._writer.write_serialized(topic, type_name, data, log_time_ns,
                                      info['source_timestamp'] or log_time_ns)
        self.counts[topic] += 1


def _drain(executor, recorder):
    """Write what the subscriptions already received, until two idle spins or DRAIN_LIMIT_S."""
    deadline = time.monotonic() + DRAIN_LIMIT_S
    idle = 0
    while idle < 2 and time.monotonic() < deadline:
        before = sum(recorder.counts.values())
        executor.spin_once(timeout_sec=0.005)
        idle = idle + 1 if sum(recorder.counts.values()) == before else 0


def _spin(executor, writer, stop, deadline):
    """Record until ``stop`` or ``deadline``; write a chunk at least every ``CHUNK_PERIOD_S``."""
    while not stop.is_set() and (remaining := deadline - time.monotonic()) > 0:
        executor.spin_once(timeout_sec=min(_SPIN_PERIOD_S, remaining))
        writer.flush_if_due()


def record(output: StrPath, topics: Sequence[str], *, duration: Optional[float] = None,
           overwrite: bool = False, compression: str = DEFAULT_COMPRESSION,
           ros_args: Optional[List[str]] = None) -> Dict[str, int]:
    """
    Record ``topics`` into ``output`` until Ctrl-C, SIGTERM, ``duration`` or a full disk.

    The bag is closed cleanly on every one of these, so it is always valid;
    messages already received by then are written first (for at most
    ``DRAIN_LIMIT_S``).

    Parameters
    ----------
    output : str or os.PathLike
        The bag: a rosbag2 directory, or a single MCAP file if it ends in ``.mcap``.
    topics : list of str
        The topics to record.
    duration : float, optional
        Seconds to record; until stopped by a signal by default.
    overwrite : bool, optional
        Replace an existing ``output``.
    compression : str, optional
        Chunk compression, ``'zstd'`` (default, as rosbag2), ``'lz4'`` or ``'none'``.
    ros_args : list of str, optional
        Command line passed to ``rclpy.init`` (``--ros-args ...``).

    Returns
    -------
    dict
        ``{topic: messages recorded}``; topics that never appeared are absent.

    Raises
    ------
    DiskFullError
        If the disk filled: the bag was closed with the messages that fitted
        (``kept``); recording stopped.
    BagError
        If ``output`` exists (without ``overwrite``), ``duration`` is not
        positive or a topic name is invalid, before anything is written.
        Should writing fail otherwise, what was flushed stays in ``<output>.part``.

    """
    if duration is not None and not (0 < duration < math.inf):
        raise BagError(f'duration must be a finite number of seconds > 0, got {duration}')
    topics = checked_topic_names(topics)
    rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        with StopSignal() as stop, BagWriter(output, overwrite=overwrite, compression=compression,
                                             keep_unfinished=True,
                                             chunk_period_s=CHUNK_PERIOD_S) as writer:
            recorder = BagRecorder(writer, topics)
            executor = SingleThreadedExecutor()
            executor.add_node(recorder)
            deadline = math.inf if duration is None else time.monotonic() + duration
            disk_full = None
            try:
                try:
                    _spin(executor, writer, stop, deadline)
                    _drain(executor, recorder)
                except DiskFullError as error:
                    disk_full = error
                for topic in recorder.pending_topics:
                    recorder.get_logger().warning(f'{topic} never had a publisher; not recorded')
            finally:
                executor.shutdown()
                recorder.destroy_node()
        if disk_full is not None:
            raise DiskFullError(
                f'disk full: recording stopped, kept {writer.message_count} messages in '
                f'{output} ({disk_full.dropped} received messages not written)',
                kept=writer.message_count, dropped=disk_full.dropped)
        return writer.message_counts
    finally:
        rclpy.try_shutdown()
