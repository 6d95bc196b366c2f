"""
Write ROS 2 bags as ``ros2 bag record -s mcap`` does: crash-safe, exclusive, closed on a full disk.

The output is a rosbag2 directory (``metadata.yaml`` and ``<name>_0.mcap``) or one ``.mcap``
file: profile ``ros2``, one ``ros2msg`` schema per type, one ``cdr`` channel per topic with
``offered_qos_profiles`` and ``topic_type_hash``, zstd/lz4/no chunk compression, indexes, and
the version 9 rosbag2 metadata (docs/recording.md). It is written as ``<output>.part``
(:mod:`~rotation_node.bag.writing.part_output`) and renamed when closed. Chunks are cut at
``CHUNK_SIZE`` bytes (a live recording also ``chunk_period_s`` after the last) and written
whole by :class:`~rotation_node.bag.writing.mcap_writer.ChunkWriter`; data is synced at least
every ``SYNC_PERIOD_S``. Cut by size only, the same messages give the same bytes (``write``
encodes with :mod:`rotation_node.wire.cdr` where it can, zeroing the padding rclpy leaves).
Before each chunk the space to close the bag is reserved beyond it: when that fails,
``DiskFullError``, and ``close()`` still writes a valid bag of what was written before.
"""
from __future__ import annotations

import dataclasses
import errno
import math
import operator
import os
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple, TYPE_CHECKING

import mcap
import numpy as np
from rotation_node.bag import metadata_yaml
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing.mcap_writer import (
    ChunkWriter, MESSAGE_INDEX_ENTRY, MESSAGE_INDEX_OVERHEAD, MESSAGE_RECORD_OVERHEAD)
from rotation_node.bag.writing.part_output import BagOutput
from rotation_node.errors import BagError, DiskFullError
from rotation_node.wire.cdr import message_encoder
from rotation_node.wire.message_types import message_definition, type_hash, type_name_of

if TYPE_CHECKING:
    from types import TracebackType

    from rotation_node.type_aliases import StrPath

PROFILE = 'ros2'
ROSBAG2_METADATA_VERSION = 9   # Jazzy's
LIBRARY = f'rotation_node bag; mcap-python/{mcap.__version__}'
COMPRESSIONS = ('zstd', 'lz4', 'none')   # mcap's CompressionType names
DEFAULT_COMPRESSION = 'zstd'             # rosbag2's for MCAP storage
CHUNK_SIZE = 768 * 1024   # message bytes that make a chunk (rosbag2's MCAP default)
SYNC_PERIOD_S = 1.0    # longest wait of written data before fdatasync
CHUNK_PERIOD_S = 1.0   # longest wait of a live recording's message before its chunk

_MAX_TIMESTAMP = 2**64 - 1
_CHECK_CLOCK_EVERY = 64              # messages between clock reads (a power of two)
_MESSAGE_OVERHEAD = MESSAGE_RECORD_OVERHEAD + MESSAGE_INDEX_ENTRY
_CHUNK_OVERHEAD = 4096               # chunk record, compression frame, page rounding
_SUMMARY_PER_CHUNK = 96              # chunk index record (77 bytes with 'zstd'), w/o entries
_SUMMARY_PER_CHANNEL_IN_CHUNK = 10
_SUMMARY_FIXED = 64 * 1024           # statistics, offsets, footer, metadata.yaml's block


def _timestamp(value, name):
    try:
        value = operator.index(value)
    except TypeError:
        raise BagError(
            f'{name} must be an integer number of nanoseconds, got {value!r}') from None
    if not 0 <= value <= _MAX_TIMESTAMP:
        raise BagError(f'{name} must be in [0, 2**64) ns, got {value}')
    return value


def _all_timestamps(values):
    """Whether every value is an integer in [0, 2**64) (False: let _timestamp say why not)."""
    array = np.array(values)
    kind = array.dtype.kind
    return kind == 'u' or (kind == 'i' and (not array.size or bool(array.min() >= 0)))


class _Channel:
    __slots__ = ('id', 'type_name', 'msg_class', 'encode')

    def __init__(self, channel_id, type_name):
        self.id = channel_id
        self.type_name = type_name
        self.msg_class = None   # of the messages given to write(), and their encode(msg)
        self.encode = None


class BagWriter:
    """
    Write a ROS 2 bag; a context manager.

    The bag is written to ``<path>.part`` and renamed to ``path`` when the
    writer is closed cleanly (end of the ``with`` block or ``close()``). An
    exception in the ``with`` block (or ``abort()``) removes the ``.part``, or
    with ``keep_unfinished`` leaves it as an unfinished bag that a linear scan
    reads. A process killed while writing leaves the ``.part`` holding every
    message up to the last chunk written.

    Parameters
    ----------
    path : str or os.PathLike
        The bag: a rosbag2 directory, or a single MCAP file if it ends in ``.mcap``.
    overwrite : bool, optional
        Replace an existing bag (atomically, when closed). Default False: an
        existing bag is an error.
    compression : str, optional
        Chunk compression: ``'zstd'`` (default, as rosbag2), ``'lz4'`` or ``'none'``.
    keep_unfinished : bool, optional
        On failure, keep the ``.part`` instead of removing it (for recordings,
        which cannot be repeated).
    chunk_period_s : float, optional
        Also write a chunk when the last one is this old (checked every 64
        messages and by ``flush_if_due()``): for live recordings. Default:
        chunks by size only, so the bag depends on the messages alone.

    Attributes
    ----------
    path : str
    part_path : str
        Where the bag is until it is closed.
    message_count : int
        Messages written to the file so far (not those still collected in
        memory, nor those dropped on a full disk).

    Raises
    ------
    BagError
        If ``path`` exists and ``overwrite`` is false, ``<path>.part`` exists
        (another writer, or a crashed one), or it cannot be created.

    Examples
    --------
    >>> with BagWriter('out.mcap') as writer:                  # doctest: +SKIP
    ...     writer.write('/imu', Imu(), log_time_ns=1_700_000_000_000_000_000)

    """

    def __init__(self, path: StrPath, *, overwrite: bool = False,
                 compression: str = DEFAULT_COMPRESSION, keep_unfinished: bool = False,
                 chunk_period_s: Optional[float] = None) -> None:
        self.path = os.fspath(path)
        if not (isinstance(compression, str) and compression in COMPRESSIONS):
            raise BagError(
                f'compression must be one of {", ".join(COMPRESSIONS)}, got {compression!r}')
        self.keep_unfinished = keep_unfinished
        self._output = BagOutput(self.path, overwrite=overwrite)
        self.part_path = self._output.part_path
        self._writer = ChunkWriter(self._output.stream, compression=compression)
        self._schema_ids: Dict[Tuple[str, str, str], int] = {}
        self._channels: Dict[str, Any] = {}
        self._topics: List[TopicMetadata] = []
        self._drop_pending()
        self._registered_bytes = 0      # schemas and channels since the last chunk
        self._summary_bytes = 0         # schemas and channels repeated in the summary
        self._chunk_count = 0
        self._chunk_period_s = chunk_period_s
        self._flush_due = (math.inf if chunk_period_s is None
                           else time.monotonic() + chunk_period_s)
        self._sync_due = time.monotonic() + SYNC_PERIOD_S
        self._failed = False
        try:
            self._writer.start(profile=PROFILE, library=LIBRARY)
            self._output.sync()
        except OSError as error:
            self._output.discard()
            raise BagError(f'cannot write output {self.path}: {error.strerror}') from None
        except BaseException:   # Ctrl-C, SIGTERM: no writer to abort yet
            self._output.discard()
            raise

    @property
    def message_count(self) -> int:
        """Messages written to the file so far (not those in memory, nor those dropped)."""
        return self._writer.statistics.message_count

    @property
    def message_counts(self) -> Dict[str, int]:
        """``{topic: messages flushed to disk so far}`` for every registered topic."""
        counts = self._writer.statistics.channel_message_counts
        return {topic: counts.get(channel.id, 0) for topic, channel in self._channels.items()}

    def add_topic(self, metadata: TopicMetadata) -> None:
        """
        Register a topic with its QoS profiles and, to copy a topic of any bag, its schema.

        ``write`` and ``write_serialized`` register new topics themselves (installed
        definition, no QoS); call this first to record the publishers' QoS.

        Parameters
        ----------
        metadata : TopicMetadata
            The topic's name, type, QoS profiles and (optionally) definition. A topic with its
            own ``definition`` keeps its type name as given, for copying topics of any bag.

        Raises
        ------
        BagError
            If the topic is already registered, or, without its own ``definition``, its type
            is not an installed ``pkg/msg/Type``.

        """
        if metadata.name in self._channels:
            raise BagError(f'topic {metadata.name} is already registered in {self.path}')
        definition = (message_definition(metadata.type_name) if metadata.definition is None
                      else metadata.definition)
        schema_key = (metadata.type_name, metadata.definition_encoding, definition)
        schema_id = self._schema_ids.get(schema_key)
        if schema_id is None:
            data = definition.encode()
            schema_id = self._writer.register_schema(
                name=metadata.type_name, encoding=metadata.definition_encoding, data=data)
            self._schema_ids[schema_key] = schema_id
            self._add_registered(len(data) + len(metadata.type_name) + 64)
        topic_hash = (type_hash(metadata.type_name) if metadata.type_hash is None
                      else metadata.type_hash)
        channel_id = self._writer.register_channel(
            topic=metadata.name, message_encoding=metadata.serialization_format,
            schema_id=schema_id,
            metadata={
                'offered_qos_profiles': metadata.offered_qos_profiles,
                'topic_type_hash': topic_hash,
            })
        self._add_registered(len(metadata.name) + len(metadata.offered_qos_profiles)
                             + len(topic_hash) + 128)
        self._channels[metadata.name] = _Channel(channel_id, metadata.type_name)
        self._topics.append(dataclasses.replace(metadata, type_hash=topic_hash))

    def _add_registered(self, size):
        self._registered_bytes += size
        self._summary_bytes += size

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

    def write(self, topic: str, msg: Any, log_time_ns: int,
              publish_time_ns: Optional[int] = None) -> None:
        """
        Serialise and write one message.

        Encoded by :func:`rotation_node.wire.cdr.message_encoder` where it covers the type
        (zero padding: the same message gives the same bytes), else by ``rclpy.serialization``.

        Parameters
        ----------
        topic : str
            The topic to write on.
        msg : rclpy message
            Its class decides the topic's type on first use.
        log_time_ns : int
            Receive time, nanoseconds (e.g. since the Unix epoch), in [0, 2**64).
        publish_time_ns : int, optional
            Publish time, nanoseconds; defaults to ``log_time_ns``.

        Raises
        ------
        BagError
            If the topic already holds another type, a time is not an integer in
            [0, 2**64), or an earlier write failed.
        DiskFullError
            If the disk filled: the chunk in progress was dropped, ``close()`` keeps
            everything written before.

        """
        channel = self._channels.get(topic)
        if channel is None or channel.msg_class is not type(msg):
            channel = self._channel(topic, type_name_of(type(msg)))
            channel.msg_class = type(msg)
            channel.encode = message_encoder(channel.type_name)
            if channel.encode is None:   # rclpy, imported on first use: it loads rcl
                from rclpy.serialization import serialize_message
                channel.encode = serialize_message
        self._add(channel.id, channel.encode(msg), log_time_ns, publish_time_ns)

    def write_serialized(self, topic: str, type_name: str, data: bytes, log_time_ns: int,
                         publish_time_ns: Optional[int] = None) -> None:
        """
        Write one message that is already CDR-serialised.

        Parameters
        ----------
        topic : str
            The topic to write on.
        type_name : str
            ``'pkg/msg/Type'``; decides the topic's type on first use.
        data : bytes
            The serialised (CDR) message.
        log_time_ns : int
            Receive time, nanoseconds, in [0, 2**64).
        publish_time_ns : int, optional
            Publish time, nanoseconds; defaults to ``log_time_ns``.

        Raises
        ------
        BagError
            As ``write``; also if the type is not installed on first use of a topic not
            registered with ``add_topic``.
        DiskFullError
            As ``write``.

        """
        channel = self._channels.get(topic)
        if channel is None or channel.type_name != type_name:
            channel = self._channel(topic, type_name)
        self._add(channel.id, data, log_time_ns, publish_time_ns)

    def _add(self, channel_id, data, log_time_ns, publish_time_ns):
        log_time_ns = _timestamp(log_time_ns, 'log_time_ns')
        publish_time_ns = (log_time_ns if publish_time_ns is None
                           else _timestamp(publish_time_ns, 'publish_time_ns'))
        if self._failed:
            raise BagError(f'cannot write to {self.path} after a failed write')
        self._pending_channels.append(channel_id)
        self._pending_log_times.append(log_time_ns)
        self._pending_publish_times.append(publish_time_ns)
        datas = self._pending_datas
        datas.append(data)
        self._pending_bytes += len(data)
        if self._pending_bytes >= CHUNK_SIZE or (
                not len(datas) % _CHECK_CLOCK_EVERY and time.monotonic() >= self._flush_due):
            self.flush()

    def write_serialized_block(self, messages: Sequence[Tuple[str, str, Any, int, int]]
                               ) -> None:
        """
        Write messages that are already CDR-serialised, in order; as ``write_serialized`` each.

        The bag is byte for byte the one ``write_serialized`` of each message in turn writes
        (chunks are cut after the same messages), with the per-message work done once for the
        block: the topics' channels looked up once, the times checked as one array.

        Parameters
        ----------
        messages : sequence of tuple
            ``(topic, type name, data, log_time_ns, publish_time_ns)`` each.

        Raises
        ------
        BagError
            As ``write_serialized``, for the first message it would raise it for; the messages
            before it are written.
        DiskFullError
            As ``write``.

        """
        if not messages:
            return
        topics, type_names, datas, log_times, publish_times = zip(*messages)
        channel_ids: Dict[str, int] = {}
        known = True
        for topic, type_name in dict.fromkeys(zip(topics, type_names)):
            channel = self._channels.get(topic)
            if channel is None or channel.type_name != type_name:
                known = False   # a new topic, or a type clash: message by message
                break
            channel_ids[topic] = channel.id
        if (not known or self._failed or self._chunk_period_s is not None
                or not _all_timestamps(log_times) or not _all_timestamps(publish_times)):
            for message in messages:
                self.write_serialized(*message)
            return
        channels = list(map(channel_ids.__getitem__, topics))
        ends = np.cumsum(np.fromiter(map(len, datas), np.int64, len(datas)))
        start, written = 0, 0         # first message not pending yet; its bytes before it
        while start < len(datas):
            # The message that fills the chunk in progress, as _add would find it.
            end = int(np.searchsorted(ends, written + CHUNK_SIZE - self._pending_bytes))
            end = min(max(end, start) + 1, len(datas))
            self._pending_channels += channels[start:end]
            self._pending_log_times += log_times[start:end]
            self._pending_publish_times += publish_times[start:end]
            self._pending_datas += datas[start:end]
            self._pending_bytes += int(ends[end - 1]) - written
            start, written = end, int(ends[end - 1])
            if self._pending_bytes >= CHUNK_SIZE:
                self.flush()

    def flush_if_due(self) -> None:
        """Write a chunk, or sync to disk, if one is due (call it when idle)."""
        now = time.monotonic()
        if self._pending_datas and now >= self._flush_due:
            self.flush()
        elif now >= self._sync_due:
            self._sync(now)

    def _sync(self, now):
        self._sync_due = now + SYNC_PERIOD_S
        try:
            self._output.sync()
        except OSError as error:
            self._fail(error)

    def _summary_reserve(self):
        """Bytes that closing the bag may still need: summary, metadata record, metadata.yaml."""
        channels = len(self._channels)
        chunk_indexes = (self._chunk_count + 1) * (
            _SUMMARY_PER_CHUNK + _SUMMARY_PER_CHANNEL_IN_CHUNK * channels)
        # The rosbag2 metadata is written twice (metadata record, metadata.yaml).
        metadata = 2 * (2048 + 1024 * channels)
        return 2 * self._summary_bytes + chunk_indexes + metadata + _SUMMARY_FIXED

    def flush(self) -> None:
        """
        Write the messages collected so far as one chunk (to disk, if a sync is due).

        Raises
        ------
        DiskFullError
            If the chunk and the space needed to close the bag do not fit on the disk: as many
            of its first messages as fit are written, the others dropped.
        BagError
            If writing failed otherwise (the bag cannot be closed then).

        """
        now = time.monotonic()
        if self._chunk_period_s is not None:
            self._flush_due = now + self._chunk_period_s
        count = len(self._pending_datas)
        if not count:
            return
        fitting = self._reserve_chunk()
        dropped = count - fitting
        pending: Tuple[List[Any], ...] = (self._pending_channels, self._pending_log_times,
                                          self._pending_publish_times, self._pending_datas)
        if dropped:
            pending = tuple(values[:fitting] for values in pending)
        try:
            self._writer.write_chunk(*pending)
            self._writer.flush()
        except OSError as error:
            self._fail(error)
        if now >= self._sync_due:
            self._sync(now)
        if fitting:
            self._chunk_count += 1
            self._registered_bytes = 0
        self._drop_pending()
        if dropped:
            raise DiskFullError(
                f'disk full writing {self.path}: kept {self.message_count} messages, '
                f'{dropped} not written', kept=self.message_count, dropped=dropped)

    def _reserve_chunk(self):
        """Reserve space for a chunk and for closing; return how many pending messages fit."""
        count = len(self._pending_datas)
        data_bytes = self._pending_bytes
        # A message index record per channel (its entries are in _MESSAGE_OVERHEAD).
        indexes = MESSAGE_INDEX_OVERHEAD * len(self._channels)
        while count:
            chunk_size = (data_bytes + _MESSAGE_OVERHEAD * count + self._registered_bytes
                          + indexes + _CHUNK_OVERHEAD)
            try:
                self._output.reserve(chunk_size + self._summary_reserve())
                return count
            except OSError as error:
                if error.errno != errno.ENOSPC:
                    self._fail(error)
            count //= 2
            data_bytes = sum(map(len, self._pending_datas[:count]))
        return 0

    def _drop_pending(self):
        """Start an empty chunk: each message's channel id, log and publish time, data."""
        self._pending_channels: List[int] = []
        self._pending_log_times: List[int] = []
        self._pending_publish_times: List[int] = []
        self._pending_datas: List[Any] = []
        self._pending_bytes = 0

    def _fail(self, error):
        self._failed = True
        kept = (f'; what was written is in {self.part_path}' if self.keep_unfinished else '')
        raise BagError(f'cannot write output {self.path}: {error.strerror}{kept}') from None

    def rosbag2_metadata(self) -> Dict[str, Any]:
        """Return metadata.yaml's ``rosbag2_bagfile_information`` (version 9) of the bag so far."""
        statistics = self._writer.statistics
        count = statistics.message_count
        start = statistics.message_start_time if count else 0
        duration = {'nanoseconds': statistics.message_end_time - start if count else 0}
        storage_name = self._output.storage_name
        message_counts = self.message_counts
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
                    'offered_qos_profiles': metadata_yaml.load(topic.offered_qos_profiles) or [],
                    'type_description_hash': topic.type_hash,
                },
                'message_count': message_counts[topic.name],
            } for topic in self._topics],
            # rosbag2's own (file or message) compression: none; MCAP compresses chunks.
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [storage_name],
            'files': [{
                'path': storage_name,
                'starting_time': {'nanoseconds_since_epoch': start},
                'duration': dict(duration),   # a copy: no YAML alias
                'message_count': count,
            }],
            'custom_data': {},
            'ros_distro': os.environ.get('ROS_DISTRO', 'jazzy'),
        }

    def close(self) -> None:
        """
        Write what is collected, finish the bag and rename it to ``path``; idempotent.

        After a ``DiskFullError`` it still closes the bag, with the messages written before it.

        Raises
        ------
        BagError
            If the bag cannot be finished; the ``.part`` is removed, or kept with
            ``keep_unfinished``.

        """
        if self._output.closed:
            return
        try:
            try:
                self.flush()
            except DiskFullError:
                if not self.keep_unfinished:
                    raise
            metadata = self.rosbag2_metadata()
            try:
                serialized = metadata_yaml.dump(metadata)
                self._writer.add_metadata('rosbag2', {'serialized_metadata': serialized})
                self._writer.finish()
            except OSError as error:
                self._fail(error)
            self._output.finish(metadata_yaml.dump({'rosbag2_bagfile_information': metadata}))
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Stop writing: remove the ``.part`` (or keep it, with ``keep_unfinished``)."""
        if self._output.closed:
            return
        if self.keep_unfinished:
            self._output.keep()
        else:
            self._output.discard()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type: Optional[type[BaseException]], exc: Optional[BaseException],
                 traceback: Optional[TracebackType]) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
