"""
The private rclpy APIs the package uses, each where no public one does the job.

Everything else uses rclpy's public API (``Subscription`` with ``raw=True``,
``SubscriptionEventCallbacks``, ``get_publishers_info_by_topic``,
``wait_for_all_acked``, ``rclpy.utilities.remove_ros_args``). What is here can
change in any rclpy release; test/test_rclpy_private.py checks that each name
exists and behaves as used here, and fails when one changes.

Checked against rclpy 7.1.5 and 7.1.6 (ROS 2 Jazzy, the wheels of the venv:
:data:`CHECKED_RCLPY_VERSIONS`); the sources of ros2/rclpy's ``jazzy`` branch
(7.1.3) and of ``rolling`` (8.0.0) define the same names and signatures.

- :data:`RCLError`: what ``rclpy.init`` and ``remove_ros_args`` raise for a
  malformed ``--ros-args`` (``RCLInvalidROSArgsError`` derives from it), and
  rclpy calls on a context shut down under them. rclpy exports no public name
  for it (``rclpy.exceptions`` has none, in rolling neither).
- :data:`RMWError`: what ``rclpy.serialization.deserialize_message`` raises for
  bytes that are not a message of the type; no public name either.
- :func:`message_lost_event` / :func:`message_lost_count`: the message-lost
  status of a subscription, read when the node asks (once a second). The public
  way, ``SubscriptionEventCallbacks(message_lost=...)``, adds an event handler
  that the executor examines at every wake-up, i.e. every message at 1 kHz; and
  ``EventHandler.take_data`` only returns data once the executor saw it ready.
- :func:`take_waiting`: take what else waits in a subscription's queue, in the
  callback of one message. rclpy's executor costs more per wake-up than the
  node's conversion of a message (2000 queued Imu messages: 170-350 us CPU per
  message with one wake-up each, 6-12 us taken this way; 2-core machine, load
  14); rclpy has no public "take" (its executor and ``wait_for_message`` call
  the same handle method).
"""
from typing import Any, Iterator, Optional, Tuple, TYPE_CHECKING

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

if TYPE_CHECKING:   # imported where used: the bag tools need only the errors
    from rclpy.subscription import Subscription

#: The rclpy releases this module was checked against.
CHECKED_RCLPY_VERSIONS = ('7.1.5', '7.1.6')

#: rclpy's error of the rcl layer (malformed ROS arguments, a context shut down).
RCLError = _rclpy.RCLError
#: rclpy's error for serialized bytes that are not a message of the type.
RMWError = _rclpy.RMWError


def message_lost_event(subscription: 'Subscription') -> Optional[Any]:
    """
    Return a handle on the message-lost status of ``subscription``, or None.

    None where the middleware reports no message-lost events. The handle is
    not given to the executor: it is read with :func:`message_lost_count` and
    must be destroyed (``destroy_when_not_in_use()``) before the subscription.
    """
    from rclpy.event_handler import QoSSubscriptionEventType, UnsupportedEventTypeError
    try:
        with subscription.handle:
            return _rclpy.EventHandle(
                subscription.handle, QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST)
    except UnsupportedEventTypeError:
        return None


def message_lost_count(event: Any) -> int:
    """Return how many messages the middleware reported lost since the last call."""
    with event:
        return event.take_event().total_count_change


def take_waiting(subscription: 'Subscription', limit: int) -> Iterator[Tuple[Any, Any]]:
    """
    Yield ``(message, message info)`` of what waits on ``subscription``, ``limit`` at most.

    The message as the subscription's callback gets it (bytes with ``raw=True``);
    the info as rclpy's executor passes it (a dict: ``source_timestamp``,
    ``publication_sequence_number``...). Stops when nothing more waits.
    """
    handle = subscription.handle
    take = handle.take_message
    message_type, raw = subscription.msg_type, subscription.raw
    for _ in range(limit):
        with handle:
            taken = take(message_type, raw)
        if taken is None:
            return
        yield taken
