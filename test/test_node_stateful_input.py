"""
The node with an input type of several topics and a stateful stream (as /tf and /tf_static).

In-process: a registry entry with two topics, ``input`` and a transient-local
``latched``, whose stream turns every message of either topic into a sample.
The node must subscribe to each topic of the entry with its own QoS, and when a
parameter change gives it a new pipeline (an empty stream), the latched topic's
publisher must deliver what it keeps again, while the other topic's messages are
converted once each.
"""
import dataclasses
import sys
import time
import types

from geometry_msgs.msg import QuaternionStamped
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile

from rotation_node import registry
from rotation_node.registry import InputTopic, Sample

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

LATCHED = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _stream(params, report):
    """Every message of either topic is one sample, its quaternion unchanged."""
    def samples(topic, msg):
        q = msg.quaternion
        return (Sample(msg.header, (q.x, q.y, q.z, q.w)),)
    return samples


@pytest.fixture
def stateful_quaternion(monkeypatch):
    module = types.ModuleType('latched_stream')   # what InputType.stream names
    module.sample_stream, module.DROP_REASONS = _stream, ()
    monkeypatch.setitem(sys.modules, module.__name__, module)
    entry = dataclasses.replace(
        registry.INPUTS['quaternion'], stream=module.__name__,
        topics=(registry.INPUT_TOPIC, InputTopic('latched', transient_local=True)))
    monkeypatch.setitem(registry.INPUTS, 'quaternion', entry)


class Side:
    """An rclpy node in its own context, spun by its own executor."""

    def __init__(self, make_node):
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = make_node(self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def spin_until(sides, condition, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not condition():
        for side in sides:
            side.executor.spin_once(timeout_sec=0.01)
    return condition()


def message(stamp_sec):
    msg = QuaternionStamped()
    msg.header.stamp.sec = stamp_sec
    msg.quaternion.w = 1.0
    return msg


def test_each_topic_with_its_qos_and_latched_data_again_for_a_new_stream(stateful_quaternion):
    from rotation_node.node.conversion_node import RotationNode
    node = Side(lambda context: RotationNode(
        context=context, parameter_overrides=[
            Parameter('input_type', value='quaternion'),
            Parameter('outputs', value=['quaternion'])]))
    test = Side(lambda context: rclpy.create_node('stateful_test', context=context))
    sides = (node, test)
    try:
        received = []
        test.node.create_subscription(
            QuaternionStamped, 'quaternion', lambda msg: received.append(msg.header.stamp.sec),
            100)
        latched = test.node.create_publisher(QuaternionStamped, 'latched', LATCHED)
        plain = test.node.create_publisher(QuaternionStamped, 'input', 100)
        durability = {state.name: state.qos.durability for state in node.node._inputs}
        assert durability == {'input': DurabilityPolicy.VOLATILE,
                              'latched': DurabilityPolicy.TRANSIENT_LOCAL}
        assert spin_until(sides, lambda: plain.get_subscription_count() == 1
                          and latched.get_subscription_count() == 1
                          and test.node.count_publishers('quaternion') == 1, 30.0)
        spin_until(sides, lambda: False, 0.5)   # both readers have matched the writers
        latched.publish(message(1))
        plain.publish(message(2))
        assert spin_until(sides, lambda: sorted(received) == [1, 2], 10.0), received

        # A new pipeline: the latched message again (from the publisher's history), once.
        node.node.set_parameters([Parameter('euler.sequence', value='ZYX')])
        assert spin_until(sides, lambda: len(received) == 3, 10.0), received
        plain.publish(message(3))
        assert spin_until(sides, lambda: len(received) == 4, 10.0), received
        spin_until(sides, lambda: False, 1.0)   # nothing else arrives
        assert sorted(received) == [1, 1, 2, 3]
        assert all(state.retiring is None for state in node.node._inputs)
    finally:
        test.close()
        node.close()
