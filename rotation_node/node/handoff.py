"""
The node's subscriptions and publishers, replaced (a new QoS) without losing a message.

:class:`InputTopic`: a new subscription replaces the old one once it has
delivered a message the old one delivered too (or the old one went quiet).
:class:`OutputPublishers`: a new publisher takes over once it has matched the
old one's subscribers; the old one lives until they acknowledged what it sent.
The node calls ``check_handoff(s)`` from a timer while a replacement is under way.
"""
from dataclasses import dataclass
import functools
import time
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Set, Tuple

from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from rotation_node import registry
from rotation_node.node.reception import Identity, message_identity, Reception
from rotation_node.rclpy_private import message_lost_count, message_lost_event, take_waiting

HANDOFF_QUIET_S = 0.25   # the old subscription's silence once the new one delivers
HANDOFF_MAX_S = 2.0      # the longest an old subscription or publisher lives on
# How long a new publisher must have matched the old one's subscribers (on its side)
# before it takes over, so that their readers match it too.
PUBLISHER_SETTLE_S = 0.5

MessageInfo = Dict[str, Any]


class InputTopic:
    """
    One topic of the input type: its subscription, QoS, and what it received.

    During a handoff ``retiring`` is the old subscription, still taken from, and
    ``pending`` holds the new one's messages. ``memory``: the messages the
    :class:`Reception` remembers. The node's callbacks: ``accept(self, message, info)``
    for each message taken (maybe seen before), ``drain(self)`` after one of the current
    subscription outside a handoff (to take what else waits), and
    ``on_incompatible_qos(self, event)`` for a publisher the subscription cannot match.
    """

    def __init__(self, node: Node, topic: registry.InputTopic, memory: int,
                 accept: Callable[['InputTopic', Any, MessageInfo], None],
                 drain: Callable[['InputTopic'], None],
                 on_incompatible_qos: Callable[['InputTopic', Any], None]):
        self.topic = topic
        self.name = topic.name
        self._node = node
        self._accept, self._drain = accept, drain
        self._on_incompatible_qos = on_incompatible_qos
        self.subscription: Optional[Subscription] = None   # set when the node subscribes
        self.qos: Optional[QoSProfile] = None
        self.generation = 0
        self.retiring: Optional[Subscription] = None
        self.retiring_heard = 0.0     # monotonic time of the old subscription's last message
        self.handoff_started = 0.0
        self.pending: List[Tuple[Any, MessageInfo]] = []
        self.pending_identities: Set[Identity] = set()
        self.reception = Reception(memory, on_new_publisher=self._publisher_started)
        self.lost_events = 0          # total_count_change of the rmw's message-lost events
        self.message_lost: Dict[Subscription, Any] = {}   # None: the rmw has no such event

    @property
    def lost(self) -> int:
        """Messages lost: the larger of the sequence gaps and the message-lost events."""
        return max(self.reception.lost, self.lost_events)

    def matched_publishers(self) -> int:
        """Return how many publishers the topic's subscriptions (current, retiring) match."""
        return max((subscription.get_publisher_count()
                    for subscription in (self.subscription, self.retiring)
                    if subscription is not None), default=0)

    def _publisher_started(self) -> None:
        # A publisher joined or restarted: whose message just came is matched (at least one),
        # and one that left is no longer: a later gap must not be credited to it.
        self.reception.retain(max(self.matched_publishers(), 1))

    def subscribed(self) -> Tuple[Subscription, QoSProfile]:
        """Return the subscription messages are taken from and its QoS (set on configuring)."""
        if self.subscription is None or self.qos is None:
            raise RuntimeError(f'input {self.name}: not subscribed')
        return self.subscription, self.qos

    def offered_qos(self) -> List[QoSProfile]:
        """Return the QoS profiles the publishers of the topic offer (from the ROS graph)."""
        name = (self.subscription.topic_name if self.subscription is not None
                else self._node.resolve_topic_name(self.name))
        return [info.qos_profile for info in self._node.get_publishers_info_by_topic(name)]

    def subscribe(self, message_type: Any, qos: QoSProfile, *, raw: bool, memory: int) -> bool:
        """Subscribe the topic with ``qos``; return whether a handoff (of the old one) started."""
        if self.retiring is not None:
            self.finish_handoff()
        self.generation += 1
        callbacks = SubscriptionEventCallbacks(
            incompatible_qos=functools.partial(self._on_incompatible_qos, self))
        subscription = self._node.create_subscription(
            message_type, self.name, functools.partial(self.on_message, self.generation), qos,
            event_callbacks=callbacks, raw=raw)
        # The message-lost status is read once a second, not waited on: an event handler
        # is one more entity the executor examines at every wake-up.
        self.message_lost[subscription] = message_lost_event(subscription)
        handoff = self.subscription is not None
        if handoff:
            self.retiring = self.subscription
            self.handoff_started = self.retiring_heard = time.monotonic()
        self.subscription, self.qos = subscription, qos
        self.reception.resize(memory)
        return handoff

    def on_message(self, generation: int, data: Any, info: MessageInfo) -> None:
        """Take one message of the topic from its subscription of ``generation``."""
        if self.retiring is not None:
            if generation != self.generation:   # the old subscription
                self.retiring_heard = time.monotonic()
                self._accept(self, data, info)
                if message_identity(info) in self.pending_identities:
                    self.finish_handoff()
                return
            if not self.reception.seen(info):
                self.pending.append((data, info))
                self.pending_identities.add(message_identity(info))
                return
            self.finish_handoff()   # the new subscription has caught up
        self._accept(self, data, info)
        if self.retiring is None:
            self._drain(self)

    def waiting(self, limit: int) -> Iterator[Tuple[Any, MessageInfo]]:
        """Take what else waits on the current subscription (``limit`` messages at most)."""
        return take_waiting(self.subscribed()[0], limit)

    def check_handoff(self, now: float) -> bool:
        """Finish the handoff if it is due; return whether one is still under way."""
        if self.retiring is not None and (
                (self.pending and now - self.retiring_heard > HANDOFF_QUIET_S)
                or now - self.handoff_started > HANDOFF_MAX_S):
            self.finish_handoff()
        return self.retiring is not None

    def finish_handoff(self) -> None:
        """Destroy the retiring subscription; accept what the new one delivered meanwhile."""
        if self.retiring is None:
            return
        self.destroy_subscription(self.retiring)
        self.retiring = None
        pending, self.pending = self.pending, []
        self.pending_identities.clear()
        for data, info in pending:
            self._accept(self, data, info)

    def count_message_lost(self) -> None:
        """Add the message-lost events of the subscriptions since the last call."""
        for subscription in (self.subscription, self.retiring):
            self._count_message_lost(subscription)

    def _count_message_lost(self, subscription: Optional[Subscription]) -> None:
        event = None if subscription is None else self.message_lost.get(subscription)
        if event is not None:
            self.lost_events += message_lost_count(event)

    def destroy_subscription(self, subscription: Subscription) -> None:
        """Destroy one of the topic's subscriptions, its message-lost event first."""
        self._count_message_lost(subscription)
        event = self.message_lost.pop(subscription)
        if event is not None:
            event.destroy_when_not_in_use()
        self._node.destroy_subscription(subscription)

    def unsubscribe(self) -> None:
        """Destroy the topic's subscriptions (the input type changed)."""
        self.finish_handoff()
        self.destroy_subscription(self.subscribed()[0])

    def destroy_events(self) -> None:
        """
        Destroy the message-lost event handles (before the node destroys the subscriptions).

        A handle left alive would be finalised at exit against a subscription already gone.
        """
        for event in self.message_lost.values():
            if event is not None:
                event.destroy_when_not_in_use()
        self.message_lost.clear()


@dataclass
class _PublisherReplacement:
    """An output's new publisher (a new QoS), until it takes over from the old one."""

    publisher: Publisher
    created_at: float   # monotonic
    matched_since: Optional[float] = None   # of the old one's subscribers


class OutputPublishers:
    """The node's output publishers (``publish``, ``encoders`` by name), replaced without loss."""

    def __init__(self, node: Node):
        self._node = node
        self._publishers: Dict[str, Publisher] = {}
        self.publish: Dict[str, Callable[[bytes], None]] = {}
        self.encoders: Dict[str, Callable[[Any, Sequence[float]], bytes]] = {}
        self._replacing: Dict[str, _PublisherReplacement] = {}   # by output name
        # publishers no longer published on, until acknowledged: (publisher, retired at)
        self._retiring: List[Tuple[Publisher, float]] = []

    def configure(self, outputs: Sequence[str], qos: QoSProfile) -> bool:
        """Publish ``outputs`` with ``qos`` from now on; return whether a handoff started."""
        for name in list(self._publishers):
            replacement = self._replacing.pop(name, None)
            if replacement is not None:   # superseded before it took over
                self._node.destroy_publisher(replacement.publisher)
            if name not in outputs:
                self._retire(self._publishers.pop(name))
                del self.publish[name]
            elif self._publishers[name].qos_profile != qos:
                self._replacing[name] = _PublisherReplacement(
                    self._create(name, qos), time.monotonic())
        for name in outputs:
            if name not in self._publishers:
                publisher = self._create(name, qos)
                self._publishers[name] = publisher
                self.publish[name] = publisher.publish
                self.encoders[name] = registry.OUTPUTS[name].message.encoder()
        return self.handing_off

    @property
    def handing_off(self) -> bool:
        """Whether a publisher is being replaced or waits for its acknowledgements."""
        return bool(self._replacing or self._retiring)

    def _create(self, name: str, qos: QoSProfile) -> Publisher:
        # Without QoS event handlers (as the diagnostics publisher): a subscriber
        # that cannot match reports it itself.
        return self._node.create_publisher(
            registry.OUTPUTS[name].message_class, name, qos,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

    def check_handoffs(self, now: float) -> bool:
        """Let matched new publishers take over, destroy acknowledged old ones; return if busy."""
        for name, replacement in list(self._replacing.items()):
            new, old = replacement.publisher, self._publishers[name]
            if new.get_subscription_count() < old.get_subscription_count():
                # (a subscriber the new QoS cannot match: HANDOFF_MAX_S)
                replacement.matched_since = None
            elif replacement.matched_since is None:
                # matched on the publisher's side; let readers match too
                replacement.matched_since = now
            settled = (replacement.matched_since is not None
                       and now - replacement.matched_since >= PUBLISHER_SETTLE_S)
            if settled or now - replacement.created_at > HANDOFF_MAX_S:
                del self._replacing[name]
                self._publishers[name], self.publish[name] = new, new.publish
                self._retire(old)
        for retiring in list(self._retiring):
            publisher, retired_at = retiring
            if (publisher.wait_for_all_acked(Duration())   # a check, without waiting
                    or now - retired_at > HANDOFF_MAX_S):
                self._retiring.remove(retiring)
                self._node.destroy_publisher(publisher)
        return self.handing_off

    def _retire(self, publisher: Publisher) -> None:
        """Stop publishing on ``publisher``; destroy it once what it sent is acknowledged."""
        self._retiring.append((publisher, time.monotonic()))
