"""
Fast CDR encoding and decoding of fixed-layout ROS 2 messages.

rclpy's ``serialize_message`` and ``deserialize_message`` spend tens of
microseconds per message, mostly building or reading the Python message
object (an empty ``sensor_msgs/Imu()`` alone takes ~15 us). For the types
that ``rotation_bag convert`` and the scene simulator read and write, this
module does the same work with one precompiled ``struct.Struct`` call.

A type has a *fixed layout* when its fields, recursively, are booleans,
integers, floats, fixed-size arrays of those, and unbounded strings: no
sequences, bounded or wide strings. std_msgs/Header, sensor_msgs/Imu,
nav_msgs/Odometry and the geometry_msgs ``*Stamped`` types are. Once the
lengths of its strings are known, such a message is one fixed ``struct``
format; the formats are derived from the type's rosidl definition
(``SLOT_TYPES``) and compiled once per set of string lengths.

The CDR written by rmw_fastrtps in Jazzy (plain CDR, XCDR version 1):

- a 4-byte encapsulation header, ``00 01 00 00`` for little-endian CDR;
- then the payload, in which every primitive is aligned to its size,
  relative to the start of the payload (after the encapsulation header);
- a string is a uint32 length that counts a terminating NUL, then the UTF-8
  bytes and the NUL; a fixed array is its elements; a sequence is a uint32
  count and its elements (aligned as the element type even when empty); a
  nested message is its fields, with no alignment of its own;
- a message without strings or sequences (a "plain" type) is padded at the
  end to a multiple of 4 bytes.

Decoding returns read-only *views*: named tuples, one class per message
type, with the message's field names (``view.header.stamp.sec``,
``view.orientation.x``) and fixed arrays as tuples. They stand in for the
rclpy message wherever fields are only read, as in
:meth:`rotation_node.pipeline.ConversionPipeline.process_values`. Data that is
not little-endian CDR is left to rclpy. Encoding gives rclpy's bytes, except
that the padding is zero where rclpy leaves it uninitialised, so that equal
messages give equal bytes and bags are reproducible.
"""
from __future__ import annotations

import collections
import functools
import operator
import struct
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Sequence, Tuple

import numpy as np
from rosidl_parser.definition import Array, BasicType, NamespacedType, UnboundedString
from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_class

#: Encapsulation header of little-endian plain CDR (the options bytes zero).
CDR_LE = b'\x00\x01\x00\x00'
_CDR_LE_ID = CDR_LE[:2]   # the representation identifier; the options are ignored
_ENCAPSULATION_SIZE = len(CDR_LE)
_UINT32 = struct.Struct('<I')
_STRING = 's'   # the struct code of a string's bytes (after its uint32 length)
# struct codes of the rosidl basic types with a fixed size, which is also their alignment.
_STRUCT_CODES = {
    'boolean': '?', 'int8': 'b', 'uint8': 'B', 'int16': 'h', 'uint16': 'H', 'int32': 'i',
    'uint32': 'I', 'int64': 'q', 'uint64': 'Q', 'float': 'f', 'double': 'd'}
# Structs kept per type, one per distinct set of string lengths; a bag with more
# distinct frame_id lengths than this recompiles (correct, only slower).
_MAX_CACHED_STRUCTS = 64


def _padding(offset, alignment):
    """Bytes of padding that align ``offset`` to a multiple of ``alignment``."""
    return -offset % alignment


def _string_at(position, values):
    """
    Return the text of the string whose bytes are ``values[position]``.

    As rclpy (Fast CDR) reads it: the NUL dropped if there is one, bytes that
    are not UTF-8 replaced.
    """
    raw = values[position]
    return (raw[:-1] if raw[-1:] == b'\0' else raw).decode('utf-8', 'replace')


class _NotFixedLayout(Exception):
    """Internal: a field whose CDR size depends on its value (a sequence...)."""


class _Leaf(NamedTuple):
    """One primitive field (or fixed array) of a message, in CDR order."""

    path: str     # 'header.stamp.sec'
    code: str     # struct code; _STRING for a string
    count: int  # type: ignore[assignment]  # elements of a fixed array; 0: a value or string


_STRING_LENGTH = _Leaf('<string length>', 'I', 0)


@functools.lru_cache(maxsize=None)
def _view_class(msg_class):
    """Return the named tuple class that views messages of ``msg_class``."""
    # mypy cannot type a namedtuple whose fields are only known at run time.
    view = collections.namedtuple(  # type: ignore[misc]
        msg_class.__name__, msg_class.get_fields_and_field_types())
    view.__doc__ = (f'Read-only view of a decoded {msg_class.__module__.split(".")[0]}/msg/'
                    f'{msg_class.__name__} (rotation_node.wire.cdr).')
    return view


def _compile(msg_class, prefix, leaves, position):
    """
    Append the leaves of ``msg_class`` to ``leaves``; return ``(build, position)``.

    ``build(values)`` makes the view of the message from the tuple its type's
    struct unpacks, whose items from ``position`` on are this message's: one per
    value, ``count`` per array and two per string (length, bytes with the NUL).
    The returned position is the first item after them.
    """
    new = tuple.__new__   # the named tuple's own __new__ is a Python function: slower
    view = _view_class(msg_class)
    start, getters, values_only = position, [], True
    for name, slot in zip(msg_class.get_fields_and_field_types(), msg_class.SLOT_TYPES):
        path = prefix + name
        value_type = slot.value_type if isinstance(slot, Array) else slot
        if isinstance(slot, NamespacedType):
            getter, position = _compile(
                message_class('/'.join((*slot.namespaces, slot.name))), path + '.', leaves,
                position)
            values_only = False
        elif isinstance(slot, UnboundedString):
            leaves.append(_Leaf(path, _STRING, 0))
            getter = functools.partial(_string_at, position + 1)
            position += 2
            values_only = False
        elif isinstance(value_type, BasicType) and value_type.typename in _STRUCT_CODES:
            code = _STRUCT_CODES[value_type.typename]
            if slot is value_type:
                leaves.append(_Leaf(path, code, 0))
                getter = operator.itemgetter(position)
                position += 1
            else:
                leaves.append(_Leaf(path, code, slot.size))
                getter = operator.itemgetter(slice(position, position + slot.size))
                position += slot.size
                values_only = False
        else:
            raise _NotFixedLayout(f'{path} ({type(slot).__name__})')
        getters.append(getter)
    if not getters:
        raise _NotFixedLayout(f'{msg_class.__name__} has no fields')
    if values_only:   # no nested message, array or string: a slice of the unpacked tuple
        end = position
        return (lambda values: new(view, values[start:end])), position
    return (lambda values: new(view, [get(values) for get in getters])), position


class FixedLayoutCodec:
    """
    CDR decoder and encoder of one fixed-layout message type.

    Use :func:`fixed_layout_codec` to get one (it is cached and tells which
    types have a fixed layout).

    Parameters
    ----------
    type_name : str
        ``'pkg/msg/Type'``.

    Raises
    ------
    BagError
        If the type is unknown or has no fixed layout.

    Attributes
    ----------
    type_name : str
    message_class : type
        The rclpy message class, used for data that is not little-endian CDR.
    view_class : type
        The named tuple class :meth:`decode` returns.

    """

    def __init__(self, type_name: str) -> None:
        self.type_name = type_name
        self.message_class = message_class(type_name)
        self._leaves: List[_Leaf] = []
        try:
            self._build, _ = _compile(self.message_class, '', self._leaves, 0)
        except _NotFixedLayout as error:
            raise BagError(f'{type_name} has no fixed CDR layout: {error}') from None
        self.view_class = _view_class(self.message_class)
        self._getters = [operator.attrgetter(leaf.path) for leaf in self._leaves]
        # For each string, the bytes from the end of the previous one (or the
        # payload start) to the end of its uint32 length, by that offset % 8.
        self._to_string_lengths = [
            tuple(_fixed_format([*run, _STRING_LENGTH], start)[1] - start for start in range(8))
            for run in _runs_before_strings(self._leaves)[0]]
        self._structs: Dict[Any, Any] = {}
        # rmw_fastrtps pads types without strings ("plain" types) to 4 bytes;
        # readers do not need it, the decoder does not expect it.
        self._end_padding = (bytes(_padding(self._struct(()).size, 4))
                             if not self._to_string_lengths else b'')

    @property
    def leaves(self) -> Tuple[_Leaf, ...]:
        """Return the primitive fields in CDR order: ``path``, struct ``code``, ``count``."""
        return tuple(self._leaves)

    @property
    def to_string_lengths(self) -> List[Tuple[int, ...]]:
        """
        Per string, the bytes from the previous string's end to the end of this one's length.

        Indexed by that start offset modulo 8 (the padding depends on it): the
        table :meth:`decode` walks to find the strings' lengths.
        """
        return self._to_string_lengths

    def leaf_offsets(self, string_lengths: Sequence[int]) -> Dict[str, int]:
        """
        Return ``{path: payload offset}`` of every field when the strings have these lengths.

        Offsets count from the payload start (after the 4-byte encapsulation
        header); a string's offset is that of its uint32 length, an array's
        that of its first element. ``string_lengths`` include the NUL.
        """
        offsets, offset, strings = {}, 0, iter(string_lengths)
        for leaf in self._leaves:
            if leaf.code == _STRING:
                offset += _padding(offset, 4)
                offsets[leaf.path] = offset
                offset += 4 + next(strings)
            else:
                size = struct.calcsize(leaf.code)
                offset += _padding(offset, size)
                offsets[leaf.path] = offset
                offset += size * (leaf.count or 1)
        return offsets

    def payload_size(self, string_lengths: Sequence[int]) -> int:
        """Bytes of the payload :meth:`decode` reads when the strings have these lengths."""
        return self._struct(tuple(string_lengths)).size

    def _struct(self, string_lengths):
        """Return the struct of the payload when the strings have these lengths (NUL included)."""
        compiled = self._structs.get(string_lengths)
        if compiled is None:
            if len(self._structs) >= _MAX_CACHED_STRUCTS:
                self._structs.clear()
            compiled = self._structs[string_lengths] = struct.Struct(
                _payload_format(self._leaves, string_lengths))
        return compiled

    def decode(self, data: bytes) -> Any:
        """
        Decode one message.

        Parameters
        ----------
        data : bytes-like
            CDR with its encapsulation header, as in a bag or on the wire.

        Returns
        -------
        view or rclpy message
            A :attr:`view_class` instance for little-endian CDR; for any other
            encapsulation, what rclpy's ``deserialize_message`` makes of it.

        Raises
        ------
        BagError
            If the data is too short for the message, or rclpy rejects data
            that is not little-endian CDR.

        """
        if data[:2] != _CDR_LE_ID:
            from rclpy.serialization import deserialize_message   # loads rcl: only here
            try:
                return deserialize_message(bytes(data), self.message_class)
            except Exception as error:   # rclpy raises RMWError, RuntimeError...
                raise BagError(f'{self.type_name}: encapsulation {bytes(data[:4]).hex(" ")} '
                               f'is not little-endian CDR and rclpy failed: {error}') from None
        size, lengths = len(data) - _ENCAPSULATION_SIZE, []
        offset = 0   # in the payload
        for to_length in self._to_string_lengths:
            offset += to_length[offset & 7]   # past the string's uint32 length
            if offset > size:
                raise self._truncated(data, offset)
            (length,) = _UINT32.unpack_from(data, _ENCAPSULATION_SIZE + offset - 4)
            offset += length
            if offset > size:
                raise self._truncated(data, offset)
            lengths.append(length)
        payload = self._struct(tuple(lengths))
        if payload.size > size:
            raise self._truncated(data, payload.size)
        return self._build(payload.unpack_from(data, _ENCAPSULATION_SIZE))

    def _truncated(self, data, payload_size):
        return BagError(f'{self.type_name}: CDR data of {len(data)} bytes is truncated '
                        f'(needs at least {_ENCAPSULATION_SIZE + payload_size})')

    def encode(self, msg: Any) -> bytes:
        """
        Encode one message.

        Parameters
        ----------
        msg : object
            Anything with the type's fields as attributes: an rclpy message of
            the type, or a view.

        Returns
        -------
        bytes
            Little-endian CDR with its encapsulation header and zero padding.

        Raises
        ------
        BagError
            If a field holds a value its type cannot (an integer out of range,
            an array of the wrong length...).

        """
        values: List[Any] = []
        lengths: List[int] = []
        for leaf, get in zip(self._leaves, self._getters):
            value = get(msg)
            if leaf.code == _STRING:
                raw = value.encode()
                lengths.append(len(raw) + 1)
                values += (len(raw) + 1, raw)
            elif leaf.count:   # rclpy holds these arrays as numpy arrays: tolist() is faster
                values.extend(value.tolist() if isinstance(value, np.ndarray) else value)
            else:
                values.append(value)
        try:
            return CDR_LE + self._struct(tuple(lengths)).pack(*values) + self._end_padding
        except struct.error:
            raise BagError(f'cannot encode {self.type_name}: {self._bad_field(msg)}') from None

    def _bad_field(self, msg):
        """Name the first field whose value cannot be packed, and why."""
        for leaf, get in zip(self._leaves, self._getters):
            value = get(msg)
            if leaf.code == _STRING:
                continue
            try:
                struct.pack(f'<{leaf.count or 1}{leaf.code}', *(value if leaf.count else (value,)))
            except struct.error as error:
                return f'{leaf.path} = {value!r}: {error}'
        return 'the values do not match the fields'

    def stamped_encoder(self) -> Callable[[Any, Sequence[float]], bytes]:
        """
        Return an encoder from a header and numbers, without a message object.

        For a type that is a std_msgs/Header followed by numbers only
        (geometry_msgs/Vector3Stamped, QuaternionStamped...).

        Returns
        -------
        callable
            ``encode(header, numbers) -> bytes``: ``header`` has ``stamp.sec``,
            ``stamp.nanosec`` and ``frame_id`` (an rclpy Header or a view),
            ``numbers`` the fields after it, flattened in definition order
            (``(x, y, z)`` for Vector3Stamped).

        Raises
        ------
        BagError
            If the type does not have that form.

        """
        paths = [leaf.path for leaf in self._leaves]
        if (paths[:3] != ['header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id']
                or any(leaf.code == _STRING for leaf in self._leaves[3:])):
            raise BagError(f'{self.type_name} is not a std_msgs/Header followed by numbers')
        structs = self._struct

        def encode(header, numbers):
            if isinstance(numbers, np.ndarray):
                numbers = numbers.tolist()   # Python floats: packed faster than numpy's
            stamp, raw = header.stamp, header.frame_id.encode()
            length = len(raw) + 1
            try:
                return CDR_LE + structs((length,)).pack(
                    stamp.sec, stamp.nanosec, length, raw, *numbers)
            except struct.error as error:
                raise BagError(f'cannot encode {self.type_name} from stamp {stamp} and '
                               f'{list(numbers)}: {error}') from None
        return encode


def _fixed_format(leaves, offset):
    """
    ``struct`` format of string-free ``leaves`` from payload ``offset``, and the offset after them.

    Each leaf is preceded by the padding that aligns it to its size. A
    string's uint32 length is included when ``leaves`` are followed by one.
    """
    parts = []
    for leaf in leaves:
        size, count = struct.calcsize(leaf.code), leaf.count or 1
        padding = _padding(offset, size)
        parts.append(f'{padding}x{count}{leaf.code}')
        offset += padding + size * count
    return ''.join(parts), offset


def _runs_before_strings(leaves):
    """Return the leaves between strings: the runs before each string, then after the last."""
    runs: List[List[_Leaf]] = [[]]
    for leaf in leaves:
        if leaf.code == _STRING:
            runs.append([])
        else:
            runs[-1].append(leaf)
    return runs[:-1], runs[-1]


def _payload_format(leaves, string_lengths):
    """``struct`` format of a whole payload, given the lengths of its strings (NUL included)."""
    parts, offset = ['<'], 0
    before_strings, last = _runs_before_strings(leaves)
    for run, length in zip(before_strings, string_lengths, strict=True):
        fixed, offset = _fixed_format([*run, _STRING_LENGTH], offset)
        parts += (fixed, f'{length}{_STRING}')
        offset += length
    parts.append(_fixed_format(last, offset)[0])
    return ''.join(parts)


@functools.lru_cache(maxsize=None)
def fixed_layout_codec(type_name: str) -> Optional[FixedLayoutCodec]:
    """
    Return the codec of a message type, or None if its layout is not fixed.

    Parameters
    ----------
    type_name : str
        ``'pkg/msg/Type'``.

    Returns
    -------
    FixedLayoutCodec or None

    Raises
    ------
    BagError
        If the type name is malformed or the type is not installed.

    """
    message_class(type_name)   # an unknown type is an error, not "no codec"
    try:
        return FixedLayoutCodec(type_name)
    except BagError:
        return None


def float64_multi_array_encoder(layout: Any) -> Callable[[Sequence[float]], bytes]:
    """
    Return an encoder of std_msgs/Float64MultiArray messages with a given layout.

    Parameters
    ----------
    layout : std_msgs.msg.MultiArrayLayout
        Encoded once; every message gets it.

    Returns
    -------
    callable
        ``encode(data) -> bytes``: little-endian CDR with its encapsulation
        header and zero padding, ``data`` a sequence of floats.

    """
    payload = bytearray(_UINT32.pack(len(layout.dim)))
    for dim in layout.dim:
        label = dim.label.encode()
        payload += struct.pack(f'<I{len(label) + 1}s', len(label) + 1, label)
        payload += bytes(_padding(len(payload), 4))
        payload += struct.pack('<II', dim.size, dim.stride)
    payload += _UINT32.pack(layout.data_offset)
    head = CDR_LE + bytes(payload)
    padding = _padding(len(payload) + 4, 8)   # after the data's uint32 count

    def encode(data):
        if isinstance(data, np.ndarray):
            data = data.tolist()   # Python floats: packed faster than numpy's
        return head + struct.pack(f'<I{padding}x{len(data)}d', len(data), *data)
    return encode


@functools.lru_cache(maxsize=None)
def message_encoder(type_name: str) -> Optional[Callable[[Any], bytes]]:
    """
    Return ``encode(msg) -> bytes`` for a type this module encodes, or None.

    Parameters
    ----------
    type_name : str
        ``'pkg/msg/Type'``.

    Returns
    -------
    callable or None
        For fixed-layout types and std_msgs/Float64MultiArray: ``encode(msg)``
        of an rclpy message of the type, giving little-endian CDR with its
        encapsulation header and zero padding. None for other types.

    """
    if type_name == 'std_msgs/msg/Float64MultiArray':
        return lambda msg: float64_multi_array_encoder(msg.layout)(msg.data)
    codec = fixed_layout_codec(type_name)
    return None if codec is None else codec.encode
