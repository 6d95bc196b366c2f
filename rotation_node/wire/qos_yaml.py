"""
rosbag2's ``offered_qos_profiles`` YAML written without rclpy, and the node's output QoS by name.

rosbag2 (metadata version 9, Jazzy) stores a topic's offered profiles as a YAML list of
entries of one shape (:data:`ENTRY_KEYS`; policies by name, durations as ``{sec, nsec}``).
:func:`profiles_yaml` writes it as ``yaml.safe_dump`` does, without PyYAML's slow emitter and
without importing rclpy. rclpy profiles and reading: :mod:`rotation_node.wire.qos`.
"""
from __future__ import annotations

import re
from typing import Any, Dict, Iterable, List, Mapping, Protocol


class QosParameters(Protocol):
    """The node's ``qos.*`` parameters, read-only as a ``NodeParameters`` has them."""

    @property
    def qos_reliability(self) -> str:
        ...

    @property
    def qos_depth(self) -> int:
        ...


#: The keys of an entry, in rosbag2's order.
ENTRY_KEYS = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
              'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions')
_DURATION_KEYS = ('sec', 'nsec')
# A policy name that YAML writes plain (not a word YAML 1.1 reads as a bool or null).
_PLAIN_NAME = re.compile(r'[a-z][a-z_]*')
_YAML_WORDS = frozenset(('y', 'n', 'yes', 'no', 'on', 'off', 'true', 'false', 'null'))
# Reliabilities the node's outputs offer by that name (``auto`` offers reliable).
_OUTPUT_RELIABILITIES = ('reliable', 'best_effort')
_ZERO_DURATION = {'sec': 0, 'nsec': 0}


def output_policies(params: QosParameters) -> Dict[str, Any]:
    """
    Return the output publishers' history, depth, reliability and durability, by name.

    Keep last ``qos.depth``, volatile, ``qos.reliability`` (``auto``: reliable, which every
    subscriber matches); the other policies are rclpy's defaults.
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
    Return ``yaml.safe_dump(entries, sort_keys=False, default_flow_style=False)``, unterminated.

    ``'[]'`` for none; PyYAML writes an entry of another shape or with values it would quote.
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
