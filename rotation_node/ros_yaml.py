"""
The one YAML loader of the package: parameters files and scene files.

Plain scalars are typed as rcl's ``rcl_yaml_param_parser`` types them, so that a
file means the same to the node, ``rotation_bag convert`` and ``rotation_scene``:
yes/no/on/off/y/n/true/false words are booleans; what the C library's ``strtol``
(base 0) reads entirely is an integer, what its ``strtod`` reads entirely
without ``ERANGE`` (or ``.inf``/``.nan``) a float; anything else a string
(``1_000``, ``1e999``). Quoted scalars are strings; empty, ``~`` and ``null``
are None. Duplicate keys are refused, and so are a file beyond
:data:`MAX_FILE_BYTES`, aliases expanding beyond :data:`MAX_NODES` nodes, and
nesting deeper than :data:`MAX_DEPTH`, before the document is built.
"""
import ctypes
import math
import re
from typing import Any, Type

import yaml

MAX_FILE_BYTES = 1 << 20   # parameters files and scenes are a few kB
MAX_NODES = 100_000        # YAML nodes of a document, each alias counted as what it expands to
MAX_DEPTH = 64             # nesting of collections

_TRUE = frozenset(('Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on', 'On', 'ON'))
_FALSE = frozenset(('N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE', 'off', 'Off', 'OFF'))
_NULL = frozenset(('', '~', 'null', 'Null', 'NULL'))
_SPECIAL_FLOATS = {
    **{f'{sign}.{word}': sign_value * math.inf
       for sign, sign_value in (('', 1), ('+', 1), ('-', -1)) for word in ('inf', 'Inf', 'INF')},
    **{f'.{word}': math.nan for word in ('nan', 'NaN', 'NAN')},
}
_LIBC = ctypes.CDLL(None, use_errno=True)   # the process's C library, which rcl calls
_strtol = _LIBC.strtol
_strtol.restype, _strtol.argtypes = ctypes.c_long, [
    ctypes.c_char_p, ctypes.POINTER(ctypes.c_char_p), ctypes.c_int]
_strtod = _LIBC.strtod
_strtod.restype, _strtod.argtypes = ctypes.c_double, [
    ctypes.c_char_p, ctypes.POINTER(ctypes.c_char_p)]


def _c_number(function, raw, *base):
    """Return what ``function`` (strtol, strtod) reads from all of ``raw``, or None."""
    end = ctypes.c_char_p()
    ctypes.set_errno(0)
    value = function(raw, ctypes.byref(end), *base)
    return value if raw and end.value == b'' and ctypes.get_errno() == 0 else None


def ros_scalar(text: str) -> Any:
    """Return the value (bool, int, float, str or None) of a plain YAML scalar, as rcl types it."""
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    if text in _NULL:
        return None
    if text in _SPECIAL_FLOATS:
        return _SPECIAL_FLOATS[text]
    raw = text.encode()
    if b'\0' in raw:
        return text
    integer = _c_number(_strtol, raw, 0)
    if integer is not None:
        return integer
    number = _c_number(_strtod, raw)
    return text if number is None else number


_ROS_SCALAR_TAG = 'tag:rotation_node,2024:ros-scalar'


class _RosLoader(yaml.SafeLoader):
    """SafeLoader with ROS scalar typing, keys as written, duplicate keys (and aliases) refused."""

    aliases = True   # False for a parameters file: rcl refuses aliases there

    def compose_node(self, parent, index):
        if not self.aliases and self.check_event(yaml.AliasEvent):
            raise yaml.composer.ComposerError(
                None, None, 'aliases (*name) are not allowed in a parameters file (ROS refuses '
                'them)', self.peek_event().start_mark)
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):
        if not isinstance(node, yaml.MappingNode):
            raise yaml.constructor.ConstructorError(
                None, None, f'expected a mapping, found {node.id}', node.start_mark)
        mapping = {}
        for key_node, value_node in node.value:
            if isinstance(key_node, yaml.ScalarNode) and key_node.tag == _ROS_SCALAR_TAG:
                key = self.construct_scalar(key_node)   # names stay text: 'on', '1'
            else:
                key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in mapping
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    'while constructing a mapping', node.start_mark,
                    'found an unhashable key', key_node.start_mark) from None
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    None, None, f'duplicate key {key!r}', key_node.start_mark)
            mapping[key] = self.construct_object(value_node, deep=deep)
        return mapping


# Every plain scalar resolves to the ROS tag (the resolvers for any first character and
# for the empty scalar, in this class's table only: yaml.SafeLoader is unchanged).
_RosLoader.yaml_implicit_resolvers = {
    key: [(_ROS_SCALAR_TAG, re.compile(r'.*', re.DOTALL))] for key in (None, '')}
_RosLoader.add_constructor(
    _ROS_SCALAR_TAG,
    lambda loader, node: ros_scalar(loader.construct_scalar(node)))  # type: ignore[arg-type]


def _expanded_size(node, label, error, depth=1, sizes=None):
    """Return the node count of ``node`` with its aliases expanded; refuse too many or too deep."""
    sizes = {} if sizes is None else sizes   # id(node) -> its count, for nodes counted
    if id(node) not in sizes:
        if depth > MAX_DEPTH:
            raise error(f'{label}: nested deeper than {MAX_DEPTH} levels; refused')
        children = () if isinstance(node, yaml.ScalarNode) else (
            [item for pair in node.value for item in pair]
            if isinstance(node, yaml.MappingNode) else node.value)
        size = 1 + sum(_expanded_size(child, label, error, depth + 1, sizes) for child in children)
        if size > MAX_NODES:
            raise error(f'{label}: its aliases expand it beyond {MAX_NODES} YAML nodes; refused')
        sizes[id(node)] = size
    return sizes[id(node)]


def load_ros_yaml(path: Any, label: str, error: Type[Exception], *,
                  aliases: bool = True) -> Any:
    """
    Return the one YAML document of a file (None if empty), read with the rules of this module.

    Any problem raises ``error`` with one line starting with ``label`` (YAML errors
    with line and column). ``aliases=False`` refuses aliases (a parameters file).
    """
    try:
        with open(path, 'rb') as stream:
            data = stream.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise error(f'{label}: cannot read it ({exc.strerror})') from None
    if len(data) > MAX_FILE_BYTES:
        raise error(f'{label}: larger than {MAX_FILE_BYTES} bytes; refused')
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise error(f'{label}: not UTF-8 text (byte {exc.start})') from None
    loader = _RosLoader(text)
    loader.aliases = aliases
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _expanded_size(node, label, error)
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1}, column {mark.column + 1})' if mark else ''
        problem = getattr(exc, 'problem', None) or str(exc).replace('\n', ' ')
        raise error(f'{label}: invalid YAML{where}: {problem}') from None
    finally:
        loader.dispose()
