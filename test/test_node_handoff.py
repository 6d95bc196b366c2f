"""
Tests of rotation_node.node.handoff: subscriptions and publishers replaced without loss.

In-process, one rclpy node in its own context; test_node_qos.py checks the same through
the running node (a qos.depth change during a 1 kHz stream).
"""
import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rotation_node.node.handoff import HANDOFF_MAX_S, InputTopic, OutputPublishers
from rotation_node.registry import InputTopic as Topic
from std_msgs.msg import String

TIMEOUT_S = 20.0


@pytest.fixture
def node():
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('handoff_test', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    node.spin_until = lambda done: _spin_until(executor, done)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _spin_until(executor, done):
    deadline = time.monotonic() + TIMEOUT_S
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    return done()


def reliable(depth):
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)


def test_a_replaced_subscription_delivers_every_message_once(node):
    accepted = []

    def accept(state, data, info):
        if state.reception.accept(info):
            accepted.append(int(data.data))

    def drain(state):
        for data, info in state.waiting(100):
            accept(state, data, info)

    topic = InputTopic(node, Topic('handoff'), 1000, accept, drain, lambda *_: None)
    assert topic.subscribe(String, reliable(500), raw=False, memory=1000) is False
    publisher = node.create_publisher(String, 'handoff', reliable(500))
    assert node.spin_until(lambda: publisher.get_subscription_count() == 1)
    for k in range(100):
        publisher.publish(String(data=str(k)))
    assert node.spin_until(lambda: len(accepted) >= 20)
    assert topic.subscribe(String, reliable(400), raw=False, memory=1000) is True
    first = topic.subscription
    for k in range(100, 200):
        publisher.publish(String(data=str(k)))
    assert node.spin_until(lambda: not topic.check_handoff(time.monotonic())
                           and len(accepted) >= 200)
    assert accepted == list(range(200))
    assert topic.retiring is None and topic.subscription is first
    assert list(topic.message_lost) == [first]   # the old one and its event destroyed
    assert topic.reception.lost == 0 and topic.lost == 0
    topic.unsubscribe()
    assert not topic.message_lost and node.count_subscribers('/handoff') == 0


def test_a_handoff_ends_after_the_longest_wait_even_if_the_new_one_is_silent(node):
    topic = InputTopic(node, Topic('silent'), 100, lambda *_: None, lambda _: None,
                       lambda *_: None)
    topic.subscribe(String, reliable(10), raw=True, memory=100)
    assert topic.subscribe(String, reliable(5), raw=True, memory=100) is True
    started = topic.handoff_started
    assert topic.check_handoff(started + HANDOFF_MAX_S / 2) is True
    assert topic.check_handoff(started + HANDOFF_MAX_S + 0.1) is False
    assert topic.retiring is None and node.count_subscribers('/silent') == 1


def test_an_output_publisher_is_replaced_and_the_old_one_retired(node):
    outputs = OutputPublishers(node)
    assert outputs.configure(['euler'], reliable(10)) is False
    old_publish = outputs.publish['euler']
    assert outputs.configure(['euler'], reliable(20)) is True
    assert outputs.publish['euler'] == old_publish   # until the new one takes over
    assert node.count_publishers('/euler') == 2
    now = time.monotonic()
    assert outputs.check_handoffs(now) is True      # matched (no subscriber): settling
    assert outputs.check_handoffs(now + 0.6) is False   # took over; the old one acknowledged
    assert outputs.publish['euler'] != old_publish
    assert node.count_publishers('/euler') == 1
    assert outputs.configure([], reliable(20)) is True
    assert 'euler' not in outputs.publish
    assert outputs.check_handoffs(time.monotonic()) is False
    assert node.count_publishers('/euler') == 0
