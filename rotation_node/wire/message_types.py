"""
ROS 2 message types by name (``'pkg/msg/Type'``): classes, fields, definitions, type hashes.

Classes come from the Python message packages (imported only where a message object is
needed); fields, definitions and hashes from the ``.msg`` and ``.json`` files installed under
``<prefix>/share/<pkg>/msg/``, ``<prefix>`` each entry of ``AMENT_PREFIX_PATH`` and then
``sys.prefix`` (where PyPI wheels install them).
"""
import functools
import importlib
import json
import os
import re
import sys
from typing import NamedTuple, Optional, Tuple

from rotation_node.errors import BagError

_NAME = r'[A-Za-z][A-Za-z0-9_]*'
_TYPE_NAME = re.compile(rf'({_NAME})/({_NAME})/({_NAME})')
_SHORT_TYPE_NAME = re.compile(rf'({_NAME})/({_NAME})')

# Field types in a .msg text ("foo_msgs/Bar" in "foo_msgs/Bar[] bar"), the same
# expression rosbag2's LocalMessageDefinitionSource uses, so that the
# dependency set, and therefore the concatenated definition, is the same.
_MSG_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVE_TYPES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))
_DEFINITION_DELIMITER = '=' * 80 + '\n'
# The field types of REP-2011 type descriptions (type_description_interfaces/msg/FieldType):
# a basic type's id is its index here; plus 48 for a fixed array of it, 96 for a bounded
# sequence, 144 for an unbounded sequence (the containers' order below).
_FIELD_TYPES = (
    'not_set', 'nested_type', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64',
    'uint64', 'float', 'double', 'long_double', 'char', 'wchar', 'boolean', 'byte', 'string',
    'wstring', 'fixed_string', 'fixed_wstring', 'bounded_string', 'bounded_wstring')
_CONTAINERS = ('', 'array', 'bounded_sequence', 'sequence')
_CONTAINER_STEP = 48
# The one uint8 field a type description gives a message without fields (rosidl's placeholder;
# the Python class has no field).
_EMPTY_MESSAGE_PLACEHOLDER = 'structure_needs_at_least_one_member'


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """Return ``('sensor_msgs', 'msg', 'Imu')`` of ``'sensor_msgs/msg/Imu'``; BagError if not."""
    match = _TYPE_NAME.fullmatch(type_name) if isinstance(type_name, str) else None
    if match is None:
        raise BagError(f"invalid message type name {type_name!r}: expected 'pkg/msg/Type'")
    package, kind, name = match.groups()
    return package, kind, name


@functools.lru_cache(maxsize=None)
def message_class(type_name: str) -> type:
    """Return the rosidl-generated class of a type; BagError if no installed package has it."""
    package, kind, name = split_type_name(type_name)
    try:
        module = importlib.import_module(f'{package}.{kind}')
    except ImportError:
        raise BagError(
            f'unknown message type {type_name!r}: '
            f'Python package {package}.{kind} is not installed') from None
    cls = getattr(module, name, None)
    if not (isinstance(cls, type) and hasattr(cls, '_TYPE_SUPPORT')):
        raise BagError(f'unknown message type {type_name!r}: {package}.{kind} has no {name}')
    return cls


def type_name_of(msg_class: type) -> str:
    """Return ``'pkg/msg/Type'`` of a rosidl-generated message class; BagError for another."""
    parts = getattr(msg_class, '__module__', '').split('.')
    if len(parts) < 3 or not hasattr(msg_class, '_TYPE_SUPPORT'):
        raise BagError(f'{msg_class!r} is not a ROS message class')
    return f'{parts[0]}/{parts[1]}/{msg_class.__name__}'


def _share_prefixes():
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return list(dict.fromkeys(prefixes))


def _interface_file(package, kind, name, extension):
    """Return the first ``<prefix>/share/<package>/<kind>/<name><extension>``, or None."""
    for prefix in _share_prefixes():
        path = os.path.join(prefix, 'share', package, kind, name + extension)
        if os.path.isfile(path):
            return path
    return None


def _definition_file(dependency_name):
    """Return the .msg file of a dependency named ``pkg/Type`` or ``pkg/msg/Type``, its package."""
    match = _SHORT_TYPE_NAME.fullmatch(dependency_name)
    package, kind, name = (
        (match[1], 'msg', match[2]) if match else split_type_name(dependency_name))
    path = _interface_file(package, kind, name, '.msg')
    if path is None:
        raise BagError(
            f'no message definition for {dependency_name!r}: {package}/{kind}/{name}.msg '
            f'not found under share/ of {os.pathsep.join(_share_prefixes())}')
    return path, package


def _dependencies(text, package):
    """Return the sorted non-primitive field types of a .msg text, qualified with ``package``."""
    names = set()
    for field_type in _MSG_FIELD_TYPE.findall(text):
        if field_type not in _PRIMITIVE_TYPES:
            names.add(field_type if '/' in field_type else f'{package}/{field_type}')
    return sorted(names)


@functools.lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """
    Return the complete ``ros2msg`` definition of a message type, as rosbag2 stores it.

    The type's .msg text, then each type it depends on, recursively and once, depth first in
    sorted order, each after a line of 80 ``=`` and ``MSG: <name as the .msg spells it>``
    (rosbag2's ``local_message_definition_source.cpp``). BagError if a .msg file is missing.
    """
    split_type_name(type_name)
    seen = set()

    def definition_with_dependencies(name):
        path, package = _definition_file(name)
        with open(path, encoding='utf-8') as stream:
            text = stream.read()
        parts = [text]
        for dependency in _dependencies(text, package):
            if dependency not in seen:
                seen.add(dependency)
                parts.append(f'\n{_DEFINITION_DELIMITER}MSG: {dependency}\n')
                parts.append(definition_with_dependencies(dependency))
        return ''.join(parts)

    return definition_with_dependencies(type_name)


@functools.lru_cache(maxsize=None)
def _type_description_file(type_name):
    """Return a type's REP-2011 ``share/<pkg>/msg/<Type>.json``, or None if not installed."""
    package, kind, name = split_type_name(type_name)
    path = _interface_file(package, kind, name, '.json')
    if path is None:
        return None
    try:
        with open(path, encoding='utf-8') as stream:
            return json.load(stream)
    except (OSError, ValueError) as error:
        raise BagError(f'the type description {path} of {type_name} is unreadable: '
                       f'{error}') from None


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """Return the REP-2011 type hash ``'RIHS01_...'``; ``''`` without a description, as rosbag2."""
    description = _type_description_file(type_name)
    hashes = [] if description is None else description.get('type_hashes', [])
    return next((h['hash_string'] for h in hashes if h.get('type_name') == type_name), '')


class MessageField(NamedTuple):
    """One field of a message type, as its REP-2011 type description gives it."""

    name: str
    field_type: str         # REP-2011's name ('double', 'string'...), 'nested_type' for a message
    container: str          # '', 'array', 'bounded_sequence' or 'sequence'
    capacity: int           # elements of an array, most of a bounded sequence; else 0
    nested_type_name: str   # 'std_msgs/msg/Header' for a nested field; else ''


@functools.lru_cache(maxsize=None)
def message_fields(type_name: str) -> Optional[Tuple[MessageField, ...]]:
    """
    Return a type's fields in order from its REP-2011 description, without importing its package.

    ``()`` for a message without fields (std_msgs/Empty); None without an installed description.
    BagError if the description is unreadable or describes another type.
    """
    description = _type_description_file(type_name)
    if description is None:
        return None
    try:
        described = description['type_description_msg']['type_description']
        fields = []
        for field in described['fields']:
            container, basic = divmod(field['type']['type_id'], _CONTAINER_STEP)
            fields.append(MessageField(
                field['name'], _FIELD_TYPES[basic], _CONTAINERS[container],
                field['type']['capacity'], field['type']['nested_type_name']))
    except (KeyError, TypeError, IndexError) as error:
        raise BagError(f'the type description of {type_name} is malformed '
                       f'({type(error).__name__} {error})') from None
    if described['type_name'] != type_name:
        raise BagError(f"the type description of {type_name} describes {described['type_name']}")
    if [field.name for field in fields] == [_EMPTY_MESSAGE_PLACEHOLDER]:
        return ()
    return tuple(fields)
