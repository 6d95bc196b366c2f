"""
The QoS of the node's input subscriptions: fixed, or adapted to the publishers.

With ``qos.reliability: auto`` an input topic is subscribed with the
reliability and durability that every publisher on it matches (as ``ros2 bag
record`` adapts to what is offered), from the profiles the ROS graph shows
(``Node.get_publishers_info_by_topic``) and from incompatible-QoS events (a
publisher the graph does not show yet). Pure functions of the profiles: the
node subscribes again when the result changes (:mod:`.handoff`).
"""
from __future__ import annotations

from typing import Optional, Sequence, TYPE_CHECKING

from rclpy.qos import DurabilityPolicy, QoSPolicyKind, QoSProfile, ReliabilityPolicy
from rotation_node.wire.qos import matching_policies, qos_profile

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

#: ``qos.reliability`` value that adapts the input subscriptions to the publishers.
AUTO = 'auto'


def input_qos(params: NodeParameters, offered: Sequence[QoSProfile],
              current: Optional[QoSProfile] = None, *, transient_local: bool = False,
              incompatible_policy: Optional[QoSPolicyKind] = None) -> QoSProfile:
    """
    Return the QoS of one input subscription of the node.

    With ``qos.reliability: auto`` the reliability and durability are those
    every publisher on the topic is compatible with (:func:`matching_policies`,
    as ``ros2 bag record`` adapts to what is offered); while no publisher is
    known, those of the ``current`` subscription, or of :func:`qos_profile`
    (reliable) for the first one: a reliable publisher then matches at once,
    and a best-effort one is reported by an incompatible-QoS event, whose
    ``incompatible_policy`` lowers that policy even before the graph shows the
    publisher. Otherwise :func:`qos_profile`. The history is that of
    :func:`qos_profile` either way.

    Parameters
    ----------
    params : rotation_node.parameters.NodeParameters
        The node's parameters (``qos.reliability``, ``qos.depth``).
    offered : list of rclpy.qos.QoSProfile
        The profiles the topic's publishers offer (may be empty).
    current : rclpy.qos.QoSProfile, optional
        The QoS of the topic's subscription, if it has one.
    transient_local : bool, optional
        The topic holds latched data: keep all, and reliable and transient
        local unless adapted to the publishers.
    incompatible_policy : rclpy.qos.QoSPolicyKind, optional
        The policy of an incompatible-QoS event of the current subscription.

    Returns
    -------
    rclpy.qos.QoSProfile

    """
    profile = qos_profile(params, transient_local=transient_local)
    if params.qos_reliability != AUTO:
        return profile
    if offered:
        profile.reliability, profile.durability = matching_policies(offered)
    elif current is not None:
        profile.reliability, profile.durability = current.reliability, current.durability
    if current is not None and incompatible_policy == QoSPolicyKind.RELIABILITY:
        profile.reliability = ReliabilityPolicy.BEST_EFFORT
    elif current is not None and incompatible_policy == QoSPolicyKind.DURABILITY:
        profile.durability = DurabilityPolicy.VOLATILE
    return profile


def policies_text(profiles: Sequence[QoSProfile]) -> str:
    """Return each distinct profile's ``'reliable, volatile'``, joined by ``/``; ``'nothing'``."""
    return ' / '.join(sorted({f'{p.reliability.short_key}, {p.durability.short_key}'
                              for p in profiles})) or 'nothing'
