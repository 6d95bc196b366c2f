"""
The one rule that maps input topic names not valid in ROS 2 to valid ones (docs/bags.md).

Valid names are kept, fully qualified or relative, unless a relative one resolves in the root
namespace to another topic of the bag (``c`` beside ``/c``); every other name is mapped
(:func:`ros2_topic_name`), ``_2``, ``_3``... appended where taken (:func:`topic_renames`).
"""
import re
from typing import Dict, Iterable

_INVALID_CHARACTER = re.compile(r'[^A-Za-z0-9_/]')
_VALID_NAME = re.compile(r'/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*')


def is_valid_topic_name(name: str) -> bool:
    """Whether ``name`` is a valid ROS 2 topic name, fully qualified or relative (no ``~``)."""
    return _VALID_NAME.fullmatch(name) is not None


def _resolved(name: str) -> str:
    """Return a valid name resolved in the root namespace: ``imu`` -> ``/imu``."""
    return name if name.startswith('/') else '/' + name


def ros2_topic_name(name: str) -> str:
    """
    Return ``name`` if it is a valid ROS 2 topic name, else its mapped name, fully qualified.

    Other characters than ASCII letters, digits, ``_`` and ``/`` become ``_``; empty tokens go; a
    token starting with a digit gets a ``_`` in front: ``'/2d/scan/'`` -> ``'/_2d/scan'``.
    """
    if is_valid_topic_name(name):
        return name
    tokens = [token for token in _INVALID_CHARACTER.sub('_', name).split('/') if token]
    tokens = ['_' + token if token[0].isdigit() else token for token in tokens]
    return '/' + '/'.join(tokens) if tokens else '/_'


def topic_renames(names: Iterable[str]) -> Dict[str, str]:
    """
    Return ``{original: mapped}`` for the topics of a bag that are not kept, names all distinct.

    Those are the invalid names and the relative names that resolve to another of ``names``.
    """
    names = sorted(set(names))
    qualified = {name for name in names if name.startswith('/') and is_valid_topic_name(name)}
    kept = qualified | {name for name in names if is_valid_topic_name(name)
                        and _resolved(name) not in qualified}
    taken = {_resolved(name) for name in kept}   # mapped names are fully qualified
    renames = {}
    for name in names:
        if name in kept:
            continue
        base = _resolved(ros2_topic_name(name))
        mapped, suffix = base, 1
        while mapped in taken:
            suffix += 1
            mapped = f'{base}_{suffix}'
        taken.add(mapped)
        renames[name] = mapped
    return renames
