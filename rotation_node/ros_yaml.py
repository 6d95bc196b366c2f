"""
The one YAML loader of the package: parameters files and scene files.

Plain (unquoted) scalars are typed as ROS 2 types them in parameters files
(``rcl_yaml_param_parser``), so that a file means the same to the node, to
``rotation_bag convert`` and to ``rotation_scene``:

- ``true``/``false``, ``yes``/``no``, ``on``/``off`` (lower, capitalised or
  upper case) and ``y``/``n``/``Y``/``N`` are booleans;
- an integer as C ``strtol`` reads it with base 0 (``42``, ``-7``, ``0x1F``,
  octal ``017``), within int64, is an integer;
- otherwise a number as C ``strtod`` reads it (``0.5``, ``.5e-3``, ``1e3``,
  ``1.``, ``inf``, ``nan``, hexadecimal ``0x1p-3``), or ``.inf``, ``-.inf``,
  ``.nan``, is a float; one beyond the float range, or one that rounds to a
  value below the normal range (``5e-324``, ``1e-400``), is not a number;
- anything else is a string (``1_000`` and ``1_0e3`` included, as in ROS);
  quoted scalars are always strings. An empty scalar, ``~`` and ``null`` are
  None.

A key given twice in one mapping is an error; parameters files may hold no
alias (rcl refuses them). Why parameters files are read here and not with
rclpy's ``parameter_dict_from_yaml_file``: the list of where rcl and rclpy
differ, in :mod:`rotation_node.parameters`. Input is bounded: a file larger
than :data:`MAX_FILE_BYTES`, a document whose aliases expand it beyond
:data:`MAX_NODES` nodes (a "billion laughs" alias bomb), or one nested deeper
than :data:`MAX_DEPTH` is refused before it is built.
"""
import math
import re
import sys
from typing import Any, Type

import yaml

MAX_FILE_BYTES = 1 << 20
"""Largest file read (1 MiB); parameters files and scenes are a few kB."""

MAX_NODES = 100_000
"""Largest number of YAML nodes of a document, counting each alias as what it expands to."""

MAX_DEPTH = 64
"""Deepest nesting of collections in a document."""

_TRUE = frozenset(('Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on', 'On', 'ON'))
_FALSE = frozenset(('N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE', 'off', 'Off', 'OFF'))
_NULL = frozenset(('', '~', 'null', 'Null', 'NULL'))
_SPECIAL_FLOATS = {
    **{f'{sign}.{word}': sign_value * math.inf
       for sign, sign_value in (('', 1), ('+', 1), ('-', -1)) for word in ('inf', 'Inf', 'INF')},
    **{f'.{word}': math.nan for word in ('nan', 'NaN', 'NAN')},
}
_INT64 = (-2**63, 2**63 - 1)
# What strtol(value, &end, 0) consumes entirely (strtol skips leading white space).
_STRTOL = re.compile(r'\s*([+-]?)(?:0[xX]([0-9a-fA-F]+)|(0[0-7]*)|([1-9][0-9]*))')
# What strtod consumes entirely: decimal, inf/infinity, nan, nan(chars), hexadecimal.
_STRTOD_DECIMAL = re.compile(r'\s*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?')
_STRTOD_WORD = re.compile(r'\s*([+-]?)(?:(inf(?:inity)?)|(nan(?:\([0-9A-Za-z_]*\))?))',
                          re.IGNORECASE)
_STRTOD_HEX = re.compile(
    r'\s*[+-]?0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?[0-9]+)?')


def ros_scalar(text: str) -> Any:
    """
    Return the value of a plain YAML scalar as ROS 2 parameters files type it.

    Parameters
    ----------
    text : str
        The scalar as written (unquoted).

    Returns
    -------
    bool, int, float, str or None

    """
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    if text in _NULL:
        return None
    match = _STRTOL.fullmatch(text)
    if match is not None:
        sign, hexadecimal, octal, decimal = match.groups()
        if hexadecimal is not None:
            value = int(hexadecimal, 16)
        elif octal is not None:
            value = int(octal, 8)
        else:
            value = int(decimal)
        value = -value if sign == '-' else value
        if _INT64[0] <= value <= _INT64[1]:
            return value   # else strtol's ERANGE: strtod reads it below
    if text in _SPECIAL_FLOATS:
        return _SPECIAL_FLOATS[text]
    return _strtod(text)


def _strtod(text):
    """Return the double C ``strtod`` reads from all of ``text``, or ``text`` if it is not one."""
    if _STRTOD_DECIMAL.fullmatch(text):
        value = float(text)
    elif _STRTOD_HEX.fullmatch(text):
        stripped = text.strip()
        sign = -1.0 if stripped.startswith('-') else 1.0
        try:
            value = sign * float.fromhex(stripped.lstrip('+-'))
        except OverflowError:
            return text
    else:
        match = _STRTOD_WORD.fullmatch(text)
        if match is None:
            return text
        sign_text, infinity, _ = match.groups()
        return (-1.0 if sign_text == '-' else 1.0) * (math.inf if infinity else math.nan)
    if math.isinf(value) or (abs(value) < sys.float_info.min and not _exact(text, value)):
        return text   # strtod's ERANGE: beyond the float range, or rounded below it
    return value


def _exact(number, value):
    """Whether the float ``value`` is exactly the decimal or hexadecimal ``number`` text."""
    digits = number.strip().lstrip('+-')
    hexadecimal = digits[:2] in ('0x', '0X')
    parts = re.split('[pP]' if hexadecimal else '[eE]', digits, maxsplit=1)
    significand, exponent = parts[0][2 if hexadecimal else 0:], parts[1:] or ['0']
    if value == 0.0:   # exact for a zero significand only (and a huge exponent costs nothing)
        return not significand.strip('0.')
    from decimal import Decimal   # (and fractions): only for subnormal numbers
    from fractions import Fraction
    if hexadecimal:
        whole, _, fraction = significand.partition('.')
        exact = (Fraction(int(whole + fraction, 16), 16 ** len(fraction))
                 * Fraction(2) ** int(exponent[0]))
    else:
        exact = Fraction(Decimal(digits))
    return Fraction(abs(value)) == exact


class _RosLoader(yaml.SafeLoader):
    """SafeLoader with ROS scalar typing, string keys and duplicate keys rejected."""

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


_ROS_SCALAR_TAG = 'tag:rotation_node,2024:ros-scalar'
# Every plain scalar resolves to the ROS tag: the resolvers PyYAML tries for any
# first character (None) and for the empty scalar (''), in a table of this class
# only (yaml.SafeLoader is unchanged).
_RosLoader.yaml_implicit_resolvers = {
    key: [(_ROS_SCALAR_TAG, re.compile(r'.*', re.DOTALL))] for key in (None, '')}
# The tag is only ever resolved for scalars, whose node is a ScalarNode; mypy sees a Node.
_RosLoader.add_constructor(
    _ROS_SCALAR_TAG,
    lambda loader, node: ros_scalar(loader.construct_scalar(node)))  # type: ignore[arg-type]


class _RosLoaderWithoutAliases(_RosLoader):
    """The loader of parameters files: rcl refuses aliases there, so does this one."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            raise yaml.composer.ComposerError(
                None, None, 'aliases (*name) are not allowed in a parameters file (ROS refuses '
                'them)', self.peek_event().start_mark)
        return super().compose_node(parent, index)


def _check_size(node, label, error):
    """Refuse a document that, with its aliases expanded, is too large or too deep."""
    sizes = {}   # id(node) -> expanded node count, for nodes already counted
    stack = [(node, 1, False)]
    while stack:
        current, depth, children_done = stack.pop()
        if id(current) in sizes:
            continue
        if depth > MAX_DEPTH:
            raise error(f'{label}: nested deeper than {MAX_DEPTH} levels; refused')
        if isinstance(current, yaml.ScalarNode):
            sizes[id(current)] = 1
            continue
        children = ([item for pair in current.value for item in pair]
                    if isinstance(current, yaml.MappingNode) else list(current.value))
        if children_done:
            total = 1 + sum(sizes.get(id(child), 0) for child in children)
            if total > MAX_NODES:
                raise error(f'{label}: its aliases expand it beyond {MAX_NODES} YAML nodes; '
                            'refused')
            sizes[id(current)] = total
            continue
        stack.append((current, depth, True))
        stack.extend((child, depth + 1, False) for child in children
                     if id(child) not in sizes)


def load_ros_yaml(path: Any, label: str, error: Type[Exception], *,
                  aliases: bool = True) -> Any:
    """
    Read one YAML document from a file with the rules of this module.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    label : str
        How error messages name the file, e.g. ``'parameters file config/params.yaml'``.
    error : type
        The exception class raised (e.g. ParameterError, SceneError).
    aliases : bool, optional
        Allow YAML aliases (``*name``), within the bounds; a ROS parameters file
        may not have any.

    Returns
    -------
    object
        The document: dict, list, scalar, or None for an empty file.

    Raises
    ------
    error
        One line starting with ``label``: the file cannot be read, is too large,
        is not valid YAML (with line and column), repeats a key, or expands
        beyond the bounds.

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
    loader = (_RosLoader if aliases else _RosLoaderWithoutAliases)(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_size(node, label, error)
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1}, column {mark.column + 1})' if mark else ''
        problem = getattr(exc, 'problem', None) or str(exc).replace('\n', ' ')
        raise error(f'{label}: invalid YAML{where}: {problem}') from None
    finally:
        loader.dispose()
