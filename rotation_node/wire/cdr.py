"""
Fast CDR encoding and decoding of fixed-layout ROS 2 messages, one message or a block of them.

rclpy's ``serialize_message`` and ``deserialize_message`` spend tens of
microseconds per message, mostly building or reading the Python message
object (an empty ``sensor_msgs/Imu()`` alone takes ~15 us). For the types
that ``rotation_bag convert``, the node and the scene simulator read and
write, this module does the same work with one precompiled ``struct.Struct``
call per message, or with numpy for a whole block of messages at once.

A type has a *fixed layout* when its fields, recursively, are booleans,
integers, floats, fixed-size arrays of those, and unbounded strings: no
sequences, bounded or wide strings. std_msgs/Header, sensor_msgs/Imu,
nav_msgs/Odometry and the geometry_msgs ``*Stamped`` types are. Once the
lengths of its strings are known, every field of such a message is at a
fixed offset: a :class:`PayloadLayout`, computed once per set of string
lengths from the type's fields as its installed type description gives them
(:func:`rotation_node.wire.message_types.message_fields`: neither rclpy nor
the Python message packages are imported to encode or decode), and given in the
two forms the codec uses: a ``struct.Struct`` that packs or unpacks one
message in one call (:meth:`FixedLayoutCodec.decode`, :meth:`~FixedLayoutCodec.encode`),
and a numpy structured dtype that reads or writes the fields of a block of
messages as arrays (:meth:`FixedLayoutCodec.decode_block`,
:meth:`PayloadLayout.encode_block`). Both come from the one layout, so the
two forms agree by construction.

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
messages give equal bytes and bags are reproducible. The block form reads
exactly what the per-message decoder reads, and declines (returns None for)
a block it cannot: data that is not little-endian CDR, a truncated message,
a string the per-message decoder would rewrite (not NUL-terminated UTF-8).
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


def _placed(leaves, string_lengths, offset=0):
    """
    Return where each leaf starts and ends in the payload, ``[(start, end)]``, from ``offset``.

    The alignment rules of CDR, applied here only: a primitive (or a fixed
    array's first element) at a multiple of its size; a string's uint32
    length at a multiple of 4, then its bytes, ``string_lengths`` of them in
    the order of the strings (the NUL included). A string starts at its length.
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
    Where each field of a fixed-layout type is when its strings have given lengths.

    Get one from :meth:`FixedLayoutCodec.layout`.

    Attributes
    ----------
    string_lengths : tuple of int
        Bytes of each string, in CDR order, its NUL included.
    offsets : dict
        ``{leaf path: payload offset}``, from the payload start (after the
        4-byte encapsulation header): a string's is that of its uint32
        length, a fixed array's that of its first element.
    size : int
        Bytes of the payload, without the end padding.
    end_padding : int
        Zero bytes after the payload: up to a multiple of 4 for a type
        without strings ("plain"), none otherwise.
    struct : struct.Struct
        Packs and unpacks one payload: one item per value, ``count`` per
        fixed array, two per string (its uint32 length, its bytes with the NUL).

    """

    def __init__(self, leaves: Sequence[_Leaf], string_lengths: Tuple[int, ...]) -> None:
        places = _placed(leaves, string_lengths)
        self._leaves = leaves
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
        """
        Return the numpy structured dtype of one payload, a field per leaf path.

        A value is a scalar field, a fixed array a subarray field, a string
        its bytes (the NUL included) as a uint8 subarray; its uint32 length is
        not a field (it is in :attr:`string_lengths`).
        """
        names: List[str] = []
        formats: List[Any] = []
        offsets: List[int] = []
        strings = iter(self.string_lengths)
        for leaf in self._leaves:
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
        Return the CDR data of ``count`` messages from arrays of their fields.

        Parameters
        ----------
        count : int
            Messages.
        fields : mapping
            ``{leaf path: array}`` with a row per message (as :meth:`FixedLayoutCodec.decode_block`
            gives them): a string as its bytes with the NUL, ``string_lengths``
            of them. Fields left out are zero.

        Returns
        -------
        list of bytes
            Little-endian CDR with its encapsulation header and zero padding,
            the bytes :meth:`FixedLayoutCodec.encode` gives for each message.

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
        for leaf in self._leaves:
            if leaf.code == _STRING:
                at = self.offsets[leaf.path]
                payload[:, at:at + 4] = np.frombuffer(_UINT32.pack(next(strings)), np.uint8)
        records = payload.view(self.dtype)[:, 0]
        for path, values in fields.items():
            records[path] = values
        return _rows(out, width)


class DecodedBlock(NamedTuple):
    """
    The messages of a block decoded into arrays, grouped by the lengths of their strings.

    Attributes
    ----------
    group : ndarray of int, shape (n,)
        Each message's group.
    records : list of ndarray
        Per group, its messages in block order as a structured array of its
        :attr:`PayloadLayout.dtype`: ``records[g]['orientation.x']``. Read-only.

    """

    group: np.ndarray
    records: List[np.ndarray]


@functools.lru_cache(maxsize=None)
def _view_class(type_name):
    """Return the named tuple class that views messages of ``type_name`` (``pkg/msg/Type``)."""
    name = split_type_name(type_name)[2]
    # mypy cannot type a namedtuple whose fields are only known at run time.
    view = collections.namedtuple(  # type: ignore[misc]
        name, [field.name for field in _fields(type_name)])
    view.__doc__ = f'Read-only view of a decoded {type_name} (rotation_node.wire.cdr).'
    return view


def _fields(type_name):
    """Return the fields of a type; one without an installed description has no fixed layout."""
    fields = message_fields(type_name)
    if fields is None:
        raise _NotFixedLayout(f'{type_name} has no type description installed')
    return fields


def _compile(type_name, prefix, leaves, position):
    """
    Append the leaves of ``type_name`` to ``leaves``; return ``(build, position)``.

    ``build(values)`` makes the view of the message from the tuple its type's
    struct unpacks, whose items from ``position`` on are this message's: one per
    value, ``count`` per array and two per string (length, bytes with the NUL).
    The returned position is the first item after them.
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
    view_class : type
        The named tuple class :meth:`decode` returns.

    """

    def __init__(self, type_name: str) -> None:
        self.type_name = type_name
        leaves: List[_Leaf] = []
        try:
            self._build, _ = _compile(type_name, '', leaves, 0)
        except _NotFixedLayout as error:
            raise BagError(f'{type_name} has no fixed CDR layout: {error}') from None
        self._leaves = tuple(leaves)
        self.view_class = _view_class(type_name)
        self._getters = [operator.attrgetter(leaf.path) for leaf in leaves]
        # For each string, the bytes from the end of the previous one (or the
        # payload start) to the end of its uint32 length, by that offset % 8:
        # the table decode and decode_block walk to find the strings' lengths.
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
    def leaves(self) -> Tuple[_Leaf, ...]:
        """Return the primitive fields in CDR order: ``path``, struct ``code``, ``count``."""
        return self._leaves

    @property
    def starts_with_header(self) -> bool:
        """Whether the type's first field is a std_msgs/Header (:data:`HEADER_PATHS`)."""
        return tuple(leaf.path for leaf in self._leaves[:3]) == HEADER_PATHS

    def layout(self, string_lengths: Tuple[int, ...]) -> PayloadLayout:
        """Return the layout of the payload when the strings have these lengths (NUL included)."""
        found = self._layouts.get(string_lengths)
        if found is None:
            if len(self._layouts) >= _MAX_CACHED_LAYOUTS:
                self._layouts.clear()
            found = self._layouts[string_lengths] = PayloadLayout(self._leaves, string_lengths)
        return found

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
        Decode a block of messages into arrays: :meth:`decode`'s values, as :class:`DecodedBlock`.

        Parameters
        ----------
        datas : sequence of bytes
            The CDR data of each message (with the encapsulation header).

        Returns
        -------
        DecodedBlock or None
            None if the block is empty or a message is not one the block form
            reads exactly as :meth:`decode` does (not little-endian CDR,
            truncated, a string :meth:`decode` rewrites): then decode the block
            message by message (which raises where a message is bad).

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
                       for leaf in self._leaves if leaf.code == _STRING):
                return None
            records.append(fields)
        return DecodedBlock(group, records)

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
        key = tuple(lengths)
        try:
            return (CDR_LE + (self._layouts.get(key) or self.layout(key)).struct.pack(*values)
                    + self._end_padding)
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
        if not self.starts_with_header or any(leaf.code == _STRING for leaf in self._leaves[3:]):
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
    """
    Whether each row of string bytes (its NUL included) reads back as the same bytes.

    That is, whether :meth:`FixedLayoutCodec.encode` writes these bytes for
    the text :meth:`FixedLayoutCodec.decode` reads from them (the text and a
    NUL): not so without a final NUL, or with bytes that are not UTF-8.
    """
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
    return CDR_LE + bytes(payload), _padding(len(payload) + 4, 8)   # after the data's uint32 count


def float64_multi_array_encoder(layout: Any) -> Callable[[Sequence[float]], bytes]:
    """
    Return an encoder of std_msgs/Float64MultiArray messages with a given layout.

    Parameters
    ----------
    layout : std_msgs.msg.MultiArrayLayout or rotation_node.registry.ArrayLayout
        Encoded once; every message gets it (read: ``dim``, each with
        ``label``, ``size``, ``stride``; ``data_offset``).

    Returns
    -------
    callable
        ``encode(data) -> bytes``: little-endian CDR with its encapsulation
        header and zero padding, ``data`` a sequence of floats.

    """
    head, padding = _float64_multi_array_head(layout)

    def encode(data):
        if isinstance(data, np.ndarray):
            data = data.tolist()   # Python floats: packed faster than numpy's
        return head + struct.pack(f'<I{padding}x{len(data)}d', len(data), *data)
    return encode


def float64_multi_array_block_encoder(layout: Any, width: int
                                      ) -> Callable[[np.ndarray], List[bytes]]:
    """
    Return an encoder of blocks of std_msgs/Float64MultiArray messages of ``width`` numbers.

    ``encode(data) -> list of bytes``, ``data`` of shape ``(messages, width)``:
    the bytes of :func:`float64_multi_array_encoder` for each row.
    """
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
