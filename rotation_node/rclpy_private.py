"""
The private rclpy APIs the package uses, each where no public one does the job.

They can change in any rclpy release: test/test_rclpy_private.py checks each as
used here. Checked against :data:`CHECKED_RCLPY_VERSIONS` (Jazzy); rclpy's
``jazzy`` (7.1.3) and ``rolling`` (8.0.0) sources define the same names.

- :data:`RCLError`, :data:`RMWError`: what a malformed ``--ros-args`` or a context
  shut down under a call, and undeserialisable bytes raise; no public names.
- :func:`message_lost_event` / :func:`message_lost_count`: the message-lost status
  read once a second. ``SubscriptionEventCallbacks(message_lost=...)`` would add a
  handler the executor examines at every wake-up (every message at 1 kHz), and
  ``EventHandler.take_data`` returns data only once the executor has seen it ready.
- :func:`take_waiting`: take what else is queued, in one message's callback: an
  executor wake-up costs more than a conversion (170-350 us against 6-12 us CPU
  per queued Imu message, docs/node.md); rclpy has no public "take".
"""
from typing import Any, Iterator, Optional, Tuple, TYPE_CHECKING

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

if TYPE_CHECKING:   # imported where used: the bag tools need only the errors
    from rclpy.subscription import Subscription

CHECKED_RCLPY_VERSIONS = ('7.1.5', '7.1.6')
RCLError = _rclpy.RCLError
RMWError = _rclpy.RMWError


def message_lost_event(subscription: 'Subscription') -> Optional[Any]:
    """
    Return a handle on the message-lost status of ``subscription`` (None: the rmw has none).

    Not given to the executor; destroy it (``destroy_when_not_in_use()``) before the subscription.
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
    """Yield ``(message, info)`` of what waits on ``subscription``, as its callback gets them."""
    handle = subscription.handle
    take = handle.take_message
    message_type, raw = subscription.msg_type, subscription.raw
    for _ in range(limit):
        with handle:
            taken = take(message_type, raw)
        if taken is None:
            return
        yield taken
