"""
Read and write ROS 2 bags as single MCAP files, the way rosbag2 writes them.

A bag written here is what ``ros2 bag record -s mcap`` would write for the same
messages: profile ``ros2``; one schema per message type, named
``pkg/msg/Type`` with encoding ``ros2msg`` and the complete concatenated
definition (see ``message_types.message_definition``); one channel per topic
with message encoding ``cdr`` and the metadata ``offered_qos_profiles`` (QoS
YAML, see ``qos``) and ``topic_type_hash``; uncompressed chunks with message
indexes and a summary; and a ``rosbag2`` metadata record holding the
version 9 bag metadata, without which rosbag2 would read the QoS YAML with the
pre-Jazzy (integer) schema.

Messages are stored as CDR bytes, which reading returns unchanged, so a bag
round trip is byte-exact. ``BagWriter.write`` encodes messages with
:mod:`rotation_node.bag.cdr` where it can (fixed-layout types such as
sensor_msgs/Imu, and std_msgs/Float64MultiArray): rclpy's bytes, with the
alignment padding zeroed instead of uninitialised, so that the same messages
give the same bag; other types with ``rclpy.serialization``. Reading streams
chunk by chunk: memory does not grow with the length of the bag.
"""
import dataclasses
import functools
import operator
import os
import struct
from typing import Collection, Iterable, List, Optional

import mcap
import yaml
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.serialization import deserialize_message, serialize_message

from rotation_node.bag.atomic_file import AtomicFile
from rotation_node.bag.compression import ZSTD_MAGIC, decompressed_message
from rotation_node.bag.cdr import message_encoder
from rotation_node.bag.message_types import (
    message_class, message_definition, type_hash, type_name_of)
from rotation_node.errors import BagError

PROFILE = 'ros2'
MESSAGE_ENCODING = 'cdr'
SCHEMA_ENCODINGS = ('ros2msg', 'ros2idl')
#: Version of the rosbag2 metadata written (Jazzy's).
ROSBAG2_METADATA_VERSION = 9
LIBRARY = f'rotation_node bag; mcap-python/{mcap.__version__}'

_MAX_TIMESTAMP = 2**64 - 1
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

    def __init__(self, topic, type_name, data, log_time_ns, publish_time_ns):
        self.topic = topic
        self.type_name = type_name
        self.data = data
        self.log_time_ns = log_time_ns
        self.publish_time_ns = publish_time_ns

    def message(self, decode=None):
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

    def __repr__(self):
        return (f'BagMessage({self.topic!r}, {self.type_name!r}, <{len(self.data)} bytes>, '
                f'log_time_ns={self.log_time_ns}, publish_time_ns={self.publish_time_ns})')


def _timestamp(value, name):
    """Validate a timestamp argument: an integer in [0, 2**64)."""
    try:
        value = operator.index(value)
    except TypeError:
        raise BagError(
            f'{name} must be an integer number of nanoseconds, got {value!r}') from None
    if not 0 <= value <= _MAX_TIMESTAMP:
        raise BagError(f'{name} must be in [0, 2**64) ns, got {value}')
    return value


class _Channel:
    __slots__ = ('id', 'type_name', 'msg_class', 'encode')

    def __init__(self, channel_id, type_name):
        self.id = channel_id
        self.type_name = type_name
        self.msg_class = None   # of the messages given to write(), with their encode(msg)
        self.encode = None


class BagWriter:
    """
    Write a ROS 2 MCAP bag; a context manager.

    The file appears at ``path`` only when the writer is closed cleanly (end
    of the ``with`` block or ``close()``): until then the data goes to a
    temporary file in the same directory, which an exception (or ``abort()``)
    removes.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mcap`` file to write.
    overwrite : bool, optional
        Replace an existing file. Default False: an existing file is an error.

    Raises
    ------
    BagError
        If ``path`` exists and ``overwrite`` is false, or cannot be created.

    Examples
    --------
    >>> with BagWriter('out.mcap') as writer:                  # doctest: +SKIP
    ...     writer.write('/imu', Imu(), log_time_ns=1_700_000_000_000_000_000)

    """

    def __init__(self, path, *, overwrite=False):
        self.path = os.fspath(path)
        self._file = AtomicFile(self.path, overwrite=overwrite)
        self._writer = Writer(self._file.stream, compression=CompressionType.NONE)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._schema_ids = {}
        self._channels = {}
        self._topics = []
        self._counts = {}
        self._start_ns = _MAX_TIMESTAMP
        self._end_ns = 0

    def add_topic(self, metadata):
        """
        Register a topic with explicit metadata (QoS, definition).

        ``write`` and ``write_serialized`` register unknown topics by
        themselves, with the installed definition and no QoS profiles; call
        this first to record the publishers' QoS, or to copy a topic from
        another bag with its own schema.

        Parameters
        ----------
        metadata : TopicMetadata

        Raises
        ------
        BagError
            If the topic is already registered or the type name is invalid or
            (with ``definition=None``) not installed. A topic with its own
            ``definition`` is registered with its type name as given, for
            copying topics of any bag unchanged.

        """
        if metadata.name in self._channels:
            raise BagError(f'topic {metadata.name} is already registered in {self.path}')
        # A topic copied with its own schema keeps its type name as stored
        # (even a short or unknown one); others need an installed 'pkg/msg/Type'.
        definition = (message_definition(metadata.type_name) if metadata.definition is None
                      else metadata.definition)
        schema_key = (metadata.type_name, metadata.definition_encoding, definition)
        schema_id = self._schema_ids.get(schema_key)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                name=metadata.type_name, encoding=metadata.definition_encoding,
                data=definition.encode())
            self._schema_ids[schema_key] = schema_id
        channel_id = self._writer.register_channel(
            topic=metadata.name, message_encoding=metadata.serialization_format,
            schema_id=schema_id,
            metadata={
                'offered_qos_profiles': metadata.offered_qos_profiles,
                'topic_type_hash': (type_hash(metadata.type_name) if metadata.type_hash is None
                                    else metadata.type_hash),
            })
        self._channels[metadata.name] = _Channel(channel_id, metadata.type_name)
        self._topics.append(metadata)
        self._counts[channel_id] = 0

    def _channel(self, topic, type_name):
        channel = self._channels.get(topic)
        if channel is None:
            self.add_topic(TopicMetadata(topic, type_name))
            channel = self._channels[topic]
        elif channel.type_name != type_name:
            raise BagError(
                f'topic {topic} holds {channel.type_name} in {self.path}, '
                f'cannot write {type_name}')
        return channel

    def write(self, topic, msg, log_time_ns, publish_time_ns=None):
        """
        Serialise and write one message.

        Types that :func:`rotation_node.bag.cdr.message_encoder` covers are
        encoded by it (zero padding: the same message gives the same bytes),
        others by ``rclpy.serialization``.

        Parameters
        ----------
        topic : str
        msg : rclpy message
            Its class decides the topic's type on first use.
        log_time_ns : int
            Receive time, nanoseconds (e.g. since the Unix epoch).
        publish_time_ns : int, optional
            Publish time; defaults to ``log_time_ns``.

        Raises
        ------
        BagError
            If the topic already holds another type or a time is not a
            non-negative integer.

        """
        channel = self._channels.get(topic)
        if channel is None or channel.msg_class is not type(msg):
            channel = self._channel(topic, type_name_of(type(msg)))
            channel.msg_class = type(msg)
            channel.encode = message_encoder(channel.type_name) or serialize_message
        self._add(channel.id, channel.encode(msg), log_time_ns, publish_time_ns)

    def write_serialized(self, topic, type_name, data, log_time_ns, publish_time_ns=None):
        """
        Write one message that is already CDR-serialised.

        Parameters
        ----------
        topic : str
        type_name : str
            ``'pkg/msg/Type'``; decides the topic's type on first use.
        data : bytes
        log_time_ns : int
        publish_time_ns : int, optional
            Defaults to ``log_time_ns``.

        Raises
        ------
        BagError
            As ``write``; also if the type is not installed on first use of a
            topic not registered with ``add_topic``.

        """
        channel = self._channels.get(topic)
        if channel is None or channel.type_name != type_name:
            channel = self._channel(topic, type_name)
        self._add(channel.id, data, log_time_ns, publish_time_ns)

    def _add(self, channel_id, data, log_time_ns, publish_time_ns):
        log_time_ns = _timestamp(log_time_ns, 'log_time_ns')
        publish_time_ns = (log_time_ns if publish_time_ns is None
                           else _timestamp(publish_time_ns, 'publish_time_ns'))
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns)
        self._counts[channel_id] += 1
        if log_time_ns < self._start_ns:
            self._start_ns = log_time_ns
        if log_time_ns > self._end_ns:
            self._end_ns = log_time_ns

    def _rosbag2_metadata(self):
        """The bag metadata rosbag2 stores in the MCAP metadata record ``rosbag2``."""
        count = sum(self._counts.values())
        start = self._start_ns if count else 0
        duration = {'nanoseconds': self._end_ns - start if count else 0}
        name = os.path.basename(self.path)
        return {
            'version': ROSBAG2_METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': duration,
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': count,
            'topics_with_message_count': [{
                'topic_metadata': {
                    'name': topic.name,
                    'type': topic.type_name,
                    'serialization_format': topic.serialization_format,
                    'offered_qos_profiles': yaml.safe_load(topic.offered_qos_profiles) or [],
                    'type_description_hash': (type_hash(topic.type_name)
                                              if topic.type_hash is None else topic.type_hash),
                },
                'message_count': self._counts[self._channels[topic.name].id],
            } for topic in self._topics],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [name],
            'files': [{
                'path': name,
                'starting_time': {'nanoseconds_since_epoch': start},
                'duration': duration,
                'message_count': count,
            }],
            'custom_data': {},
            'ros_distro': os.environ.get('ROS_DISTRO', 'jazzy'),
        }

    def close(self):
        """Finish the file and move it to ``path``; idempotent."""
        if self._file.closed:
            return
        try:
            serialized = yaml.safe_dump(self._rosbag2_metadata(), sort_keys=False)
            self._writer.add_metadata('rosbag2', {'serialized_metadata': serialized})
            self._writer.finish()
        except BaseException:
            self._file.discard()
            raise
        self._file.commit()

    def abort(self):
        """Discard everything written; ``path`` is left as it was."""
        if not self._file.closed:
            self._file.discard()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, traceback):
        if exc_type is None:
            self.close()
        else:
            self.abort()


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
    The chunk indexes in log-time order, if their messages can be read chunk after chunk.

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
    """The chunk compression of a file: ``'zstd'``, ``'lz4'`` or ``'none'``."""
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

    def __init__(self, path, *, strict=False):
        self.path = os.fspath(path)
        self.recovered = None
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
            self._scan_count = None
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
        schemas, channels, counts = {}, {}, {}
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
        self.topic_metadata = {}
        self.message_counts = {}
        self._type_names = {}
        for channel in channels:
            metadata = self._topic_metadata(channel, schemas.get(channel.schema_id))
            known = self.topic_metadata.setdefault(channel.topic, metadata)
            if known.type_name != metadata.type_name:
                raise BagError(f'topic {channel.topic} in {self.path} has two types: '
                               f'{known.type_name} and {metadata.type_name}')
            self._type_names[channel.id] = metadata.type_name
            self.message_counts[channel.topic] = (
                self.message_counts.get(channel.topic, 0) + counts.get(channel.id, 0))
        self.topics = {topic: m.type_name for topic, m in self.topic_metadata.items()}

    def _topic_metadata(self, channel, schema):
        """The metadata of a channel as stored, whatever its schema (copied unchanged)."""
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

    def messages(self, topics=None):
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
            chunks = None if topics is not None else _chunks_in_order(self._summary)
            if chunks is None:
                for _, channel, message in self._reader.iter_messages(topics=topics):
                    yield self._message(channel, message)
                return
            channels, log_time = self._summary.channels, operator.attrgetter('log_time')
            for chunk_index in chunks:
                self._stream.seek(chunk_index.chunk_start_offset + 1 + 8)
                records = [record for record in breakup_chunk(
                    Chunk.read(ReadDataStream(self._stream)), validate_crc=True)
                    if isinstance(record, Message)]
                records.sort(key=log_time)   # stable: ties in file order
                for message in records:
                    yield self._message(channels[message.channel_id], message)
        except _FORMAT_ERRORS as error:
            if not _is_format_error(error):
                raise
            raise BagError(f'{self.path} is corrupt: {_described(error)}') from None

    def _scanned_messages(self, topics):
        """The messages the opening scan counted, no more (the file may still grow)."""
        wanted = None if topics is None else set(topics)
        channels, remaining = {}, self._scan_count
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

    def close(self):
        """Close the file."""
        self._stream.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
