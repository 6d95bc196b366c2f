"""
The node's status on ``/diagnostics``: its counters, and what went wrong in the last period.

OK (``converting``), or WARN with the messages lost, dropped and partly converted
since the last report; the values are listed in docs/node.md.
"""
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rotation_node.node.handoff import InputTopic
from rotation_node.node.qos_adaptation import policies_text
from rotation_node.parameters import NodeParameters
from rotation_node.pipeline import ConversionPipeline, SKIP_REASONS
from rotation_node.static_mounting import MOUNTING_UNKNOWN

DIAGNOSTICS_PERIOD_S = 1.0


def input_topic_names(inputs: Sequence[InputTopic]) -> str:
    """Return the subscribed input topics, ``'/a, /b'``."""
    return ', '.join(state.subscribed()[0].topic_name for state in inputs)


class ConversionDiagnostics:
    """The node's ``/diagnostics`` publisher and the totals it reported last."""

    def __init__(self, node: Node):
        self._node = node
        self._reported = (0, 0, 0)   # dropped, skipped and lost totals at the last diagnostics
        # No QoS event handlers: each is one more entity rclpy's executor examines per wake-up.
        self._publisher = node.create_publisher(
            DiagnosticArray, '/diagnostics', 10,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

    def publish(self, inputs: Sequence[InputTopic], pipeline: ConversionPipeline,
                params: NodeParameters) -> None:
        """Publish the status of the node now (its losses counted up to now)."""
        for state in inputs:
            state.count_message_lost()
            state.reception.retain(state.matched_publishers())   # forget those that left
        stats = pipeline.stats
        gaps = sum(state.reception.lost for state in inputs)
        events = sum(state.lost_events for state in inputs)
        lost = sum(state.lost for state in inputs)
        totals = (sum(stats.dropped.values()), sum(stats.skipped.values()), lost)
        new_dropped, new_skipped, new_lost = (
            now - before for now, before in zip(totals, self._reported))
        self._reported = totals
        if new_dropped or new_skipped or new_lost:
            level = DiagnosticStatus.WARN
            message = (f'{new_lost} messages lost, {new_dropped} dropped, {new_skipped} partly '
                       f'converted in the last {DIAGNOSTICS_PERIOD_S:g} s')
        else:
            level, message = DiagnosticStatus.OK, 'converting'
        subscribed = [state.subscribed() for state in inputs]
        values = {
            'input_topic': input_topic_names(inputs),
            'input_qos': '; '.join(f'{subscription.topic_name}: {policies_text([qos])}'
                                   for subscription, qos in subscribed),
            'received': stats.received,
            'published': stats.published,
            'lost': lost,
            'lost.sequence_gaps': gaps,
            'lost.message_lost_events': events,
            'duplicates': sum(state.reception.duplicates for state in inputs),
            'dropped': totals[0],
            **{f'dropped.{reason}': stats.dropped[reason]
               for reason in (*pipeline.drop_reasons, MOUNTING_UNKNOWN)},
            'skipped': totals[1],
            **{f'skipped.{reason}': stats.skipped[reason] for reason in SKIP_REASONS},
            'normalised': stats.normalised,
            'near_singular': stats.near_singular,
            **params.to_ros(),
        }
        array = DiagnosticArray()
        array.header.stamp = self._node.get_clock().now().to_msg()
        array.status = [DiagnosticStatus(
            level=level, name=f'{self._node.get_fully_qualified_name()}: orientation conversion',
            message=message, hardware_id='',
            values=[KeyValue(key=key, value=value_text(value)) for key, value in values.items()])]
        self._publisher.publish(array)


def value_text(value: Any) -> str:
    """Return a diagnostics value as text: lists joined by commas, booleans lower case."""
    if isinstance(value, list):
        return ','.join(map(value_text, value))
    if isinstance(value, bool):
        return str(value).lower()
    return str(value)
