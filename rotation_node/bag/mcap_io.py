"""
Read ROS 2 bags stored as single MCAP files, the way rosbag2 writes them.

A bag is what ``ros2 bag record -s mcap`` writes: profile ``ros2``; one schema
per message type, named ``pkg/msg/Type`` with encoding ``ros2msg`` and the
complete concatenated definition (see ``message_types.message_definition``);
one channel per topic with message encoding ``cdr`` and the metadata
``offered_qos_profiles`` (QoS YAML, see ``qos``) and ``topic_type_hash``.
:mod:`rotation_node.bag.writer` writes such bags (``BagWriter``, importable
from here too).

Messages are stored as CDR bytes, which reading returns unchanged, so a bag
round trip is byte-exact. Reading streams chunk by chunk: memory does not grow
with the length of the bag.
"""
import dataclasses
import functools
import os
import struct
from typing import Optional

import zstandard
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from rclpy.serialization import deserialize_message

from rotation_node.bag.message_types import message_class, split_type_name
from rotation_node.errors import BagError

MESSAGE_ENCODING = 'cdr'
SCHEMA_ENCODINGS = ('ros2msg', 'ros2idl')
# What parsing a damaged file can raise from inside the mcap library, besides
# its own McapError: short reads, bad lengths, undecodable strings, missing ids,
# failed decompression (zstandard's ZstdError, lz4's RuntimeError; both are
# dependencies of mcap).
_CORRUPT_DATA_ERRORS = (McapError, struct.error, EOFError, ValueError, KeyError,
                        IndexError, MemoryError, RuntimeError, zstandard.ZstdError)


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

    """

    name: str
    type_name: str
    offered_qos_profiles: str = '[]'
    definition: Optional[str] = None
    definition_encoding: str = 'ros2msg'
    type_hash: Optional[str] = None


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
        except Exception as error:  # rclpy raises bare RuntimeError/TypeError on bad CDR
            raise BagError(
                f'message on {self.topic} at {self.log_time_ns} ns is not a valid '
                f'{self.type_name}: {error}') from None

    def __repr__(self):
        return (f'BagMessage({self.topic!r}, {self.type_name!r}, <{len(self.data)} bytes>, '
                f'log_time_ns={self.log_time_ns}, publish_time_ns={self.publish_time_ns})')


class BagReader:
    """
    Read a ROS 2 MCAP bag.

    The file is checked when opened: it must be a complete MCAP file (header,
    summary, footer) whose channels all carry CDR messages with ``ros2msg`` or
    ``ros2idl`` schemas. Messages are read lazily, one chunk at a time.

    Parameters
    ----------
    path : str or os.PathLike

    Attributes
    ----------
    path : str
    topics : dict
        ``{topic: 'pkg/msg/Type'}``.
    topic_metadata : dict
        ``{topic: TopicMetadata}`` as stored (schema text, QoS YAML, hash).
    message_counts : dict
        ``{topic: number of messages}``.
    compression : str
        The compression of the file's chunks: ``'zstd'``, ``'lz4'`` or
        ``'none'`` (the first chunk's; ``'none'`` without chunks).

    Raises
    ------
    BagError
        If the file does not exist, is not MCAP, is truncated or corrupt, or
        holds a channel that is not a ROS 2 CDR channel.

    """

    def __init__(self, path):
        self.path = os.fspath(path)
        try:
            self._stream = open(self.path, 'rb')
        except OSError as error:
            raise BagError(f'cannot open bag {self.path}: {error.strerror}') from None
        try:
            self._read_summary()
        except BaseException:
            self._stream.close()
            raise

    def _read_summary(self):
        try:
            self._reader = SeekingReader(self._stream, validate_crcs=True)
            summary = self._reader.get_summary()
        except _CORRUPT_DATA_ERRORS as error:
            raise BagError(f'{self.path} is not a valid MCAP file (truncated or corrupt?): '
                           f'{error}') from None
        if summary is None:
            raise BagError(f'{self.path} has no MCAP summary section (index); '
                           'it was not closed by its writer')
        self.topic_metadata = {}
        self.message_counts = {}
        self._type_names = {}
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        for channel in summary.channels.values():
            metadata = self._topic_metadata(channel, summary.schemas.get(channel.schema_id))
            known = self.topic_metadata.setdefault(channel.topic, metadata)
            if known.type_name != metadata.type_name:
                raise BagError(f'topic {channel.topic} in {self.path} has two types: '
                               f'{known.type_name} and {metadata.type_name}')
            self._type_names[channel.id] = metadata.type_name
            self.message_counts[channel.topic] = (
                self.message_counts.get(channel.topic, 0) + counts.get(channel.id, 0))
        self.topics = {topic: m.type_name for topic, m in self.topic_metadata.items()}
        self.compression = next(
            (index.compression or 'none' for index in summary.chunk_indexes), 'none')

    def _topic_metadata(self, channel, schema):
        if channel.message_encoding != MESSAGE_ENCODING:
            raise BagError(f'topic {channel.topic} in {self.path} has message encoding '
                           f'{channel.message_encoding!r}, expected {MESSAGE_ENCODING!r}')
        if schema is None or schema.encoding not in SCHEMA_ENCODINGS:
            found = 'no schema' if schema is None else f'schema encoding {schema.encoding!r}'
            raise BagError(f'topic {channel.topic} in {self.path} has {found}, '
                           f'expected one of {SCHEMA_ENCODINGS}')
        try:
            split_type_name(schema.name)
            definition = schema.data.decode()
        except (BagError, UnicodeDecodeError) as error:
            raise BagError(f'topic {channel.topic} in {self.path}: {error}') from None
        return TopicMetadata(
            name=channel.topic, type_name=schema.name,
            offered_qos_profiles=channel.metadata.get('offered_qos_profiles', '[]'),
            definition=definition, definition_encoding=schema.encoding,
            type_hash=channel.metadata.get('topic_type_hash', ''))

    def messages(self, topics=None):
        """
        Iterate over the messages in log-time order (ties in file order).

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
            topics = list(topics)
            missing = [topic for topic in topics if topic not in self.topics]
            if missing:
                raise BagError(f'topic {", ".join(missing)} not in {self.path} '
                               f'(it has {", ".join(sorted(self.topics)) or "no topics"})')
        return self._messages(topics)

    def _messages(self, topics):
        # Log-time order streams chunk by chunk. (mcap 1.6's file order,
        # log_time_order=False, queues every chunk's messages before yielding
        # the first: it loads the whole bag.)
        type_names = self._type_names
        try:
            for _, channel, message in self._reader.iter_messages(topics=topics):
                yield BagMessage(channel.topic, type_names[channel.id], message.data,
                                 message.log_time, message.publish_time)
        except _CORRUPT_DATA_ERRORS as error:
            raise BagError(f'{self.path} is corrupt: {error!r}') from None

    def close(self):
        """Close the file."""
        self._stream.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def __getattr__(name):
    # BagWriter lives in rotation_node.bag.writer (which imports this module).
    if name == 'BagWriter':
        from rotation_node.bag.writer import BagWriter
        return BagWriter
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
