"""
QoS profiles as rosbag2 stores them, and the profiles the node, record and play use.

The node's adaptation of its input subscriptions to the publishers (``qos.reliability:
auto``) is the node's own: :mod:`rotation_node.node.qos_adaptation`.

rosbag2 (metadata version 9, Jazzy) stores the QoS profiles offered by a
topic's publishers in the MCAP channel metadata ``offered_qos_profiles`` as a
YAML list; each entry holds history, depth, reliability, durability, deadline,
lifespan, liveliness, liveliness lease duration and
avoid_ros_namespace_conventions, policies by name (``keep_last``) and durations
as ``{sec, nsec}``. Bags written before version 9 hold the policies as
integers; both are read.
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

    The policies of :func:`rotation_node.wire.qos_yaml.output_policies`, which
    ``rotation_bag convert`` stores as the offered QoS of the topics it adds.

    Parameters
    ----------
    params : rotation_node.wire.qos_yaml.QosParameters
        ``qos.reliability`` and ``qos.depth`` (keep last).
    transient_local : bool, optional
        An input topic of latched data (``/tf_static``): reliable, keep all and
        transient local, whatever the parameters, so that every message its
        publishers keep for late subscribers arrives (only a reliable reader
        gets them); volatile with the parameters' reliability and depth otherwise.

    Returns
    -------
    rclpy.qos.QoSProfile

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
    """
    Serialise QoS profiles to rosbag2's ``offered_qos_profiles`` YAML.

    Parameters
    ----------
    profiles : iterable of rclpy.qos.QoSProfile
        E.g. the ``qos_profile`` of each ``Node.get_publishers_info_by_topic`` entry.

    Returns
    -------
    str
        A YAML list, ``'[]'`` for no profiles.

    """
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
    Parse rosbag2's ``offered_qos_profiles`` YAML into QoS profiles.

    Parameters
    ----------
    text : str
        The channel metadata value; ``''`` (no metadata) gives an empty list.
    topic : str, optional
        Named in the error message.

    Returns
    -------
    list of rclpy.qos.QoSProfile

    Raises
    ------
    BagError
        If the text is not a list of complete QoS entries.

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
    Return the reliability and durability that receive every publisher's messages.

    As rosbag2's ``adapt_request_to_offers``: reliable only if every publisher
    offers reliable, transient local only if every publisher offers it; best
    effort and volatile (which every publisher matches) when there is none.

    Parameters
    ----------
    offered : list of rclpy.qos.QoSProfile
        The publishers' offered profiles.

    Returns
    -------
    (rclpy.qos.ReliabilityPolicy, rclpy.qos.DurabilityPolicy)

    """
    def every(policy_name, value):
        return bool(offered) and all(getattr(p, policy_name) == value for p in offered)

    return (ReliabilityPolicy.RELIABLE if every('reliability', ReliabilityPolicy.RELIABLE)
            else ReliabilityPolicy.BEST_EFFORT,
            DurabilityPolicy.TRANSIENT_LOCAL
            if every('durability', DurabilityPolicy.TRANSIENT_LOCAL)
            else DurabilityPolicy.VOLATILE)


def recording_qos(offered: Sequence[QoSProfile]) -> QoSProfile:
    """
    Return the subscription QoS that receives every publisher's messages.

    The policies of :func:`matching_policies`; the history keeps
    ``DEEP_QUEUE_DEPTH`` samples so that bursts are not overwritten before
    the recorder takes them.

    Parameters
    ----------
    offered : list of rclpy.qos.QoSProfile
        The publishers' offered profiles.

    Returns
    -------
    rclpy.qos.QoSProfile

    """
    reliability, durability = matching_policies(offered)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEEP_QUEUE_DEPTH,
                      reliability=reliability, durability=durability)


def playback_qos(offered: Sequence[QoSProfile], *, lossless: bool = False) -> QoSProfile:
    """
    Return the publisher QoS that replays a topic as it was recorded.

    As rosbag2 does: the recorded reliability and durability if every
    recorded publisher offered the same ones, else reliable and volatile; keep
    last 10. ``lossless`` (``--rate 0``) makes it reliable with a
    ``DEEP_QUEUE_DEPTH`` queue.

    Parameters
    ----------
    offered : list of rclpy.qos.QoSProfile
        The profiles recorded in the bag for the topic (may be empty).
    lossless : bool, optional
        Reliable with a deep queue, whatever was recorded (``--rate 0``).

    Returns
    -------
    rclpy.qos.QoSProfile

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
