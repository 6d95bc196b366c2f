"""
QoS profiles as rclpy objects: rosbag2's ``offered_qos_profiles``; the node's, record's, play's.

The YAML's shape is :mod:`rotation_node.wire.qos_yaml`'s; bags before metadata version 9 hold
the policies as integers, also read. The node's input adaptation is
:mod:`rotation_node.node.qos_adaptation`.
"""
from __future__ import annotations

from typing import Iterable, List, Sequence, Tuple

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy)
from rotation_node.errors import BagError
from rotation_node.wire.qos_yaml import output_policies, profiles_yaml, QosParameters
from rotation_node.wire.stamps import split_ns
import yaml

_POLICIES = (
    ('history', HistoryPolicy),
    ('reliability', ReliabilityPolicy),
    ('durability', DurabilityPolicy),
    ('liveliness', LivelinessPolicy),
)
_DURATIONS = ('deadline', 'lifespan', 'liveliness_lease_duration')

#: Depth of the reliable queue ``play`` offers at ``--rate 0``, and that
#: ``record`` requests: deep enough that a burst never overwrites unread samples.
DEEP_QUEUE_DEPTH = 10_000


def _duration_yaml(duration):
    seconds, nanoseconds = split_ns(duration.nanoseconds)
    return {'sec': seconds, 'nsec': nanoseconds}


def qos_profile(params: QosParameters, *, transient_local: bool = False) -> QoSProfile:
    """
    Return the QoS of the node's output publishers (and of its inputs unless adapted).

    That of :func:`~rotation_node.wire.qos_yaml.output_policies`; ``transient_local`` (an
    input of latched data, ``/tf_static``) is reliable, keep all and transient local whatever
    the parameters, so that every message publishers keep for late subscribers arrives.
    """
    if transient_local:
        return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
    policies = output_policies(params)
    return QoSProfile(
        history=HistoryPolicy[policies['history'].upper()], depth=policies['depth'],
        reliability=ReliabilityPolicy[policies['reliability'].upper()],
        durability=DurabilityPolicy[policies['durability'].upper()])


def qos_profiles_yaml(profiles: Iterable[QoSProfile]) -> str:
    """Return rosbag2's ``offered_qos_profiles`` YAML of QoS profiles (``'[]'`` for none)."""
    entries = [{
        'history': profile.history.short_key,
        'depth': profile.depth,
        'reliability': profile.reliability.short_key,
        'durability': profile.durability.short_key,
        'deadline': _duration_yaml(profile.deadline),
        'lifespan': _duration_yaml(profile.lifespan),
        'liveliness': profile.liveliness.short_key,
        'liveliness_lease_duration': _duration_yaml(profile.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(profile.avoid_ros_namespace_conventions),
    } for profile in profiles]
    return profiles_yaml(entries)


def _policy(entry, key, policy_type):
    value = entry[key]
    if isinstance(value, int):
        return policy_type(value)
    return policy_type[str(value).upper()]


def qos_profiles_from_yaml(text: str, *, topic: str = '') -> List[QoSProfile]:
    """
    Return the profiles of rosbag2's ``offered_qos_profiles`` YAML (none for ``''``).

    BagError naming ``topic`` if the text is not a list of complete entries.
    """
    if not text.strip():
        return []
    try:
        entries = yaml.safe_load(text)
        if not isinstance(entries, list):
            raise TypeError(f'expected a YAML list, got {type(entries).__name__}')
        profiles = []
        for entry in entries:
            profile = QoSProfile(
                depth=int(entry['depth']),
                avoid_ros_namespace_conventions=bool(entry['avoid_ros_namespace_conventions']),
                **{key: _policy(entry, key, policy) for key, policy in _POLICIES},
                **{key: Duration(seconds=int(entry[key]['sec']),
                                 nanoseconds=int(entry[key]['nsec'])) for key in _DURATIONS})
            profiles.append(profile)
    except (yaml.YAMLError, TypeError, KeyError, ValueError) as error:
        raise BagError(f'invalid offered_qos_profiles of topic {topic!r}: {error!r}') from None
    return profiles


def matching_policies(offered: Sequence[QoSProfile]) -> Tuple[ReliabilityPolicy, DurabilityPolicy]:
    """
    Return the reliability and durability that receive every offering publisher's messages.

    As rosbag2's ``adapt_request_to_offers``: reliable only if every publisher offers reliable,
    transient local only if every one offers transient local; best effort and volatile (which
    every publisher matches) when there is none.
    """
    def every(policy_name, value):
        return bool(offered) and all(getattr(p, policy_name) == value for p in offered)

    return (ReliabilityPolicy.RELIABLE if every('reliability', ReliabilityPolicy.RELIABLE)
            else ReliabilityPolicy.BEST_EFFORT,
            DurabilityPolicy.TRANSIENT_LOCAL
            if every('durability', DurabilityPolicy.TRANSIENT_LOCAL)
            else DurabilityPolicy.VOLATILE)


def recording_qos(offered: Sequence[QoSProfile]) -> QoSProfile:
    """Return :func:`matching_policies` keeping the last ``DEEP_QUEUE_DEPTH``: record's QoS."""
    reliability, durability = matching_policies(offered)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEEP_QUEUE_DEPTH,
                      reliability=reliability, durability=durability)


def playback_qos(offered: Sequence[QoSProfile], *, lossless: bool = False) -> QoSProfile:
    """
    Return the publisher QoS that replays a topic as it was recorded, as rosbag2 does.

    The recorded reliability and durability if every recorded publisher offered the same, else
    reliable and volatile; keep last 10. ``lossless`` (``--rate 0``): reliable, keep last
    ``DEEP_QUEUE_DEPTH``.
    """
    same = offered and all(
        (p.reliability, p.durability) == (offered[0].reliability, offered[0].durability)
        for p in offered)
    reliability, durability = (
        (offered[0].reliability, offered[0].durability) if same
        else (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE))
    if lossless:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEEP_QUEUE_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE, durability=durability)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                      reliability=reliability, durability=durability)
