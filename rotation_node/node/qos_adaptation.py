"""The QoS of the node's input subscriptions: fixed, or adapted to the publishers."""
from __future__ import annotations

from typing import Optional, Sequence, TYPE_CHECKING

from rclpy.qos import DurabilityPolicy, QoSPolicyKind, QoSProfile, ReliabilityPolicy
from rotation_node.wire.qos import matching_policies, qos_profile

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

AUTO = 'auto'


def input_qos(params: NodeParameters, offered: Sequence[QoSProfile],
              current: Optional[QoSProfile] = None, *, transient_local: bool = False,
              incompatible_policy: Optional[QoSPolicyKind] = None) -> QoSProfile:
    """
    Return the QoS of one input subscription: :func:`qos_profile`, adapted with ``auto``.

    ``auto`` takes the reliability and durability every ``offered`` profile matches
    (as ``ros2 bag record``); with none offered, the ``current`` subscription's
    (or reliable, at first); an ``incompatible_policy`` event of the current
    subscription lowers that policy before the graph shows its publisher.
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
