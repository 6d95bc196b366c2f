"""
Topic names of input bags that are not valid in ROS 2, and the one rule that maps them.

ROS 1 allowed topic names that ROS 2 rejects (``ORB-SLAM``, ``/imu-raw``,
``/2d_scan``), and other recorders write any string. A valid ROS 2 topic name
holds only ASCII letters, digits, ``_`` and ``/``, has no empty token (``//``,
a trailing ``/``) and no token that starts with a digit; it is fully qualified
(``/imu``) or relative (``groundtruth``, ``imu/data``: resolved in the
namespace of a node, as rclpy's ``validate_topic_name`` accepts it). A
relative name is kept as it is, unless it names the same topic as a fully
qualified one of the bag once resolved in the root namespace (``c`` beside
``/c``). ``~`` and substitutions (``{node}``), which only mean something to a
node, are not kept. ``rotation_bag`` maps every other topic of an input bag to
a valid name, and uses the mapped name everywhere: the topics ``convert``
writes (and the outputs derived from them, ``/imu_raw/euler``), the
publishers of ``play``, the names given to ``--topic``.

The rule (:func:`ros2_topic_name`):

1. every character other than an ASCII letter, digit, ``_`` or ``/`` becomes ``_``;
2. the name gets a leading ``/`` if it has none;
3. empty tokens are dropped (``//`` becomes ``/``, a trailing ``/`` goes);
4. a token that starts with a digit gets a ``_`` in front; an empty name becomes ``/_``.

If the mapped name is already taken (by a kept topic of the bag or an
earlier mapped one, in sorted order of the original names),
``_2``, ``_3``... is appended (:func:`topic_renames`).
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
    Map a topic name to a valid ROS 2 topic name (the module's rule).

    Parameters
    ----------
    name : str
        A topic name as an input bag stores it.

    Returns
    -------
    str
        ``name`` itself if it is valid (``'/imu'``, ``'groundtruth'``), else
        its mapped name, fully qualified: ``'ORB-SLAM'`` -> ``'/ORB_SLAM'``,
        ``'/imu-raw'`` -> ``'/imu_raw'``, ``'/2d/scan/'`` -> ``'/_2d/scan'``.

    """
    if is_valid_topic_name(name):
        return name
    tokens = [token for token in _INVALID_CHARACTER.sub('_', name).split('/') if token]
    tokens = ['_' + token if token[0].isdigit() else token for token in tokens]
    return '/' + '/'.join(tokens) if tokens else '/_'


def topic_renames(names: Iterable[str]) -> Dict[str, str]:
    """
    Return the new name of every invalid name among ``names``, distinct from all the others.

    Parameters
    ----------
    names : iterable of str
        The topics of a bag.

    Returns
    -------
    dict
        ``{original name: mapped name}`` for the names that are not valid ROS 2
        topic names, and for relative names that resolve to another topic of
        ``names`` (the names kept are not in the dict).

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
        base = ros2_topic_name(name) if not is_valid_topic_name(name) else _resolved(name)
        mapped, suffix = base, 1
        while mapped in taken:
            suffix += 1
            mapped = f'{base}_{suffix}'
        taken.add(mapped)
        renames[name] = mapped
    return renames
