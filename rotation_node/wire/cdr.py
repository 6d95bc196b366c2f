"""
CDR encoding and decoding of fixed-layout ROS 2 messages, one message or a block of them.

rclpy's (de)serialisation spends tens of microseconds per message building Python message
objects; here a type whose fields are, recursively, numbers, fixed arrays of them and
unbounded strings (Header, Imu, Odometry, the ``*Stamped`` types) has every field at a fixed
offset once its strings' lengths are known. That :class:`PayloadLayout`, computed from the
type's installed description (no rclpy, no message package), gives both forms of the codec:
a ``struct.Struct`` for one message and a numpy structured dtype for a block, so the two
agree by construction.

The format is rmw_fastrtps' plain little-endian CDR (XCDR1): a 4-byte encapsulation header
(``00 01 00 00``), then the payload, in which a primitive is aligned to its size from the
payload's start; a string is a uint32 length counting its NUL, then its bytes and the NUL; a
sequence is a uint32 count, then its elements aligned as the element type even when empty; a
nested message adds no alignment; a type without strings or sequences is padded to a multiple
of 4 bytes. Decoding returns read-only
named-tuple *views* with the message's field names (fixed arrays as tuples), which stand in
for rclpy messages wherever fields are only read; other encapsulations go to rclpy. Encoding
gives rclpy's bytes with zero padding (rclpy leaves it uninitialised), so equal messages give
equal bytes. The block decoder reads exactly what the per-message one reads, or declines.
"""
from __future__ import annotations

import collections
import functools
import operator
import struct
from typing import Any, Callable, Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np
from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_class, message_fields, split_type_name

#: Encapsulation header of little-endian plain CDR (the options bytes zero).
CDR_LE = b'\x00\x01\x00\x00'
#: Leaf paths of a std_msgs/Header that starts a message, in CDR order.
HEADER_PATHS = ('header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id')
_CDR_LE_ID = CDR_LE[:2]   # the representation identifier; the options are ignored
_ENCAPSULATION_SIZE = len(CDR_LE)
_UINT32 = struct.Struct('<I')
_STRING = 's'   # the struct code of a string's bytes (after its uint32 length)
# struct codes of the basic types with a fixed size (by their names in type descriptions),
# which is also their alignment; numpy reads the same codes with '<' as the same types.
_STRUCT_CODES = {
    'boolean': '?', 'int8': 'b', 'uint8': 'B', 'int16': 'h', 'uint16': 'H', 'int32': 'i',
    'uint32': 'I', 'int64': 'q', 'uint64': 'Q', 'float': 'f', 'double': 'd'}
# Layouts kept per type, one per distinct set of string lengths; a bag with more
# distinct frame_id lengths than this recomputes them (correct, only slower).
_MAX_CACHED_LAYOUTS = 64


def _padding(offset, alignment):
    return -offset % alignment


def _string_at(position, values):
    """Return the text of the string bytes ``values[position]`` as Fast CDR reads them."""
    raw = values[position]
    return (raw[:-1] if raw[-1:] == b'\0' else raw).decode('utf-8', 'replace')


class _NotFixedLayout(Exception):
    """A field whose CDR size depends on its value (a sequence...)."""


class _Leaf(NamedTuple):
    """One primitive field (or fixed array) of a message, in CDR order."""

    path: str     # 'header.stamp.sec'
    code: str     # struct code; _STRING for a string
    count: int  # type: ignore[assignment]  # elements of a fixed array; 0: a value or string


def _placed(leaves, string_lengths, offset=0):
    """
    Return ``[(start, end)]`` of each leaf in the payload, from ``offset``: CDR's alignment.

    Offsets count from the payload start (after the 4-byte encapsulation header). A primitive
    (or a fixed array's first element) sits at a multiple of its size; a string is its uint32
    length at a multiple of 4, then ``string_lengths``' next count of bytes (the NUL included).
    Nested messages add no alignment (the end padding is :class:`PayloadLayout`'s).
    """
    places, strings = [], iter(string_lengths)
    for leaf in leaves:
        if leaf.code == _STRING:
            offset += _padding(offset, 4)
            end = offset + 4 + next(strings)
        else:
            size = struct.calcsize(leaf.code)
            offset += _padding(offset, size)
            end = offset + size * (leaf.count or 1)
        places.append((offset, end))
        offset = end
    return places


class PayloadLayout:
    """
    Where each field of a fixed-layout type is when its strings have given lengths (NUL included).

    ``offsets[path]`` is a leaf's payload offset (a string's: its uint32 length); ``size`` the
    payload's bytes before ``end_padding`` (zeros up to a multiple of 4 for a type without
    strings); ``struct`` packs one payload as one item per value,
    ``count`` per fixed array and two per string (its length, its bytes with the NUL).
    """

    def __init__(self, leaves: Sequence[_Leaf], string_lengths: Tuple[int, ...]) -> None:
        places = _placed(leaves, string_lengths)
        self.leaves = leaves
        self.string_lengths = string_lengths
        self.offsets = {leaf.path: start for leaf, (start, _) in zip(leaves, places)}
        self.size = places[-1][1]
        self.end_padding = 0 if string_lengths else _padding(self.size, 4)
        parts, previous_end = ['<'], 0
        for leaf, (start, end) in zip(leaves, places):
            items = f'I{end - start - 4}{_STRING}' if leaf.code == _STRING else (
                f'{leaf.count or 1}{leaf.code}')   # a string: its length, its bytes
            parts.append(f'{start - previous_end}x{items}')
            previous_end = end
        self.struct = struct.Struct(''.join(parts))

    @functools.cached_property
    def dtype(self) -> np.dtype:
        """Return the structured dtype of one payload: a field per leaf, a string as its bytes."""
        names: List[str] = []
        formats: List[Any] = []
        offsets: List[int] = []
        strings = iter(self.string_lengths)
        for leaf in self.leaves:
            names.append(leaf.path)
            if leaf.code == _STRING:
                formats.append((np.uint8, (next(strings),)))
                offsets.append(self.offsets[leaf.path] + 4)
            else:
                formats.append((f'<{leaf.code}', (leaf.count,)) if leaf.count else f'<{leaf.code}')
                offsets.append(self.offsets[leaf.path])
        return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                         'itemsize': self.size})

    def encode_block(self, count: int, fields: Mapping[str, Any]) -> List[bytes]:
        """
        Return the CDR data of ``count`` messages from ``{leaf path: array with a row each}``.

        Strings are given as their bytes with the NUL; fields left out are zero. Each message's
        bytes are those :meth:`FixedLayoutCodec.encode` gives.
        """
        width = _ENCAPSULATION_SIZE + self.size + self.end_padding
        # Rows 8 bytes apart, each payload at a multiple of 8: the fields aligned
        # as in the payload, which numpy writes fastest.
        stride = width + _padding(width, 8)
        out = np.zeros(count * stride + 8, np.uint8)
        out = out[8 - _ENCAPSULATION_SIZE:][:count * stride].reshape(count, stride)
        out[:, :_ENCAPSULATION_SIZE] = np.frombuffer(CDR_LE, np.uint8)
        payload = out[:, _ENCAPSULATION_SIZE:_ENCAPSULATION_SIZE + self.size]
        strings = iter(self.string_lengths)
        for leaf in self.leaves:
            if leaf.code == _STRING:
                at = self.offsets[leaf.path]
                payload[:, at:at + 4] = np.frombuffer(_UINT32.pack(next(strings)), np.uint8)
        records = payload.view(self.dtype)[:, 0]
        for path, values in fields.items():
            records[path] = values
        return _rows(out, width)


class DecodedBlock(NamedTuple):
    """
    A block's messages as arrays, grouped by their strings' lengths.

    ``group[i]`` is message ``i``'s group; ``records[g]`` the group's messages in block order, a
    read-only structured array of its layout's dtype (``records[g]['orientation.x']``).
    """

    group: np.ndarray
    records: List[np.ndarray]


@functools.lru_cache(maxsize=None)
def _view_class(type_name):
    """Return the named tuple class that views messages of ``type_name``."""
    name = split_type_name(type_name)[2]
    view = collections.namedtuple(  # type: ignore[misc]
        name, [field.name for field in _fields(type_name)])
    view.__doc__ = f'Read-only view of a decoded {type_name} (rotation_node.wire.cdr).'
    return view


def _fields(type_name):
    fields = message_fields(type_name)
    if fields is None:
        raise _NotFixedLayout(f'{type_name} has no type description installed')
    return fields


def _compile(type_name, prefix, leaves, position):
    """
    Append the leaves of ``type_name`` to ``leaves``; return ``(build, next position)``.

    ``build(values)`` makes the message's view from the struct's unpacked tuple, whose items
    from ``position`` on are this message's.
    """
    new = tuple.__new__   # the named tuple's own __new__ is a Python function: slower
    view = _view_class(type_name)
    start, getters, values_only = position, [], True
    for field in _fields(type_name):
        path = prefix + field.name
        if field.field_type == 'nested_type' and not field.container:
            getter, position = _compile(field.nested_type_name, path + '.', leaves, position)
            values_only = False
        elif field.field_type == 'string' and not field.container:
            leaves.append(_Leaf(path, _STRING, 0))
            getter = functools.partial(_string_at, position + 1)
            position += 2
            values_only = False
        elif field.field_type in _STRUCT_CODES and field.container in ('', 'array'):
            code = _STRUCT_CODES[field.field_type]
            if not field.container:
                leaves.append(_Leaf(path, code, 0))
                getter = operator.itemgetter(position)
                position += 1
            else:
                leaves.append(_Leaf(path, code, field.capacity))
                getter = operator.itemgetter(slice(position, position + field.capacity))
                position += field.capacity
                values_only = False
        else:
            raise _NotFixedLayout(f'{path} ({field.field_type} {field.container or "value"})')
        getters.append(getter)
    if not getters:
        raise _NotFixedLayout(f'{type_name} has no fields')
    if values_only:   # no nested message, array or string: a slice of the unpacked tuple
        end = position
        return (lambda values: new(view, values[start:end])), position
    return (lambda values: new(view, [get(values) for get in getters])), position


class FixedLayoutCodec:
    """CDR codec of one fixed-layout type (get it from :func:`fixed_layout_codec`)."""

    def __init__(self, type_name: str) -> None:
        self.type_name = type_name
        leaves: List[_Leaf] = []
        try:
            self._build, _ = _compile(type_name, '', leaves, 0)
        except _NotFixedLayout as error:
            raise BagError(f'{type_name} has no fixed CDR layout: {error}') from None
        #: The primitive fields in CDR order.
        self.leaves = tuple(leaves)
        self.view_class = _view_class(type_name)
        self._getters = [operator.attrgetter(leaf.path) for leaf in leaves]
        # Per string, the bytes from the end of the previous one (or the payload start) to the
        # end of its uint32 length, by that offset % 8: how decode walks to the lengths.
        self._to_string_lengths: List[Tuple[int, ...]] = []
        run: List[_Leaf] = []
        for leaf in leaves:
            if leaf.code == _STRING:
                self._to_string_lengths.append(tuple(
                    _placed([*run, leaf], (0,), start)[-1][1] - start for start in range(8)))
                run = []
            else:
                run.append(leaf)
        self._layouts: Dict[Tuple[int, ...], PayloadLayout] = {}
        self._end_padding = b'' if self._to_string_lengths else bytes(self.layout(()).end_padding)

    @property
    def starts_with_header(self) -> bool:
        """Tell whether the type's first field is a std_msgs/Header."""
        return tuple(leaf.path for leaf in self.leaves[:3]) == HEADER_PATHS

    def layout(self, string_lengths: Tuple[int, ...]) -> PayloadLayout:
        """Return the layout of the payload when the strings have these lengths (NUL included)."""
        found = self._layouts.get(string_lengths)
        if found is None:
            if len(self._layouts) >= _MAX_CACHED_LAYOUTS:
                self._layouts.clear()
            found = self._layouts[string_lengths] = PayloadLayout(self.leaves, string_lengths)
        return found

    def decode(self, data: bytes) -> Any:
        """
        Decode one message (with its encapsulation header) into a view.

        Other encapsulations than little-endian CDR give rclpy's message. BagError if the data
        is truncated, or rclpy rejects it.
        """
        if data[:2] != _CDR_LE_ID:
            from rclpy.serialization import deserialize_message   # loads rcl: only here
            try:
                return deserialize_message(bytes(data), message_class(self.type_name))
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
        key = tuple(lengths)
        payload = (self._layouts.get(key) or self.layout(key)).struct
        if payload.size > size:
            raise self._truncated(data, payload.size)
        return self._build(payload.unpack_from(data, _ENCAPSULATION_SIZE))

    def _truncated(self, data, payload_size):
        return BagError(f'{self.type_name}: CDR data of {len(data)} bytes is truncated '
                        f'(needs at least {_ENCAPSULATION_SIZE + payload_size})')

    def decode_block(self, datas: Sequence[bytes]) -> Optional[DecodedBlock]:
        """
        Decode a block of messages into arrays holding :meth:`decode`'s values.

        None if the block is empty or a message is one the block form does not read exactly
        as :meth:`decode` does (not little-endian CDR, truncated, a string :meth:`decode`
        rewrites): then decode message by message (which raises where one is bad).
        """
        n = len(datas)
        lengths = np.fromiter(map(len, datas), dtype=np.int64, count=n)
        if n == 0 or lengths.min() < _ENCAPSULATION_SIZE:
            return None
        buffer = np.frombuffer(b''.join(datas), dtype=np.uint8)
        starts = np.cumsum(lengths) - lengths
        if not ((buffer[starts] == _CDR_LE_ID[0]) & (buffer[starts + 1] == _CDR_LE_ID[1])).all():
            return None
        payloads, sizes = starts + _ENCAPSULATION_SIZE, lengths - _ENCAPSULATION_SIZE
        keys = np.empty((n, len(self._to_string_lengths)), dtype=np.int64)
        offset = np.zeros(n, dtype=np.int64)
        for column, to_length in enumerate(self._to_string_lengths):
            offset += np.asarray(to_length)[offset & 7]   # decode's walk, all messages at once
            if (offset > sizes).any():
                return None
            at = payloads + offset - 4   # the string's uint32 length
            keys[:, column] = buffer[at[:, None] + np.arange(4)].view('<u4')[:, 0]
            offset += keys[:, column]
            if (offset > sizes).any():
                return None
        if (keys == keys[0]).all():   # the common case, much faster than np.unique
            unique, group = keys[:1], np.zeros(n, dtype=np.intp)
        else:
            unique, group = np.unique(keys, axis=0, return_inverse=True)
            group = group.reshape(-1)
        records = []
        for g, key in enumerate(unique.tolist()):
            layout = self.layout(tuple(key))
            members = group == g
            if (layout.size > sizes[members]).any():
                return None
            rows = np.lib.stride_tricks.sliding_window_view(buffer, layout.size)[payloads[members]]
            fields = rows.view(layout.dtype)[:, 0]
            fields.flags.writeable = False
            if not all(_canonical_strings(fields[leaf.path])
                       for leaf in self.leaves if leaf.code == _STRING):
                return None
            records.append(fields)
        return DecodedBlock(group, records)

    def encode(self, msg: Any) -> bytes:
        """
        Encode one message (an rclpy message or a view) as little-endian CDR.

        BagError if a field holds a value its type cannot (an integer out of range...).
        """
        values: List[Any] = []
        lengths: List[int] = []
        for leaf, get in zip(self.leaves, self._getters):
            value = get(msg)
            if leaf.code == _STRING:
                raw = value.encode()
                lengths.append(len(raw) + 1)
                values += (len(raw) + 1, raw)
            elif leaf.count:   # rclpy holds these arrays as numpy arrays: tolist() is faster
                values.extend(value.tolist() if isinstance(value, np.ndarray) else value)
            else:
                values.append(value)
        key = tuple(lengths)
        try:
            return (CDR_LE + (self._layouts.get(key) or self.layout(key)).struct.pack(*values)
                    + self._end_padding)
        except struct.error:
            raise BagError(f'cannot encode {self.type_name}: {self._bad_field(msg)}') from None

    def _bad_field(self, msg):
        """Return the first field whose value cannot be packed, and why."""
        for leaf, get in zip(self.leaves, self._getters):
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
        Return ``encode(header, numbers) -> bytes`` for a Header followed by numbers only.

        ``numbers`` are the fields after the header, flattened in definition order (``(x, y,
        z)`` for Vector3Stamped). BagError if the type does not have that form.
        """
        if not self.starts_with_header or any(leaf.code == _STRING for leaf in self.leaves[3:]):
            raise BagError(f'{self.type_name} is not a std_msgs/Header followed by numbers')
        layouts, layout = self._layouts, self.layout

        def encode(header, numbers):
            if isinstance(numbers, np.ndarray):
                numbers = numbers.tolist()   # Python floats: packed faster than numpy's
            stamp, raw = header.stamp, header.frame_id.encode()
            length = len(raw) + 1
            try:
                return CDR_LE + (layouts.get((length,)) or layout((length,))).struct.pack(
                    stamp.sec, stamp.nanosec, length, raw, *numbers)
            except struct.error as error:
                raise BagError(f'cannot encode {self.type_name} from stamp {stamp} and '
                               f'{list(numbers)}: {error}') from None
        return encode


def _canonical_strings(strings):
    """Tell whether every row of string bytes (NUL included) is what encode writes for its text."""
    if strings.shape[1] and (strings[:, -1] == 0).all() and (strings < 0x80).all():
        return True   # ASCII and a final NUL, the common case
    rows = np.unique(strings, axis=0) if strings.shape[1] else strings[:1]
    return all(_string_at(0, (row,)).encode() + b'\0' == row
               for row in map(bytes, rows))


def _rows(rows, width):
    """Return the first ``width`` bytes of each row of a C-contiguous uint8 array, as bytes."""
    if len(rows) < 2:
        return [row.tobytes()[:width] for row in rows]
    return list(_row_slicer(len(rows), width, rows.shape[1])(rows.tobytes()))


@functools.lru_cache(maxsize=16)
def _row_slicer(count, width, stride):
    """Return a function giving the rows of bytes of ``count`` rows ``stride`` apart, in C."""
    return operator.itemgetter(*(slice(start, start + width)
                                 for start in range(0, count * stride, stride)))


@functools.lru_cache(maxsize=None)
def fixed_layout_codec(type_name: str) -> Optional[FixedLayoutCodec]:
    """Return the codec of a type, None if its layout is not fixed; BagError if it is unknown."""
    if message_fields(type_name) is None:
        message_class(type_name)   # an unknown type is an error, not "no codec"
        return None   # installed without a type description: rclpy's to encode and decode
    try:
        return FixedLayoutCodec(type_name)
    except BagError:
        return None


def _float64_multi_array_head(layout):
    """Return a Float64MultiArray's CDR up to its data's count, and the padding after that."""
    payload = bytearray(_UINT32.pack(len(layout.dim)))
    for dim in layout.dim:
        label = dim.label.encode()
        payload += struct.pack(f'<I{len(label) + 1}s', len(label) + 1, label)
        payload += bytes(_padding(len(payload), 4))
        payload += struct.pack('<II', dim.size, dim.stride)
    payload += _UINT32.pack(layout.data_offset)
    # A float64 sequence's elements are 8-aligned after its count, even when empty.
    return CDR_LE + bytes(payload), _padding(len(payload) + 4, 8)


def float64_multi_array_encoder(layout: Any) -> Callable[[Sequence[float]], bytes]:
    """Return ``encode(data) -> bytes`` of std_msgs/Float64MultiArray messages with ``layout``."""
    head, padding = _float64_multi_array_head(layout)

    def encode(data):
        if isinstance(data, np.ndarray):
            data = data.tolist()   # Python floats: packed faster than numpy's
        return head + struct.pack(f'<I{padding}x{len(data)}d', len(data), *data)
    return encode


def float64_multi_array_block_encoder(layout: Any, width: int
                                      ) -> Callable[[np.ndarray], List[bytes]]:
    """Return ``encode(data (messages, width)) -> list of bytes``, a message per row."""
    head, padding = _float64_multi_array_head(layout)
    prefix = np.frombuffer(head + struct.pack(f'<I{padding}x', width), np.uint8)

    def encode(data):
        out = np.empty((len(data), len(prefix) + 8 * width), np.uint8)
        out[:, :len(prefix)] = prefix
        out[:, len(prefix):].view('<f8')[...] = data
        return _rows(out, out.shape[1])
    return encode


@functools.lru_cache(maxsize=None)
def message_encoder(type_name: str) -> Optional[Callable[[Any], bytes]]:
    """Return ``encode(msg) -> bytes`` for fixed-layout types and Float64MultiArray, else None."""
    if type_name == 'std_msgs/msg/Float64MultiArray':
        return lambda msg: float64_multi_array_encoder(msg.layout)(msg.data)
    codec = fixed_layout_codec(type_name)
    return None if codec is None else codec.encode
