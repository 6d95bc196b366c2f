"""
ROS 1 bags (format 2.0) read as ROS 2 CDR messages, as ``rosbags-convert`` converts them.

Each message becomes the ROS 2 type of its name (installed, else rosbags' Jazzy type, else the
bag's definition); :class:`Ros1ToCdr` converts a chunk's messages of one type and layout at
once, byte for byte as rosbags does.
"""
import contextlib
import io
import os
from pathlib import Path
import struct
from typing import Any, Callable, Collection, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
from rosbags.interfaces import Connection, MessageDefinitionFormat, Nodetype
from rosbags.rosbag1 import ReaderError
from rosbags.rosbag1.reader import decompressors as ros1_decompressors
from rosbags.serde import SerdeError
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from rosbags.typesys.base import TypesysError
from rotation_node.bag.reading.ros1_chunks import ChunkedReader, MessageBatch
from rotation_node.bag.reading.rosbags_input import is_installed, RosbagsInput
from rotation_node.bag.records import BagMessage, TopicMetadata
from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_definition
from rotation_node.wire.qos_yaml import profiles_yaml

SUPPORTED_VERSION = '2.0'
# What rosbags raises for a bag it cannot read or a message it cannot convert.
_FORMAT_ERRORS = (ReaderError, SerdeError, TypesysError, struct.error)
#: ROS 1 types converted to a ROS 2 type of another name (as rosbags-convert renames them).
_RENAMED_TYPES = {'tf/msg/tfMessage': 'tf2_msgs/msg/TFMessage'}
_INFINITE = {'sec': 2147483647, 'nsec': 4294967295}
#: What a latched ROS 1 topic offers (rosbags-convert's QoS for it): reliable, transient local.
LATCHED_QOS_YAML = profiles_yaml([{
    'history': 'unknown', 'depth': 0, 'reliability': 'reliable', 'durability': 'transient_local',
    'deadline': _INFINITE, 'lifespan': _INFINITE, 'liveliness': 'automatic',
    'liveliness_lease_duration': _INFINITE, 'avoid_ros_namespace_conventions': False}])


def open_ros1_bag(path: Union[str, os.PathLike]) -> RosbagsInput:
    """Open a ROS 1 bag (format 2.0) to read it as ROS 2 CDR messages; BagError if it cannot."""
    path = str(path)
    reader = ChunkedReader(Path(path))
    try:
        reader.open()   # closes the file if it fails
    except _FORMAT_ERRORS as error:
        raise BagError(f'{path}: cannot read ROS 1 bag: {error}') from None
    try:
        typestore = bag_typestore(reader.connections)
        names = {decompress: name for name, decompress in ros1_decompressors.items()}
        compressions = {names.get(chunk.decompressor, 'unknown')
                        for chunk in reader.chunks.values()}
        # lz4 stays lz4, bz2 (not in MCAP) becomes zstd.
        compression = ('lz4' if 'lz4' in compressions
                       else 'zstd' if 'bz2' in compressions else 'none')
        return Ros1Input(path, reader, _FORMAT_ERRORS + (ValueError, IndexError),
                         _converted_topics(path, reader.connections, typestore), compression,
                         stored_compression='/'.join(sorted(compressions - {'none'})) or 'none')
    except BaseException as error:
        reader.close()
        if isinstance(error, _FORMAT_ERRORS):   # bag_typestore's (the converters say theirs)
            raise BagError(f'{path}: cannot read ROS 1 bag: {error}') from None
        raise


def bag_typestore(connections: Sequence[Connection]) -> Any:
    """
    Return a typestore of the connections' stored definitions, as rosbags' ``AnyReader`` builds it.

    Not ``AnyReader`` itself: importing it loads rosbags' rosbag2 modules (~0.05 s of start-up).

    TypesysError if a definition does not parse, ReaderError if a type's MD5 sum is not its
    connection's.
    """
    types: Dict[str, Any] = {}
    digests: Dict[str, str] = {}
    for connection in connections:
        if connection.msgdef.format == MessageDefinitionFormat.MSG:
            types.update(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        if connection.digest:
            digests[connection.msgtype] = connection.digest
    typestore = get_typestore(Stores.EMPTY)
    typestore.register(types)
    for type_name, digest in digests.items():
        if (have := typestore.generate_msgdef(type_name)[1]) != digest:
            raise ReaderError(f'Message type {type_name!r} hash mismatch {have} != {digest}')
    return typestore


class Ros1Input(RosbagsInput):
    """A ROS 1 bag read a chunk's batch at a time, converted in blocks by a :class:`Ros1ToCdr`."""

    def _messages(self, connections):
        by_id = {connection.id: connection for connection in connections}
        blocks = {id_: converter.block for id_, converter in self._to_cdr.items()
                  if id_ in by_id and isinstance(converter, Ros1ToCdr)}
        type_names = self.topics
        for batch in self._read(self._reader.message_batches(connections)):
            chunk, starts, lengths = batch.chunk, batch.starts, batch.lengths
            for k, (connection_id, time_ns, cdr) in enumerate(zip(
                    batch.connections.tolist(), batch.times.tolist(), _block_cdrs(batch, blocks))):
                connection = by_id[connection_id]
                if cdr is None:
                    start = starts[k].item()
                    cdr = self.cdr(connection, time_ns, chunk[start:start + lengths[k].item()])
                yield BagMessage(connection.topic, type_names[connection.topic], cdr, time_ns,
                                 time_ns)


def _block_cdrs(batch: MessageBatch, blocks: Dict[int, Callable[..., list]]
                ) -> List[Optional[bytes]]:
    """Return the CDR data of a batch's messages that convert in blocks, None for the others."""
    connections = batch.connections
    if len(connections) <= 1:   # one message: converted as one
        return [None] * len(connections)
    first = connections[0].item()
    if (connections == first).all():
        block = blocks.get(first)
        return [None] * len(connections) if block is None else block(
            batch.chunk, batch.starts, batch.lengths)
    result: List[Optional[bytes]] = [None] * len(connections)
    for connection_id in set(connections.tolist()):
        block = blocks.get(connection_id)
        if block is not None:
            members = np.flatnonzero(connections == connection_id)
            for index, cdr in zip(members.tolist(), block(batch.chunk, batch.starts[members],
                                                          batch.lengths[members])):
                result[index] = cdr
    return result


def ros2_typestore(type_names: Collection[str]) -> Any:
    """
    Return a typestore of ROS 2 types with at least ``type_names``, as ``rosbags-convert`` does.

    The installed definitions if all are (a few ms per type), else rosbags' Jazzy types (0.1 s).
    """
    store = get_typestore(Stores.EMPTY)
    try:
        for type_name in type_names:
            if type_name not in store.fielddefs:
                store.register(get_types_from_msg(message_definition(type_name), type_name))
    except (BagError, TypesysError):   # not installed, or not a definition rosbags parses
        return get_typestore(Stores.ROS2_JAZZY)
    return store


def same_wire_format(ros1: Any, ros2: Any, ros1_type: str, type_name: str) -> bool:
    """
    Whether a ROS 1 and a ROS 2 type have the same fields, the header's seq aside.

    As rosbags-convert's ``is_same_wireformat``: the ROS 1 data is then the CDR values, packed.
    """
    if ros1_type == 'std_msgs/msg/Header':
        return True
    fields, ros2_fields = ros1.fielddefs[ros1_type][1], ros2.fielddefs[type_name][1]
    if len(fields) != len(ros2_fields):
        return False
    for (_, field), (_, ros2_field) in zip(fields, ros2_fields):
        if field != ros2_field:
            return False
        if field[0] in (Nodetype.SEQUENCE, Nodetype.ARRAY):
            field, ros2_field = field[1][0], ros2_field[1][0]
        if field[0] == Nodetype.NAME and not same_wire_format(
                ros1, ros2, field[1], ros2_field[1]):
            return False
    return True


def _converter(ros1: Any, ros2: Any, ros1_type: str, type_name: str) -> Callable[[bytes], bytes]:
    """Return the conversion of a ROS 1 type's messages to the ROS 2 type's CDR, as rosbags'."""
    if same_wire_format(ros1, ros2, ros1_type, type_name):   # without importing rosbags.convert
        def converted(data: bytes) -> bytes:
            return bytes(ros2.ros1_to_cdr(data, type_name))

        return ros1_to_cdr_converter(ros2.fielddefs, type_name, converted) or converted
    from rosbags.convert.converter import generate_message_converter
    with contextlib.redirect_stdout(io.StringIO()):   # it prints its plans
        convert = generate_message_converter(ros1, ros2, ros1_type, type_name, {},
                                             src_is2=False, dst_is2=True)
    return lambda data: bytes(convert(data))


def _converted_topics(path, connections, ros1):
    """Yield ``(connection, ROS 2 TopicMetadata, ROS 1 data -> CDR)`` of every connection."""
    ros2 = ros2_typestore({_RENAMED_TYPES.get(c.msgtype, c.msgtype) for c in connections})
    converters: Dict[str, Callable[[bytes], bytes]] = {}
    for connection in connections:
        ros1_type = connection.msgtype
        type_name = _RENAMED_TYPES.get(ros1_type, ros1_type)
        try:
            if type_name not in ros2.fielddefs:   # as rosbags-convert: the bag's definition
                types = get_types_from_msg(
                    ros1.generate_msgdef(ros1_type, ros_version=2)[0], type_name)
                types.pop('std_msgs/msg/Header', None)
                ros2.register(types)
            if ros1_type not in converters:
                converters[ros1_type] = _converter(ros1, ros2, ros1_type, type_name)
        except _FORMAT_ERRORS + (KeyError,) as error:   # KeyError: a type left undefined
            raise BagError(f'{path}: cannot convert ROS 1 type {ros1_type} to ROS 2: '
                           f'{error}') from None
        installed = is_installed(type_name)
        yield connection, TopicMetadata(
            name=connection.topic, type_name=type_name,
            offered_qos_profiles=(LATCHED_QOS_YAML if connection.ext.latching
                                  else profiles_yaml([])),
            definition=None if installed else ros2.generate_msgdef(type_name, ros_version=2)[0],
            type_hash=None if installed else ros2.hash_rihs01(type_name)), converters[ros1_type]


#: Bytes of the primitive types in ROS 1 and CDR.
_PRIMITIVE_SIZES = {'bool': 1, 'byte': 1, 'char': 1, 'int8': 1, 'uint8': 1, 'int16': 2,
                    'uint16': 2, 'int32': 4, 'uint32': 4, 'int64': 8, 'uint64': 8,
                    'float32': 4, 'float64': 8}
_ENCAPSULATION = b'\x00\x01\x00\x00'   # little-endian CDR
_UINT32 = struct.Struct('<I')
_ZEROS = tuple(bytes(n) for n in range(8))
_SKIP, _RUN, _STRING, _SEQUENCE = range(4)


def _leaves(fielddefs, type_name, leaves):
    """
    Append the leaves of ``type_name`` in wire order; False if there is no fast converter.

    ``(_SKIP, 4)`` (a header's seq), ``(_RUN, size)``, ``(_STRING, 0)`` or ``(_SEQUENCE, (element
    steps, least ROS 1 bytes of an element))``.
    """
    if type_name == 'std_msgs/msg/Header':
        leaves.append((_SKIP, 4))
    for name, (kind, desc) in fielddefs[type_name][1]:
        if name == 'structure_needs_at_least_one_member':
            return False
        count = 1
        if kind == Nodetype.SEQUENCE:
            element: List[Tuple[int, Any]] = []
            element_kind, element_desc = desc[0]
            if not _leaves_of(fielddefs, element_kind, element_desc, element):
                return False
            least = sum(size if leaf in (_RUN, _SKIP) else 4 for leaf, size in element)
            leaves.append((_SEQUENCE, (_steps(element), max(1, least))))
            continue
        if kind == Nodetype.ARRAY:
            (kind, desc), count = desc
        for _ in range(count):
            if not _leaves_of(fielddefs, kind, desc, leaves):
                return False
    return True


def _leaves_of(fielddefs, kind, desc, leaves):
    """Append the leaves of one field (not an array) of kind ``kind``; False if unsupported."""
    if kind == Nodetype.NAME:
        return _leaves(fielddefs, desc, leaves)
    if kind == Nodetype.BASE and desc[0] in ('string', 'wstring'):
        leaves.append((_STRING, 0))
    elif kind == Nodetype.BASE and desc[0] in _PRIMITIVE_SIZES:
        leaves.append((_RUN, _PRIMITIVE_SIZES[desc[0]]))
    else:
        return False
    return True


def _run_layouts(sizes):
    """
    Return ``(segments, CDR bytes)`` of a run of primitives for each CDR start offset modulo 8.

    A segment ``(padding, start, end)``: zero padding, then the run's ROS 1 bytes ``start:end``.
    """
    layouts = []
    for start in range(8):
        segments: List[list] = []
        offset, source = start, 0
        for size in sizes:
            padding = -offset % size
            if padding or not segments:
                segments.append([_ZEROS[padding], source, source])
            segments[-1][2] += size
            offset += padding + size
            source += size
        layouts.append((tuple(map(tuple, segments)), offset - start))
    return tuple(layouts)


def _steps(leaves):
    """Return the steps of the leaves: runs of primitives merged, each with its layouts."""
    merged: List[list] = []
    for kind, size in leaves:
        if kind == _RUN and merged and merged[-1][0] == _RUN:
            merged[-1][1].append(size)
        else:
            merged.append([kind, [size] if kind == _RUN else size])
    return tuple((kind, _run_layouts(sizes), sum(sizes)) if kind == _RUN else (kind, sizes, 0)
                 for kind, sizes in merged)


class _Damaged(Exception):
    """The data is not what its type says (rosbags' conversion then says what is wrong)."""


def _converted(steps, data, source, offset, parts, length_fields):
    """
    Emit the CDR parts of ``data`` from ``source`` (CDR ``offset``); return both after.

    A part ``(constant, start, end)``: the bytes ``constant``, then ``data[start:end]``. The parts
    depend on ``len(data)`` and the values at ``length_fields`` alone.
    """
    for kind, layout, size in steps:
        if kind == _RUN:
            segments, cdr_size = layout[offset & 7]
            for padding, start, end in segments:
                parts.append((padding, source + start, source + end))
            source += size
            offset += cdr_size
        elif kind == _STRING:
            length_fields.append(source)
            length, = _UINT32.unpack_from(data, source)
            end = source + 4 + length
            padding = -offset & 3
            parts.append((_ZEROS[padding] + _UINT32.pack(length + 1), source + 4, end))
            parts.append((b'\0', end, end))
            offset += padding + length + 5
            source = end
        elif kind == _SKIP:
            source += layout
        else:
            length_fields.append(source)
            count, = _UINT32.unpack_from(data, source)
            element, least = layout
            if source + 4 + count * least > len(data):
                raise _Damaged
            padding = -offset & 3
            parts.append((_ZEROS[padding], source, source + 4))
            source += 4
            offset += padding + 4
            for _ in range(count):
                source, offset = _converted(element, data, source, offset, parts, length_fields)
    return source, offset


#: Layouts (string and sequence lengths) ``Ros1ToCdr.block`` converts per message length.
_BLOCK_LAYOUTS_TRIED = 4


class Ros1ToCdr:
    """
    ROS 1 messages of one type to CDR: one message (call) or a block of them (``block``).

    Byte for byte rosbags' ``ros1_to_cdr`` for a type of the same wire format in ROS 1 and ROS 2; a
    message not as long as its type says goes to ``fallback`` (rosbags), which says what is wrong.
    """

    def __init__(self, steps: tuple, fallback: Callable[[bytes], bytes]) -> None:
        self._steps, self._fallback = steps, fallback

    def _parts(self, data: bytes) -> Optional[Tuple[list, list]]:
        """Return the ``(constant, start, end)`` parts and the length fields, or None: fallback."""
        parts: List[Tuple[bytes, int, int]] = []
        length_fields: List[int] = []

        try:
            source, _ = _converted(self._steps, data, 0, 0, parts, length_fields)
        except (struct.error, _Damaged):
            return None
        return (parts, length_fields) if source == len(data) else None

    def __call__(self, data: bytes) -> bytes:
        """Return one message's CDR data."""
        converted = self._parts(data)
        if converted is None:
            return self._fallback(data)
        return _ENCAPSULATION + b''.join(
            constant + data[start:end] for constant, start, end in converted[0])

    def block(self, chunk: bytes, starts: np.ndarray, lengths: np.ndarray
              ) -> List[Optional[bytes]]:
        """
        Return the CDR of ``chunk[starts[k]:starts[k] + lengths[k]]``, None where not in a block.

        A block: messages of one length whose strings and sequences have the lengths of the first.
        """
        result: List[Optional[bytes]] = [None] * len(starts)
        buffer = np.frombuffer(chunk, np.uint8)
        for length in set(lengths.tolist()):   # (np.unique would import numpy.ma: 10 ms)
            members = np.flatnonzero(lengths == length)
            for _ in range(_BLOCK_LAYOUTS_TRIED):
                if not len(members):
                    break
                first = starts[members[0]].item()
                data = chunk[first:first + length]
                converted = self._parts(data)
                if converted is None:
                    break
                parts, length_fields = converted
                alike = np.ones(len(members), bool)
                if length_fields:   # the same lengths: the same parts
                    at = (np.array(length_fields)[:, None] + np.arange(4)).ravel()
                    alike = (buffer[starts[members][:, None] + at]
                             == buffer[first + at]).all(axis=1)
                same = members[alike]
                copies = self._copies(buffer, starts[same], length, parts)
                for index, cdr in zip(same.tolist(), copies):
                    result[index] = cdr
                members = members[~alike]
        return result

    @staticmethod
    def _copies(buffer: np.ndarray, starts: np.ndarray, length: int, parts: list) -> List[bytes]:
        """Return the CDR data of the messages of ``length`` bytes at ``starts``, as ``parts``."""
        if len(starts) > 1 and (np.diff(starts) == starts[1] - starts[0]).all() and (
                starts[1] > starts[0]):   # evenly spaced (records alike): a view of them
            rows = np.lib.stride_tricks.as_strided(
                buffer[starts[0]:], (len(starts), length), (starts[1] - starts[0], 1),
                writeable=False)
        else:
            rows = buffer[starts[:, None] + np.arange(length)]
        template = bytearray(_ENCAPSULATION)
        copies = []
        for constant, start, end in parts:
            template += constant
            copies.append((len(template), start, end))
            template += bytes(end - start)
        size = len(template)
        out = np.empty((len(starts), size), np.uint8)
        out[:] = np.frombuffer(template, np.uint8)
        for target, start, end in copies:
            out[:, target:target + end - start] = rows[:, start:end]
        blob = out.tobytes()
        return [blob[k:k + size] for k in range(0, len(blob), size)]


def ros1_to_cdr_converter(fielddefs: Dict[str, Any], type_name: str,
                          fallback: Callable[[bytes], bytes]) -> Optional[Ros1ToCdr]:
    """
    Return a :class:`Ros1ToCdr` of ``type_name`` in ROS 2 ``fielddefs``, None if it has none.

    A quarter of rosbags' time for sensor_msgs/Imu one message at a time, a fraction in blocks.
    """
    leaves: List[Tuple[int, Any]] = []
    if not _leaves(fielddefs, type_name, leaves):
        return None
    return Ros1ToCdr(_steps(leaves), fallback)
