"""
The QoS of the node's input subscriptions: fixed, or adapted to the publishers.

With ``qos.reliability: auto`` an input topic is subscribed with the
reliability and durability that every publisher on it matches (as ``ros2 bag
record`` adapts to what is offered), from the profiles the ROS graph shows
(``Node.get_publishers_info_by_topic``) and from incompatible-QoS events (a
publisher the graph does not show yet). Pure functions of the profiles: the
node subscribes again when the result changes (:mod:`.subscription_handoff`).
"""
from __future__ import annotations

from typing import Optional, Sequence, TYPE_CHECKING

from rclpy.qos import DurabilityPolicy, QoSPolicyKind, QoSProfile, ReliabilityPolicy
from rotation_node.wire.qos import matching_policies, qos_profile

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

#: ``qos.reliability`` value that adapts the input subscriptions to the publishers.
AUTO = 'auto'


def input_qos(params: NodeParameters, offered: Sequence[QoSProfile], *,
              transient_local: bool = False) -> QoSProfile:
    """
    Return the QoS of one input subscription of the node.

    With ``qos.reliability: auto`` the reliability and durability are those
    every publisher on the topic is compatible with (:func:`matching_policies`,
    as ``ros2 bag record`` adapts to what is offered); otherwise, or while
    there is no publisher, those of :func:`qos_profile` (reliable when auto):
    a reliable publisher then matches at once, and a best-effort one is
    reported by an incompatible-QoS event. The history is that of
    :func:`qos_profile` either way.

    Parameters
    ----------
    params : rotation_node.parameters.NodeParameters
        The node's parameters (``qos.reliability``, ``qos.depth``).
    offered : list of rclpy.qos.QoSProfile
        The profiles the topic's publishers offer (may be empty).
    transient_local : bool, optional
        The topic holds latched data: keep all, and reliable and transient
        local unless adapted to the publishers.

    Returns
    -------
    rclpy.qos.QoSProfile

    """
    profile = qos_profile(params, transient_local=transient_local)
    if params.qos_reliability == AUTO and offered:
        profile.reliability, profile.durability = matching_policies(offered)
    return profile


def adapted_input_qos(params: NodeParameters, offered: Sequence[QoSProfile],
                      current: Optional[QoSProfile], *, transient_local: bool = False,
                      incompatible_policy: Optional[QoSPolicyKind] = None) -> QoSProfile:
    """
    Return the QoS to subscribe an input topic with, given the ``offered`` profiles.

    :func:`input_qos`; with ``qos.reliability: auto`` and a subscription
    already there (its QoS ``current``), its reliability and durability are
    kept while no publisher is known, and ``incompatible_policy`` (a publisher
    the current subscription cannot match offers less of it) lowers that
    policy even before the graph shows the publisher.
    """
    qos = input_qos(params, offered, transient_local=transient_local)
    if params.qos_reliability == AUTO and current is not None:
        if not offered:
            qos.reliability, qos.durability = current.reliability, current.durability
        if incompatible_policy == QoSPolicyKind.RELIABILITY:
            qos.reliability = ReliabilityPolicy.BEST_EFFORT
        elif incompatible_policy == QoSPolicyKind.DURABILITY:
            qos.durability = DurabilityPolicy.VOLATILE
    return qos


def policies_text(profiles: Sequence[QoSProfile]) -> str:
    """Return each distinct profile's ``'reliable, volatile'``, joined by ``/``; ``'nothing'``."""
    return ' / '.join(sorted({f'{p.reliability.short_key}, {p.durability.short_key}'
                              for p in profiles})) or 'nothing'
