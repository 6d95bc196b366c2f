"""
Tests of rotation_node.rclpy_private: each private rclpy API still exists and behaves as used.

A new rclpy release that renames, removes or changes one of them fails here, with its
name, before the node or the bag tools fail in use.
"""
from importlib import metadata
import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.utilities import remove_ros_args
from rotation_node import rclpy_private
from std_msgs.msg import String


def test_the_installed_rclpy_is_a_checked_version():
    # A release outside the range: check each API below against its sources, then add it.
    assert metadata.version('rclpy') in rclpy_private.CHECKED_RCLPY_VERSIONS


def test_malformed_ros_arguments_raise_rcl_error():
    with pytest.raises(rclpy_private.RCLError, match='No file path provided'):
        remove_ros_args(['x', '--ros-args', '--params-file'])


def test_bytes_that_are_no_message_raise_rmw_error():
    with pytest.raises(rclpy_private.RMWError):
        deserialize_message(b'\x00\x01\x00\x00\xff\xff\xff\x7f', String)


@pytest.fixture
def node():
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('rclpy_private_test', context=context)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize('raw', [False, True])
def test_take_waiting_takes_what_waits_in_order_up_to_the_limit(node, raw):
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    subscription = node.create_subscription(String, 'take_waiting', lambda _: None, qos, raw=raw)
    publisher = node.create_publisher(String, 'take_waiting', qos)
    deadline = time.monotonic() + 10.0
    while publisher.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    for text in 'abcd':
        publisher.publish(String(data=text))
    taken = []
    while len(taken) < 3 and time.monotonic() < deadline:
        taken += rclpy_private.take_waiting(subscription, 3 - len(taken))
        time.sleep(0.01)
    rest = []
    while not rest and time.monotonic() < deadline:
        rest = list(rclpy_private.take_waiting(subscription, 10))
    texts = [deserialize_message(data, String).data if raw else data.data
             for data, _ in taken + rest]
    assert texts == ['a', 'b', 'c', 'd']
    info = taken[0][1]
    assert {'source_timestamp', 'publication_sequence_number'} <= set(info)
    assert [info['publication_sequence_number'] for _, info in taken + rest] == [1, 2, 3, 4]
    assert list(rclpy_private.take_waiting(subscription, 10)) == []
    if raw:
        assert serialize_message(String(data='a')) == taken[0][0]


def test_message_lost_event_counts_from_zero_and_is_destroyed_first(node):
    subscription = node.create_subscription(String, 'message_lost', lambda _: None, 1)
    event = rclpy_private.message_lost_event(subscription)
    assert event is not None, 'Fast DDS reports message-lost events'
    assert rclpy_private.message_lost_count(event) == 0
    assert rclpy_private.message_lost_count(event) == 0
    event.destroy_when_not_in_use()
    node.destroy_subscription(subscription)
