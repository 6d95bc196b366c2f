"""
rosbag2's ``offered_qos_profiles`` YAML written without rclpy, and the node's output QoS by name.

rosbag2 (metadata version 9, Jazzy) stores the QoS profiles a topic's
publishers offer as a YAML list of entries of one fixed shape: history, depth,
reliability, durability, deadline, lifespan, liveliness, liveliness lease
duration, avoid_ros_namespace_conventions; policies by name (``keep_last``),
durations as ``{sec, nsec}``. :func:`profiles_yaml` writes that shape
directly, as PyYAML's ``safe_dump`` writes it, without PyYAML's emitter
(most of the time of writing a small bag) and without rclpy (whose import
loads the ROS client libraries): ``rotation_bag convert`` offers
:func:`output_qos_yaml` for the topics it adds. Profiles as rclpy objects, and reading the YAML:
:mod:`rotation_node.wire.qos`.
"""
from __future__ import annotations

import re
from typing import Any, Dict, Iterable, List, Mapping, Protocol


class QosParameters(Protocol):
    """The node's ``qos.*`` parameters (those of ``rotation_node.parameters.NodeParameters``)."""

    @property
    def qos_reliability(self) -> str:
        """Return the ``qos.reliability`` parameter."""

    @property
    def qos_depth(self) -> int:
        """Return the ``qos.depth`` parameter."""


#: The keys of an entry, in rosbag2's order.
ENTRY_KEYS = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
              'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions')
_DURATION_KEYS = ('sec', 'nsec')
#: A policy name that YAML writes plain (not a word YAML 1.1 reads as a bool or null).
_PLAIN_NAME = re.compile(r'[a-z][a-z_]*')
_YAML_WORDS = frozenset(('y', 'n', 'yes', 'no', 'on', 'off', 'true', 'false', 'null'))
#: Reliabilities the node's outputs offer by that name (``auto`` offers reliable).
_OUTPUT_RELIABILITIES = ('reliable', 'best_effort')
_ZERO_DURATION = {'sec': 0, 'nsec': 0}


def output_policies(params: QosParameters) -> Dict[str, Any]:
    """
    Return the output publishers' history, depth, reliability and durability, by name.

    Keep last ``qos.depth``, volatile, the ``qos.reliability`` (``auto``:
    reliable, which every subscriber matches). The other policies are rclpy's
    defaults. :func:`rotation_node.wire.qos.qos_profile` makes the rclpy
    profile of these.
    """
    reliability = params.qos_reliability
    return {'history': 'keep_last', 'depth': params.qos_depth,
            'reliability': reliability if reliability in _OUTPUT_RELIABILITIES else 'reliable',
            'durability': 'volatile'}


def output_qos_yaml(params: QosParameters) -> str:
    """Return the ``offered_qos_profiles`` of a topic the node (or ``convert``) publishes."""
    return profiles_yaml([{
        **output_policies(params), 'deadline': _ZERO_DURATION, 'lifespan': _ZERO_DURATION,
        'liveliness': 'system_default', 'liveliness_lease_duration': _ZERO_DURATION,
        'avoid_ros_namespace_conventions': False}])


def _scalar(value):
    """Return a value as YAML writes it plain, or None if it is not a name, an int or a bool."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str) and _PLAIN_NAME.fullmatch(value) and value not in _YAML_WORDS:
        return value
    return None


def _entry_lines(entry: Mapping[str, Any]) -> List[str]:
    """Return the lines of one entry, or [] if it is not of the fixed shape."""
    if tuple(entry) != ENTRY_KEYS:
        return []
    lines = []
    for key, value in entry.items():
        if isinstance(value, Mapping):
            if tuple(value) != _DURATION_KEYS:
                return []
            lines.append(f'  {key}:')
            for name, number in value.items():
                text = _scalar(number)
                if text is None or isinstance(number, (bool, str)):
                    return []
                lines.append(f'    {name}: {text}')
        else:
            text = _scalar(value)
            if text is None:
                return []
            lines.append(f'  {key}: {text}')
    lines[0] = '- ' + lines[0][2:]
    return lines


def profiles_yaml(entries: Iterable[Mapping[str, Any]]) -> str:
    """
    Return entries of the fixed shape as rosbag2's YAML list: ``yaml.safe_dump``'s text.

    ``yaml.safe_dump(entries, sort_keys=False, default_flow_style=False)``
    without its last newline, ``'[]'`` for none; written directly, or by
    PyYAML for an entry of another shape or with values it would quote.
    """
    entries = list(entries)
    lines: List[str] = []
    for entry in entries:
        entry_lines = _entry_lines(entry)
        if not entry_lines:
            import yaml
            return yaml.safe_dump(entries, sort_keys=False,
                                  default_flow_style=False).rstrip('\n')
        lines += entry_lines
    return '\n'.join(lines) if lines else '[]'
