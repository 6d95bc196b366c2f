"""Tests of rotation_node.node.diagnostics: the node's status on /diagnostics (in-process)."""
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rotation_node.node.diagnostics import value_text


@pytest.mark.parametrize('value, text', [
    (['euler', 'quaternion'], 'euler,quaternion'), (True, 'true'), (False, 'false'),
    (0.25, '0.25'), (7, '7'), ([[1, 2], 3], '1,2,3')])
def test_values_are_text_as_ros_shows_them(value, text):
    assert value_text(value) == text


def test_a_status_each_period_counts_what_changed_since_the_last():
    from rotation_node.node.conversion_node import RotationNode
    context = Context()
    rclpy.init(context=context)
    try:
        node = RotationNode(context=context)
        received = []
        node.create_subscription(DiagnosticArray, '/diagnostics', received.append, 10)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def next_status():
            count = len(received)
            node._diagnostics.publish(node._inputs, node._pipeline, node.params)
            deadline = time.monotonic() + 20.0
            while len(received) == count and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            status, = received[-1].status
            return status, {value.key: value.value for value in status.values}

        status, values = next_status()
        assert status.name == '/rotation_node: orientation conversion'
        assert (status.level, status.message) == (DiagnosticStatus.OK, 'converting')
        assert values['input_topic'] == '/input'
        assert values['input_qos'] == '/input: reliable, volatile'
        assert values['outputs'] == 'euler' and values['euler.degrees'] == 'false'
        node._pipeline.stats.dropped['conversion_error'] += 2
        node._inputs[0].reception.lost += 3
        status, values = next_status()
        assert status.level == DiagnosticStatus.WARN
        assert status.message == '3 messages lost, 2 dropped, 0 partly converted in the last 1 s'
        assert (values['lost'], values['lost.sequence_gaps'], values['dropped']) == ('3', '3', '2')
        assert values['dropped.conversion_error'] == '2'
        status, values = next_status()   # nothing new: OK again, the totals kept
        assert (status.level, values['lost'], values['dropped']) == (DiagnosticStatus.OK, '3', '2')
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
