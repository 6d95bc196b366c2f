"""
Read ROS 2 bags stored as single MCAP files, the way rosbag2 writes them.

A bag is what ``ros2 bag record -s mcap`` writes: profile ``ros2``; one schema
per message type, named ``pkg/msg/Type`` with encoding ``ros2msg`` and the
complete concatenated definition (see ``message_types.message_definition``);
one channel per topic with message encoding ``cdr`` and the metadata
``offered_qos_profiles`` (QoS YAML, see ``qos``) and ``topic_type_hash``.
:mod:`rotation_node.bag.writer` writes such bags (``BagWriter``, importable
from here too); :mod:`rotation_node.bag.reader` reads every other kind of bag.

Messages are stored as CDR bytes, which reading returns unchanged, so a bag
round trip is byte-exact. Reading streams chunk by chunk: memory does not grow
with the length of the bag. A chunk's Message records are read as arrays
(:func:`chunk_message_records`), without the mcap library's record object per
message: 1.0 instead of 2.9 us per message on an AMD EPYC (2 cores).
"""
from __future__ import annotations

import dataclasses
import functools
import operator
import os
import struct
from typing import (
    Any, Callable, Collection, Dict, Iterable, Iterator, List, Optional, TYPE_CHECKING)

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import (
    breakup_chunk, CRCValidationError, get_chunk_data_stream, StreamReader)
import numpy as np
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.serialization import deserialize_message
from rotation_node.bag.compression import decompressed_message, ZSTD_MAGIC
from rotation_node.bag.mcap_writer import MESSAGE_FIELDS, MESSAGE_HEADER
from rotation_node.bag.message_types import message_class
from rotation_node.errors import BagError
import zstandard

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

MESSAGE_ENCODING = 'cdr'
SCHEMA_ENCODINGS = ('ros2msg', 'ros2idl')
#: What rclpy's deserialize_message raises for data that is not a valid message.
_RMWError = rclpy_implementation.RMWError
# What the mcap library raises for a damaged file: its own McapError (bad
# magic, short reads, missing ids...), CRCValidationError, struct.error for
# short fixed-size fields, UnicodeDecodeError for strings, and failed chunk
# decompression (zstandard's ZstdError; lz4's RuntimeError, recognised by its
# message in _is_format_error so that no other RuntimeError is taken for one).
_FORMAT_ERRORS = (McapError, CRCValidationError, struct.error, UnicodeDecodeError,
                  zstandard.ZstdError, RuntimeError)
_LZ4_ERROR_PREFIX = 'LZ4F_'
_RECORD_PREFIX = struct.Struct('<BQ')   # opcode, length of what follows
_HEADER_BYTES = np.arange(MESSAGE_HEADER.itemsize)
_ZSTD_MAGIC = np.frombuffer(ZSTD_MAGIC, np.uint8)


def _is_format_error(error):
    """Whether an exception from the mcap library means damaged data (not a bug)."""
    return not isinstance(error, RuntimeError) or (
        type(error) is RuntimeError and str(error).startswith(_LZ4_ERROR_PREFIX))


def _described(error):
    """``'Type: message'`` of an exception (some mcap errors have an empty repr)."""
    text = str(error)
    return f'{type(error).__name__}: {text}' if text else type(error).__name__


@dataclasses.dataclass(frozen=True)
class TopicMetadata:
    """
    What a bag records about one topic.

    Attributes
    ----------
    name : str
        The topic, e.g. ``'/imu'``.
    type_name : str
        ``'pkg/msg/Type'``.
    offered_qos_profiles : str
        The publishers' QoS profiles as rosbag2's YAML (``'[]'`` if unknown).
    definition : str or None
        The schema text; None means the installed definition of ``type_name``.
    definition_encoding : str
        ``'ros2msg'`` or ``'ros2idl'``.
    type_hash : str or None
        REP-2011 hash; None means the installed type's hash.
    serialization_format : str
        How the messages are serialized: ``'cdr'`` for ROS 2 (other values
        only in bags of other recorders, whose topics are copied as they are).

    """

    name: str
    type_name: str
    offered_qos_profiles: str = '[]'
    definition: Optional[str] = None
    definition_encoding: str = 'ros2msg'
    type_hash: Optional[str] = None
    serialization_format: str = MESSAGE_ENCODING


class BagMessage:
    """
    One message read from a bag.

    Attributes
    ----------
    topic : str
    type_name : str
        ``'pkg/msg/Type'``.
    data : bytes
        The CDR-serialised message.
    log_time_ns : int
        Receive time, nanoseconds.
    publish_time_ns : int
        Publish time, nanoseconds.

    """

    __slots__ = ('topic', 'type_name', 'data', 'log_time_ns', 'publish_time_ns')

    def __init__(self, topic: str, type_name: str, data: bytes, log_time_ns: int,
                 publish_time_ns: int) -> None:
        self.topic = topic
        self.type_name = type_name
        self.data = data
        self.log_time_ns = log_time_ns
        self.publish_time_ns = publish_time_ns

    def message(self, decode: Optional[Callable[[bytes], Any]] = None) -> Any:
        """
        Deserialise the message.

        Parameters
        ----------
        decode : callable, optional
            ``decode(data) -> message`` to use instead of rclpy, e.g. the
            ``decode`` of a :func:`rotation_node.bag.cdr.fixed_layout_codec`.

        Returns
        -------
        object
            An instance of the rclpy message class of ``type_name``, or what
            ``decode`` returns.

        Raises
        ------
        BagError
            If the type is not installed or the bytes are not a valid message.

        """
        if decode is None:
            decode = functools.partial(deserialize_message,
                                       message_type=message_class(self.type_name))
        try:
            return decode(self.data)
        except (_RMWError, BagError) as error:   # rclpy's error for bad CDR; cdr's own
            raise BagError(
                f'message on {self.topic} at {self.log_time_ns} ns is not a valid '
                f'{self.type_name}: {error}') from None

    def __repr__(self) -> str:
        return (f'BagMessage({self.topic!r}, {self.type_name!r}, <{len(self.data)} bytes>, '
                f'log_time_ns={self.log_time_ns}, publish_time_ns={self.publish_time_ns})')


def checked_topics(topics: Iterable[str], available: Collection[str], path: str) -> List[str]:
    """
    Return ``topics`` as a list, each checked to be one of ``available`` (the topics of a bag).

    Raises
    ------
    BagError
        Naming the missing topics, the bag ``path`` and the topics it has.

    """
    topics = list(topics)
    missing = [topic for topic in topics if topic not in available]
    if missing:
        raise BagError(f'topic {", ".join(missing)} not in {path} '
                       f'(it has {", ".join(sorted(available)) or "no topics"})')
    return topics


def _chunks_in_order(summary):
    """
    Return the chunk indexes in log-time order, if their messages can be read chunk by chunk.

    ``SeekingReader.iter_messages`` orders messages by (log time, chunk offset,
    place in the chunk) through a heap, a Python comparison per step. When no
    later chunk holds a message that sorts before the end of an earlier one (a
    recording's chunks never overlap in time), that order is each chunk's
    messages sorted by log time, chunk after chunk, without the heap; the
    result is the same. None when chunks overlap: then read through the heap.
    """
    chunks = sorted(summary.chunk_indexes,
                    key=lambda index: (index.message_start_time, index.chunk_start_offset))
    for position, chunk in enumerate(chunks):
        for later in chunks[position + 1:]:
            if later.message_start_time > chunk.message_end_time:
                break
            if not (later.message_start_time == chunk.message_end_time
                    and later.chunk_start_offset > chunk.chunk_start_offset):
                return None
    return chunks


def chunk_message_records(chunk: Chunk) -> tuple:
    """
    Return the Message records of a chunk as arrays, in file order.

    The chunk is decompressed and checked against its CRC as the mcap library
    does it (``get_chunk_data_stream``); its records are then walked once to
    find the Message records (schemas, channels and unknown records skipped),
    whose fixed fields are read for all of them at once: no record object per
    message, which is where ``breakup_chunk`` spends its time.

    Returns
    -------
    data : bytes
        The uncompressed chunk.
    headers : numpy.ndarray
        One :data:`~rotation_node.bag.mcap_writer.MESSAGE_HEADER` per message.
    starts : numpy.ndarray
        Where each message's data starts in ``data`` (int64); it is
        ``headers['length'] - 22`` bytes long.

    Raises
    ------
    mcap.exceptions.McapError
        If a record runs past the end of the chunk or a Message record is
        shorter than its fixed fields; CRCValidationError and the
        decompressors' errors as the mcap library raises them.

    """
    stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    data = stream.read(size)
    offsets: List[int] = []
    add = offsets.append
    unpack = _RECORD_PREFIX.unpack_from
    position, end = 0, len(data)
    while position < end:
        if position + _RECORD_PREFIX.size > end:
            raise McapError(f'record at {position} of a chunk of {end} bytes is cut short')
        opcode, length = unpack(data, position)
        if opcode == Opcode.MESSAGE:
            if length < MESSAGE_FIELDS:
                raise McapError(f'message record at {position} of a chunk is {length} bytes')
            add(position)
        position += _RECORD_PREFIX.size + length
    if position > end:
        raise McapError(f'the last record of a chunk of {end} bytes ends at {position}')
    starts = np.array(offsets, np.int64)
    raw = np.frombuffer(data, np.uint8)
    headers = raw[starts[:, None] + _HEADER_BYTES].view(MESSAGE_HEADER)[:, 0]
    return data, headers, starts + MESSAGE_HEADER.itemsize


class _Scan:
    """
    A linear scan of an MCAP file, record by record, as its writer wrote them.

    Iterating yields the Schema, Channel and Message records in file order,
    chunks opened (each chunk checked against its CRC first, so that a damaged
    chunk yields nothing). The scan stops at the footer or at the first record
    that cannot be read, which ``error`` then holds: a file cut short by a
    crash ends in a partial record.
    """

    def __init__(self, stream):
        self._stream = stream
        self.error = None
        self.compressions = set()

    def __iter__(self):
        self._stream.seek(0)
        try:
            for record in StreamReader(self._stream, emit_chunks=True).records:
                if isinstance(record, Chunk):
                    self.compressions.add(record.compression)
                    yield from breakup_chunk(record, validate_crc=True)
                elif isinstance(record, (Schema, Channel, Message)):
                    yield record
        except _FORMAT_ERRORS as error:
            if not _is_format_error(error):
                raise
            self.error = error


def _compression_name(compressions):
    """Return the chunk compression of a file: ``'zstd'``, ``'lz4'`` or ``'none'``."""
    return next((name for name in ('zstd', 'lz4') if name in compressions), 'none')


class BagReader:
    """
    Read one ROS 2 MCAP file (``rotation_node.bag.reader`` reads every other bag).

    A complete file is read through its summary (index), chunk by chunk in
    log-time order. A file without a summary is read by a linear scan, in the
    order it was written; so is an unfinished recording (no summary and no
    footer, as a writer killed mid-recording leaves it), up to its last
    complete chunk (unless ``strict``). Channels of any schema and encoding are
    listed (bags of other recorders, schemas rosbag2 could not find); only
    decoding a message needs a ROS 2 type.

    Parameters
    ----------
    path : str or os.PathLike
    strict : bool, optional
        Refuse an unfinished recording instead of reading what it holds.

    Attributes
    ----------
    path : str
    topics : dict
        ``{topic: type name as stored}``, normally ``'pkg/msg/Type'``.
    topic_metadata : dict
        ``{topic: TopicMetadata}`` as stored (schema text, QoS YAML, hash).
    message_counts : dict
        ``{topic: number of messages}``.
    compression : str
        The chunk compression: ``'zstd'``, ``'lz4'`` or ``'none'``.
    recovered : int or None
        For an unfinished recording, the number of messages recovered; None
        for a complete file.

    Raises
    ------
    BagError
        If the file does not exist, is empty, is not MCAP, is corrupt, or is
        an unfinished recording and ``strict`` is set.

    """

    def __init__(self, path: StrPath, *, strict: bool = False) -> None:
        self.path = os.fspath(path)
        self.recovered: Optional[int] = None
        self.compression = 'none'
        try:
            self._stream = open(self.path, 'rb')
        except OSError as error:
            raise BagError(f'cannot open bag {self.path}: {error.strerror}') from None
        try:
            if os.fstat(self._stream.fileno()).st_size == 0:
                raise BagError(f'{self.path}: empty file (0 bytes), not an MCAP bag')
            self._open(strict)
        except BaseException:
            self._stream.close()
            raise

    def _open(self, strict):
        summary, unfinished = None, None
        try:
            self._reader = SeekingReader(self._stream, validate_crcs=True)
        except _FORMAT_ERRORS as error:
            if not _is_format_error(error):
                raise
            raise BagError(
                f'{self.path} is not a valid MCAP file: {_described(error)}') from None
        try:
            summary = self._reader.get_summary()
        except _FORMAT_ERRORS as error:
            if not _is_format_error(error):
                raise
            unfinished = error
        if summary is not None and summary.chunk_indexes:
            self._scan_count: Optional[int] = None
            self._read_summary(summary)
        else:
            self._read_scan(unfinished, strict)

    def _read_summary(self, summary):
        self._summary = summary
        self.compression = _compression_name({c.compression for c in summary.chunk_indexes})
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        self._set_topics(summary.channels.values(), summary.schemas, counts)

    def _read_scan(self, unfinished, strict):
        """Index a file without summary by reading it once; decide how much to recover."""
        scan = _Scan(self._stream)
        schemas: Dict[int, Any] = {}
        channels: Dict[int, Any] = {}
        counts: Dict[int, int] = {}
        total, previous, self._scan_ordered = 0, -1, True
        for record in scan:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif record.channel_id not in channels:
                scan.error = McapError(f'message on unknown channel {record.channel_id}')
                break
            else:
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                total += 1
                self._scan_ordered = self._scan_ordered and record.log_time >= previous
                previous = record.log_time
        if unfinished is None and scan.error is not None:
            raise BagError(f'{self.path} is corrupt: {_described(scan.error)}')
        if unfinished is not None:
            if strict:
                raise BagError(f'{self.path}: unfinished recording (no MCAP summary or '
                               f'footer), {total} messages recoverable; refused (--strict)')
            self.recovered = total
        self._scan_count = total
        self.compression = _compression_name(scan.compressions)
        self._set_topics(channels.values(), schemas, counts)

    def _set_topics(self, channels, schemas, counts):
        self.topic_metadata: Dict[str, TopicMetadata] = {}
        self.message_counts: Dict[str, int] = {}
        self._type_names: Dict[int, str] = {}
        self._channel_topics: Dict[int, str] = {}
        for channel in channels:
            metadata = self._topic_metadata(channel, schemas.get(channel.schema_id))
            known = self.topic_metadata.setdefault(channel.topic, metadata)
            if known.type_name != metadata.type_name:
                raise BagError(f'topic {channel.topic} in {self.path} has two types: '
                               f'{known.type_name} and {metadata.type_name}')
            self._type_names[channel.id] = metadata.type_name
            self._channel_topics[channel.id] = channel.topic
            self.message_counts[channel.topic] = (
                self.message_counts.get(channel.topic, 0) + counts.get(channel.id, 0))
        self.topics = {topic: m.type_name for topic, m in self.topic_metadata.items()}

    def _topic_metadata(self, channel, schema):
        """Return the metadata of a channel as stored, whatever its schema (copied unchanged)."""
        try:
            definition = '' if schema is None else schema.data.decode()
        except UnicodeDecodeError as error:
            raise BagError(f'topic {channel.topic} in {self.path}: schema text is not '
                           f'UTF-8: {error}') from None
        return TopicMetadata(
            name=channel.topic, type_name='' if schema is None else schema.name,
            offered_qos_profiles=channel.metadata.get('offered_qos_profiles', '[]'),
            definition=definition, definition_encoding='' if schema is None else schema.encoding,
            type_hash=channel.metadata.get('topic_type_hash', ''),
            serialization_format=channel.message_encoding)

    def messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[BagMessage]:
        """
        Iterate over the messages in log-time order (ties in file order).

        A file without summary is read in the order it was written, which
        is log-time order for a recorder; if it is not, its messages are
        sorted in memory first. Messages compressed by rosbag2
        (``--compression-mode message``) are decompressed.

        Parameters
        ----------
        topics : iterable of str, optional
            Only these topics; all by default.

        Yields
        ------
        BagMessage

        Raises
        ------
        BagError
            If a requested topic is not in the bag (raised at once), or a chunk
            turns out to be corrupt (raised when it is reached).

        """
        if topics is not None:
            topics = checked_topics(topics, self.topics, self.path)
        if self._scan_count is None:
            return self._indexed_messages(topics)
        records = self._scanned_messages(topics)
        return records if self._scan_ordered else iter(
            sorted(records, key=operator.attrgetter('log_time_ns')))

    def _message(self, channel, message):
        data = message.data
        if data[:4] == ZSTD_MAGIC and channel.message_encoding == MESSAGE_ENCODING:
            data = decompressed_message(data)
        return BagMessage(channel.topic, self._type_names[channel.id], data,
                          message.log_time, message.publish_time)

    def _indexed_messages(self, topics):
        # Log-time order streams chunk by chunk. (mcap 1.6's file order,
        # log_time_order=False, queues every chunk's messages before yielding
        # the first: it loads the whole bag.)
        try:
            chunks = _chunks_in_order(self._summary)
            if chunks is None:
                for _, channel, message in self._reader.iter_messages(topics=topics):
                    yield self._message(channel, message)
                return
            channels = self._summary.channels
            wanted = np.array([channel_id for channel_id, channel in channels.items()
                               if topics is None or channel.topic in topics], np.uint16)
            for chunk_index in chunks:
                self._stream.seek(chunk_index.chunk_start_offset + 1 + 8)
                yield from self._chunk_messages(Chunk.read(ReadDataStream(self._stream)),
                                                wanted)
        except _FORMAT_ERRORS as error:
            if not _is_format_error(error):
                raise
            raise BagError(f'{self.path} is corrupt: {_described(error)}') from None

    def _chunk_messages(self, chunk, wanted):
        """Return the messages of a chunk on the ``wanted`` channels, sorted by log time."""
        data, headers, starts = chunk_message_records(chunk)
        channel_ids = headers['channel_id']
        if not np.isin(channel_ids, wanted).all():
            kept = np.isin(channel_ids, wanted)
            headers, starts, channel_ids = headers[kept], starts[kept], channel_ids[kept]
        order = np.argsort(headers['log_time'], kind='stable')   # ties in file order
        headers, starts = headers[order], starts[order]
        ends = starts + (headers['length'].astype(np.int64) - MESSAGE_FIELDS)
        channel_ids = channel_ids[order].tolist()
        messages = list(map(BagMessage, map(self._channel_topics.__getitem__, channel_ids),
                            map(self._type_names.__getitem__, channel_ids),
                            map(data.__getitem__, map(slice, starts.tolist(), ends.tolist())),
                            headers['log_time'].tolist(), headers['publish_time'].tolist()))
        # Messages that rosbag2 compressed (--compression-mode message) are decompressed.
        long_enough = np.nonzero(ends - starts >= _ZSTD_MAGIC.size)[0]
        first_bytes = np.frombuffer(data, np.uint8)[
            starts[long_enough, None] + np.arange(_ZSTD_MAGIC.size)]
        for index in long_enough[(first_bytes == _ZSTD_MAGIC).all(axis=1)].tolist():
            if self._summary.channels[channel_ids[index]].message_encoding == MESSAGE_ENCODING:
                messages[index].data = decompressed_message(messages[index].data)
        return messages

    def _scanned_messages(self, topics):
        """Return the messages the opening scan counted, no more (the file may still grow)."""
        wanted = None if topics is None else set(topics)
        channels: Dict[int, Any] = {}
        remaining = self._scan_count
        assert remaining is not None   # set by the opening scan
        for record in _Scan(self._stream):
            if remaining == 0:
                return
            if isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                remaining -= 1
                channel = channels[record.channel_id]
                if wanted is None or channel.topic in wanted:
                    try:
                        yield self._message(channel, record)
                    except zstandard.ZstdError as error:
                        raise BagError(
                            f'{self.path} is corrupt: {_described(error)}') from None

    def close(self) -> None:
        """Close the file."""
        self._stream.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def __getattr__(name: str) -> Any:
    # BagWriter lives in rotation_node.bag.writer (which imports this module).
    if name == 'BagWriter':
        from rotation_node.bag.writer import BagWriter
        return BagWriter
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
