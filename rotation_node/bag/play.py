"""
Publish the messages of a bag on their topics (``rotation_bag play``).

Messages go out as stored (CDR bytes) in log-time order, spaced as recorded divided by the
rate, under their ROS 2 names; topics of types not installed (or not CDR) are left out with
a note unless named. Rate 0 publishes as fast as the subscribers acknowledge (a deep
reliable queue, acknowledged every ``ACK_BATCH`` messages), losing none. Publishers are
matched a little after they see their subscribers, so ``wait_for_subscribers`` (implied by
rate 0) starts ``DISCOVERY_SETTLE_S`` after every topic has one; ``delay`` waits further.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Callable, List, Optional, Sequence, TYPE_CHECKING

import rclpy
from rclpy.duration import Duration
from rclpy.qos import ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.records import MESSAGE_ENCODING
from rotation_node.command_line.stop_signal import StopSignal
from rotation_node.command_line.topic_arguments import checked_topic_names
from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_class
from rotation_node.wire.qos import DEEP_QUEUE_DEPTH, playback_qos, qos_profiles_from_yaml

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

NODE_NAME = 'rotation_bag_play'
ACK_BATCH = DEEP_QUEUE_DEPTH // 4
ACK_TIMEOUT = Duration(seconds=30)
_POLL_S = 0.05
DISCOVERY_SETTLE_S = 0.5
MIN_RATE = 1e-9                        # a second of the bag then takes about 32 years
MAX_DELAY_S = threading.TIMEOUT_MAX    # what threading can wait for


def _wait(stop, seconds):
    """Sleep ``seconds`` (any length) or until a stop signal."""
    deadline = time.monotonic() + seconds
    while (remaining := deadline - time.monotonic()) > 0:
        if stop.event.wait(min(remaining, 3600.0)):
            return


def _playable_topics(reader, topics, report):
    """
    Return the topics to play: the given ones (all checked), or every topic that can be published.

    A topic of a type not installed, or not CDR, is an error if named, else left out (a note).
    """
    if topics is not None:
        topics = list(topics)
        # A name the bag does not have is checked as a ROS 2 name first: the error says why.
        checked_topic_names(topic for topic in topics
                            if topic not in reader.topics and topic not in reader.renames)
        topics = list(dict.fromkeys(reader.topic_name(topic) for topic in topics))
        for topic in topics:
            _message_class(reader, topic)
        return topics
    playable, left_out = [], []
    for topic in reader.topics:
        try:
            _message_class(reader, topic)
        except BagError:
            left_out.append(topic)
        else:
            playable.append(topic)
    if not playable:
        raise BagError(f'{reader.path} has no topic that can be played (not installed or not '
                       f'CDR: {", ".join(left_out) or "no topics"})')
    if left_out and report is not None:
        report(f'{reader.path}: not playing {", ".join(left_out)} (message type not installed '
               'or not CDR)')
    return playable


def _message_class(reader, topic):
    metadata = reader.topic_metadata[topic]
    if metadata.serialization_format != MESSAGE_ENCODING:
        raise BagError(f'topic {topic} in {reader.path} is serialized as '
                       f'{metadata.serialization_format!r}, not {MESSAGE_ENCODING!r}: '
                       'cannot publish it')
    return message_class(metadata.type_name)


def _publishers(node, reader, topics, lossless):
    """One publisher per topic with the QoS recorded in the bag; message classes checked first."""
    classes = {topic: _message_class(reader, topic) for topic in topics}
    return {topic: node.create_publisher(
        classes[topic], topic,
        playback_qos(qos_profiles_from_yaml(reader.topic_metadata[topic].offered_qos_profiles,
                                            topic=topic), lossless=lossless))
            for topic in topics}


def _wait_for_subscribers(node, publishers, stop):
    waiting = sorted(topic for topic, p in publishers.items() if p.get_subscription_count() == 0)
    if waiting:
        node.get_logger().info(f'waiting for subscribers on {", ".join(waiting)}')
    while waiting and not stop.event.wait(_POLL_S):
        waiting = [topic for topic in waiting if publishers[topic].get_subscription_count() == 0]
    stop.event.wait(DISCOVERY_SETTLE_S)


def _wait_for_acks(publishers):
    for publisher in publishers.values():
        if publisher.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
            publisher.wait_for_all_acked(ACK_TIMEOUT)


def _play_once(reader, topics, publishers, rate, stop):
    """Publish every message once; return how many, or stop early on a signal."""
    count = 0
    start_wall = time.monotonic()
    start_bag = None
    for record in reader.messages(topics):
        if rate > 0:
            if start_bag is None:
                start_bag = record.log_time_ns
            _wait(stop, start_wall + (record.log_time_ns - start_bag) * 1e-9 / rate
                  - time.monotonic())
        if stop.is_set():
            break
        publishers[record.topic].publish(record.data)
        count += 1
        if rate == 0 and count % ACK_BATCH == 0:
            _wait_for_acks(publishers)
    return count


def play(path: StrPath, *, rate: float = 1.0, topics: Optional[Sequence[str]] = None,
         loop: bool = False, delay: float = 0.0, wait_for_subscribers: bool = False,
         ros_args: Optional[List[str]] = None, strict: bool = False,
         report: Optional[Callable[[str], None]] = None) -> int:
    """
    Publish the messages of a bag until it ends (or forever with ``loop``) or Ctrl-C.

    Parameters
    ----------
    path : str or os.PathLike
        The bag: anything :func:`rotation_node.bag.reading.reader.open_bag` reads.
    rate : float, optional
        Speed factor on the recorded timing; 0 publishes as fast as the
        subscribers acknowledge, after waiting for a subscriber on every topic.
    topics : list of str, optional
        Only these topics (names in the bag or their ROS 2 names); by
        default every topic whose type is installed.
    loop : bool, optional
        Start again at the end.
    delay : float, optional
        Seconds to wait before the first message (after the subscribers, if
        waiting for them), so that subscribers can match the new publishers.
    wait_for_subscribers : bool, optional
        Start only once every played topic has a subscriber (always at rate 0).
    ros_args : list of str, optional
        Command line passed to ``rclpy.init`` (``--ros-args ...``).
    strict : bool, optional
        Refuse an unfinished recording or a damaged MCAP file instead of
        playing what it holds.
    report : callable, optional
        ``report(line)`` receives the input's notes (an unfinished recording,
        a renamed topic, topics left out) before anything is published, then
        what reading found could not be read.

    Returns
    -------
    int
        Messages published.

    Raises
    ------
    BagError
        If the bag is unreadable, a topic is not in it or not a valid name, a
        type is not installed, the rate is neither 0 nor in ``[MIN_RATE, inf)``
        or the delay not in ``[0, MAX_DELAY_S]``; nothing is published then.

    """
    if not (rate == 0 or MIN_RATE <= rate < math.inf):
        raise BagError(f'rate must be 0 or a finite number >= {MIN_RATE:g}, got {rate}')
    if not 0 <= delay <= MAX_DELAY_S:
        raise BagError(f'delay must be a number of seconds in [0, {MAX_DELAY_S:.4g}], '
                       f'got {delay}')
    with open_bag(path, strict=strict) as reader:
        reader.report_notes(report)
        topics = _playable_topics(reader, topics, report)
        rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = rclpy.create_node(NODE_NAME)
            with StopSignal() as stop:
                publishers = _publishers(node, reader, topics, lossless=rate == 0)
                if rate == 0 or wait_for_subscribers:
                    _wait_for_subscribers(node, publishers, stop)
                _wait(stop, delay)
                count = 0
                with reader.reporting_new_notes(report):
                    while True:
                        published = _play_once(reader, topics, publishers, rate, stop)
                        count += published
                        if not loop or published == 0 or stop.is_set():
                            break
                if not stop.is_set():
                    _wait_for_acks(publishers)
            node.get_logger().info(f'published {count} messages from {path}')
            node.destroy_node()
            return count
        finally:
            rclpy.try_shutdown()
