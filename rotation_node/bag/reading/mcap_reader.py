"""
Read one MCAP file, every layout, as rosbag2 writes it (``ros2 bag record -s mcap``) or not.

CDR bytes are returned unchanged, chunk by chunk; a chunk's Message records are read as arrays
(:func:`chunk_records`: 1.0 instead of the mcap library's 2.9 us per message). Every length is
checked against the end of its record or of the file before anything is read or decompressed:
a damaged length is a note or one error line, never a huge allocation.
"""
from __future__ import annotations

from collections import Counter
import dataclasses
import heapq
import io
import itertools
import operator
import os
import struct
from typing import (
    Collection, Dict, Iterable, Iterator, List, NamedTuple, Optional, Tuple, TYPE_CHECKING, Union)
import zlib

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import Channel, ChunkIndex, Schema, Statistics
import numpy as np
from rotation_node.bag.mcap_layout import MCAP_MAGIC, MESSAGE_FIELDS, MESSAGE_HEADER
from rotation_node.bag.reading.compression import decompressed_message, ZSTD_MAGIC
from rotation_node.bag.records import BagMessage, MESSAGE_ENCODING, TopicMetadata
from rotation_node.errors import BagError
import zstandard

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

_MAGIC_SIZE = len(MCAP_MAGIC)
_RECORD_PREFIX = struct.Struct('<BQ')    # opcode, length of what follows
_FOOTER = struct.Struct('<BQQQI')        # opcode, length, summary (offset) start, summary CRC
_CHUNK_FIELDS = struct.Struct('<QQQII')  # start and end time, size, CRC, compression name length
_MESSAGE_FIELDS = struct.Struct('<HIQQ')       # channel id, sequence, log and publish time
_MESSAGE_INDEX_FIELDS = struct.Struct('<HI')   # channel id, length of the entries
_MESSAGE_INDEX_ENTRY = 16                      # log time, offset
_DECOMPRESS_PIECE = 1 << 24   # bytes asked of a decompressor at a time
_SUMMARY_RECORDS = {Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
                    Opcode.CHUNK_INDEX: ChunkIndex, Opcode.STATISTICS: Statistics}
_OPCODES = frozenset(Opcode)
_SUMMARY_ONLY = (Opcode.CHUNK_INDEX, Opcode.ATTACHMENT_INDEX, Opcode.METADATA_INDEX,
                 Opcode.STATISTICS, Opcode.SUMMARY_OFFSET)
_LOSSES_SHOWN = 3   # places named in the loss note
_HEADER_BYTES = np.arange(MESSAGE_HEADER.itemsize)
_ZSTD_MAGIC = np.frombuffer(ZSTD_MAGIC, np.uint8)


def checked_topics(topics: Iterable[str], available: Collection[str], path: str) -> List[str]:
    """Return ``topics`` as a list; BagError naming those not in ``available`` (bag ``path``)."""
    topics = list(topics)
    missing = [topic for topic in topics if topic not in available]
    if missing:
        raise BagError(f'topic {", ".join(missing)} not in {path} '
                       f'(it has {", ".join(sorted(available)) or "no topics"})')
    return topics


def add_topic(topic_metadata: Dict[str, TopicMetadata], message_counts: Dict[str, int],
              topic: str, metadata: TopicMetadata, count: int, path: str) -> None:
    """Add a topic's metadata and ``count`` messages; BagError if it already has another type."""
    known = topic_metadata.setdefault(topic, metadata)
    if known.type_name != metadata.type_name:
        raise BagError(f'topic {topic} in {path} has two types: '
                       f'{known.type_name} and {metadata.type_name}')
    message_counts[topic] = message_counts.get(topic, 0) + count


class _Damage(Exception):
    """A part of an MCAP file that cannot be read: what is wrong with it, at which offset."""

    def __init__(self, offset: int, what: str) -> None:
        super().__init__(offset, what)
        self.offset, self.what = offset, what

    def __str__(self) -> str:
        return f'{self.what} at offset {self.offset}'


class _RecordStream(ReadDataStream):
    """The mcap library's field reader over one record's bytes, refusing a field cut short."""

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile()
        return data


def _parsed(record_class, body, offset):
    """Parse the body of one record with the mcap library; _Damage if it does not parse."""
    try:
        return record_class.read(_RecordStream(io.BytesIO(body)))
    except (McapError, struct.error, UnicodeDecodeError) as error:
        described = f'{type(error).__name__}: {error}' if str(error) else type(error).__name__
        raise _Damage(offset, f'{record_class.__name__} record that does not parse '
                              f'({described})') from None


class _File:
    """Bounded reads of an open file: nothing past its end is read, whatever a length says."""

    def __init__(self, stream):
        self.stream = stream
        self.size = os.fstat(stream.fileno()).st_size

    def read(self, offset, length, what):
        """Return ``length`` bytes at ``offset``; _Damage if they run past the end of the file."""
        if offset < 0 or length < 0 or offset + length > self.size:
            raise _Damage(offset, f'{what} of {length} bytes that runs past the end of the '
                                  f'file ({self.size} bytes)')
        self.stream.seek(offset)
        data = self.stream.read(length)
        if len(data) != length:
            raise _Damage(offset, f'{what} cut short (the file shrank while it was read)')
        return data

    def records(self, start, end):
        """Yield ``(offset, opcode, length)`` of the records from ``start`` to ``end``, unread."""
        position = start
        while position < end:
            if end - position < _RECORD_PREFIX.size:
                raise _Damage(position, f'record cut short ({end - position} bytes)')
            opcode, length = _RECORD_PREFIX.unpack(
                self.read(position, _RECORD_PREFIX.size, 'record'))
            if opcode == 0:
                raise _Damage(position, 'record of opcode 0 (zeroed bytes?)')
            if length > end - position - _RECORD_PREFIX.size:
                limit = ('the end of the file' if end == self.size
                         else f'the end of its section ({end})')
                raise _Damage(position, f'record (opcode {opcode:#04x}) of {length} bytes that '
                                        f'runs past {limit}')
            yield position, opcode, length
            position += _RECORD_PREFIX.size + length


def _bounded(read, size, offset):
    """Join what ``read(max_length)`` returns; _Damage once it exceeds the chunk's ``size``."""
    pieces, total = [], 0
    while True:
        piece = read(min(_DECOMPRESS_PIECE, size + 1 - total))
        if not piece:
            break
        pieces.append(piece)
        total += len(piece)
        if total > size:
            raise _Damage(offset, f'chunk that decompresses to more than the {size} '
                                  'bytes it states')
    return pieces[0] if len(pieces) == 1 else b''.join(pieces)


def _unzstd(stored, size, offset):
    """Decompress a zstd chunk stating ``size`` bytes, never holding more than that."""
    try:
        with zstandard.ZstdDecompressor().stream_reader(stored) as reader:
            return _bounded(reader.read, size, offset)
    except zstandard.ZstdError as error:
        raise _Damage(offset, f'chunk that does not decompress (zstd: {error})') from None


def _unlz4(stored, size, offset):
    """Decompress an lz4 chunk stating ``size`` bytes, never holding more than that."""
    import lz4.frame   # only for lz4 chunks
    decompressor = lz4.frame.LZ4FrameDecompressor()
    pending = [stored]   # the frame, given to the decompressor once

    def read(max_length):
        if decompressor.eof:
            return b''
        return decompressor.decompress(pending.pop() if pending else b'', max_length=max_length)

    try:
        data = _bounded(read, size, offset)
    except RuntimeError as error:   # lz4.frame's error for data that is not a valid frame
        raise _Damage(offset, f'chunk that does not decompress (lz4: {error})') from None
    if not decompressor.eof:
        raise _Damage(offset, 'chunk whose lz4 frame is cut short')
    return data


#: ``decompressed(stored, size, offset)`` by chunk compression name.
_DECOMPRESSED = {'zstd': _unzstd, 'lz4': _unlz4, '': lambda stored, size, offset: bytes(stored)}


def chunk_data(body: Union[bytes, memoryview], offset: int = 0) -> tuple:
    """
    Return the compression (``'zstd'``, ``'lz4'``, ``''``) and the records of a Chunk record.

    ``body``: the record after opcode and length. _Damage if a length runs past the record, it does
    not decompress to the size it states, or fails its CRC; memory never exceeds the real data.
    """
    if len(body) < _CHUNK_FIELDS.size:
        raise _Damage(offset, f'chunk of {len(body)} bytes, shorter than its fixed fields')
    _, _, size, crc, name_length = _CHUNK_FIELDS.unpack_from(body)
    position = _CHUNK_FIELDS.size + name_length
    if position + 8 > len(body):
        raise _Damage(offset, f'chunk whose compression name length ({name_length}) runs past '
                              'the chunk')
    compression = bytes(body[_CHUNK_FIELDS.size:position])
    records_length, = struct.unpack_from('<Q', body, position)
    position += 8
    if records_length > len(body) - position:
        raise _Damage(offset, f'chunk whose records length ({records_length}) runs past the '
                              'chunk')
    decompressed = _DECOMPRESSED.get(compression.decode('latin-1'))
    if decompressed is None:
        raise _Damage(offset, f'chunk of unknown compression {compression[:16]!r}')
    data = decompressed(body[position:position + records_length], size, offset)
    if crc != 0 and zlib.crc32(data) != crc:
        raise _Damage(offset, f'chunk that fails its CRC (stored {crc:#010x}, computed '
                              f'{zlib.crc32(data):#010x})')
    if compression and len(data) != size and crc == 0:   # (a CRC vouches for the data)
        raise _Damage(offset, f'chunk that decompresses to {len(data)} bytes, not the {size} '
                              'it states')
    return compression.decode(), data


def _chunk_data_by_index(body, index):
    """Return the records of a chunk with damaged lengths, by its index's, if its CRC vouches."""
    crc = _CHUNK_FIELDS.unpack_from(body)[3] if len(body) >= _CHUNK_FIELDS.size else 0
    start = _CHUNK_FIELDS.size + len(index.compression.encode()) + 8
    stored = body[start:start + index.compressed_size]
    if crc == 0 or len(stored) != index.compressed_size:
        return None
    try:
        data = _DECOMPRESSED.get(index.compression, _DECOMPRESSED[''])(
            stored, index.uncompressed_size, index.chunk_start_offset)
    except _Damage:
        return None
    return data if zlib.crc32(data) == crc else None


class ChunkRecords(NamedTuple):
    """
    The records of an uncompressed chunk, as :func:`chunk_records` finds them.

    ``headers``: a ``MESSAGE_HEADER`` per Message record; ``starts``: where their data starts
    (``headers['length'] - 22`` bytes); ``definitions``: ``(position, opcode, length)`` of the
    Schema and Channel records; ``damage``: what stopped the walk early, or None.
    """

    headers: np.ndarray
    starts: np.ndarray
    definitions: List[Tuple[int, int, int]]
    damage: Optional[str]


def chunk_records(data: bytes) -> ChunkRecords:
    """
    Find the records of an uncompressed chunk in one walk, the Message records' fields as arrays.

    The walk stops at the first record that cannot be one (opcode 0, a length past the end, a
    Message record shorter than its fixed fields); ``damage`` says what stopped it.
    """
    offsets: List[int] = []
    definitions: List[Tuple[int, int, int]] = []
    add = offsets.append
    unpack = _RECORD_PREFIX.unpack_from
    prefix, message, schema, channel = (
        _RECORD_PREFIX.size, int(Opcode.MESSAGE), int(Opcode.SCHEMA), int(Opcode.CHANNEL))
    position, end, damage = 0, len(data), None
    while position < end:
        if position + prefix > end:
            damage = f'record at {position} of a chunk of {end} bytes is cut short'
            break
        opcode, length = unpack(data, position)
        following = position + prefix + length
        if opcode == message and length >= MESSAGE_FIELDS and following <= end:
            add(position)
        elif opcode == 0:
            damage = f'record of opcode 0 (zeroed bytes?) at {position} of the chunk'
            break
        elif following > end:
            damage = f'record at {position} of a chunk of {end} bytes ends at {following}'
            break
        elif opcode == message:
            damage = f'message record at {position} of the chunk is {length} bytes'
            break
        elif opcode == schema or opcode == channel:
            definitions.append((position, opcode, length))
        position = following
    starts = np.array(offsets, np.int64)
    raw = np.frombuffer(data, np.uint8)
    headers = raw[starts[:, None] + _HEADER_BYTES].view(MESSAGE_HEADER)[:, 0]
    return ChunkRecords(headers, starts + MESSAGE_HEADER.itemsize, definitions, damage)


@dataclasses.dataclass
class _Loss:
    """Messages a file says it holds but that could not be read, and where."""

    offset: Optional[int]    # of the chunk or record; None: not in any chunk the index lists
    what: str
    counts: Optional[Dict[int, int]]   # {channel id: messages lost}; None if unknown
    #: Only fewer messages than the chunk's message index (a misplaced chunk's too).
    index_only: bool = False


def _summary_counts(statistics):
    """``{channel id: messages}`` of a Statistics record; None without per-channel counts."""
    if statistics is None:
        return None
    counts = dict(statistics.channel_message_counts)
    return counts if sum(counts.values()) == statistics.message_count else None


@dataclasses.dataclass
class _Summary:
    """What the summary section of a complete file holds (empty if it has none)."""

    end: int      # where the data section ends at the latest
    schemas: Dict[int, Schema] = dataclasses.field(default_factory=dict)
    channels: Dict[int, Channel] = dataclasses.field(default_factory=dict)
    chunk_indexes: List[ChunkIndex] = dataclasses.field(default_factory=list)
    statistics: Optional[Statistics] = None
    damage: Optional[_Damage] = None


def _overlapping(chunks):
    """
    Whether chunks (sorted by start time, offset) must be merged to be read in the right order.

    The mcap library's: log time, chunk offset, place in the chunk. Recordings' never overlap.
    """
    for position, chunk in enumerate(chunks):
        for later in chunks[position + 1:]:
            if later.message_start_time > chunk.message_end_time:
                break
            if not (later.message_start_time == chunk.message_end_time
                    and later.chunk_start_offset > chunk.chunk_start_offset):
                return True
    return False


class _LinearScan:
    """
    A scan of an MCAP file's data section, yielding ``(channel, log time, publish time, data)``.

    In file order, collecting schemas and channels. What cannot be read adds a :class:`_Loss`,
    counted by the message indexes after it; a record running past ``end`` ends the scan (where the
    writer stopped if ``cut_ok``, else a loss too).
    """

    def __init__(self, file, end, cut_ok, summary=None):
        self._file = file
        self._end = end
        self._cut_ok = cut_ok
        # A readable summary's channels are known before a chunk moved ahead uses them.
        known = summary is not None and summary.damage is None
        self.schemas: Dict[int, Schema] = dict(summary.schemas) if known else {}
        self.channels: Dict[int, Channel] = dict(summary.channels) if known else {}
        self.losses: List[_Loss] = []
        self.compressions: set = set()
        # {channel id: [offset of the first, number]} of messages on channels never defined
        self._orphans: Dict[int, List[int]] = {}

    def __iter__(self):
        pending = None   # [offset, {channel: read}, damage, {channel: indexed}] of the last chunk
        try:
            for offset, opcode, length in self._file.records(_MAGIC_SIZE, self._end):
                if opcode == Opcode.MESSAGE_INDEX:
                    if pending is None:   # the chunk it indexes is not where it should be
                        pending = [offset, {}, 'message index of a missing chunk', None]
                    self._count_index(pending, offset, length)
                    continue
                if pending is not None:
                    self._settle(pending)
                    pending = None
                if opcode == Opcode.DATA_END or opcode == Opcode.FOOTER:
                    break
                if opcode == Opcode.CHUNK:
                    pending = [offset, {}, None, None]
                    yield from self._chunk(offset, length, pending)
                elif opcode in (Opcode.MESSAGE, Opcode.SCHEMA, Opcode.CHANNEL):
                    yield from self._record(offset, opcode, length)
                elif opcode in _SUMMARY_ONLY:   # what it replaced is lost
                    self.losses.append(_Loss(offset, f'{Opcode(opcode).name.lower()} record '
                                                     'out of place (in the data section)', None))
        except _Damage as damage:
            if not self._cut_ok:
                self.losses.append(_Loss(None, f'{damage}; nothing after it could be read',
                                         None))
            elif pending is None:   # where the writer stopped: perhaps inside a chunk
                yield from self._cut_chunk(damage.offset)
        if pending is not None:
            self._settle(pending)
        self.losses.extend(
            _Loss(offset, f'messages on channel {channel_id}, which has no Channel record',
                  {channel_id: count})
            for channel_id, (offset, count) in sorted(self._orphans.items()))

    def _define(self, opcode, body, offset):
        """Keep a Schema or Channel record; _Damage if it does not parse."""
        record = _parsed(Schema if opcode == Opcode.SCHEMA else Channel, body, offset)
        (self.schemas if opcode == Opcode.SCHEMA else self.channels)[record.id] = record

    def _record(self, offset, opcode, length):
        body = self._file.read(offset + _RECORD_PREFIX.size, length, 'record')
        if opcode != Opcode.MESSAGE:
            try:
                self._define(opcode, body, offset)
            except _Damage:   # its messages are on an unknown channel: lost, counted there
                pass
            return
        if length < MESSAGE_FIELDS:
            self.losses.append(_Loss(offset, f'message record of {length} bytes', None))
            return
        channel_id, _, log_time, publish_time = _MESSAGE_FIELDS.unpack_from(body)
        channel = self.channels.get(channel_id)
        if channel is None:
            self._orphans.setdefault(channel_id, [offset, 0])[1] += 1
        else:
            yield channel, log_time, publish_time, body[MESSAGE_FIELDS:]

    def _chunk(self, offset, length, pending):
        body = self._file.read(offset + _RECORD_PREFIX.size, length, 'chunk')
        try:
            compression, data = chunk_data(body, offset)
        except _Damage as damage:
            pending[2] = damage.what
            return
        self.compressions.add(compression or 'none')
        yield from self._chunk_messages(data, offset, pending)

    def _cut_chunk(self, offset):
        """Yield the complete messages of an uncompressed chunk cut short by the file's end."""
        if self._file.size - offset < _RECORD_PREFIX.size + _CHUNK_FIELDS.size:
            return
        body = self._file.read(offset, self._file.size - offset, 'chunk')
        start = _RECORD_PREFIX.size + _CHUNK_FIELDS.size
        if (body[0] != Opcode.CHUNK or _CHUNK_FIELDS.unpack_from(body, _RECORD_PREFIX.size)[-1]
                or len(body) < start + 8):
            return   # not a chunk, or a compressed one: nothing can be read of a part
        yield from self._chunk_messages(body[start + 8:], offset, [offset, {}, None, None])

    def _chunk_messages(self, data, offset, pending):
        """Yield the messages of a chunk's records; note its schemas, channels and damage."""
        records = chunk_records(data)
        pending[2] = records.damage
        for position, opcode, record_length in records.definitions:
            start = position + _RECORD_PREFIX.size
            try:
                self._define(opcode, data[start:start + record_length], offset)
            except _Damage as damage:
                pending[2] = f'{damage.what} at {position} of the chunk'
        read = pending[1]
        headers, starts = records.headers, records.starts
        ends = (starts + (headers['length'].astype(np.int64) - MESSAGE_FIELDS)).tolist()
        for channel_id, log_time, publish_time, start, end in zip(
                headers['channel_id'].tolist(), headers['log_time'].tolist(),
                headers['publish_time'].tolist(), starts.tolist(), ends):
            channel = self.channels.get(channel_id)
            if channel is None:
                pending[2] = pending[2] or f'messages on channel {channel_id}, which has no ' \
                                           'Channel record'
                continue
            read[channel_id] = read.get(channel_id, 0) + 1
            yield channel, log_time, publish_time, data[start:end]

    def _count_index(self, pending, offset, length):
        """Add a Message Index record's count to the chunk before it."""
        try:
            channel_id, count = _message_index_count(
                self._file.read(offset + _RECORD_PREFIX.size, length, 'message index'), offset)
        except _Damage:
            return
        indexed = pending[3] = pending[3] or {}
        indexed[channel_id] = indexed.get(channel_id, 0) + count

    def _settle(self, pending):
        offset, read, damage, indexed = pending
        if indexed is None:
            if damage is not None:
                self.losses.append(_Loss(offset, damage, None))
            return
        lost = {channel: count - read.get(channel, 0) for channel, count in indexed.items()
                if count > read.get(channel, 0)}
        if damage is not None or lost:
            self.losses.append(_Loss(offset, damage or 'fewer messages than its message index '
                                                       'lists', lost, index_only=damage is None))


def _message_index_count(body, offset):
    """``(channel id, number of messages)`` of a Message Index record's body."""
    if len(body) < _MESSAGE_INDEX_FIELDS.size:
        raise _Damage(offset, 'message index record shorter than its fixed fields')
    channel_id, records_length = _MESSAGE_INDEX_FIELDS.unpack_from(body)
    if (records_length > len(body) - _MESSAGE_INDEX_FIELDS.size
            or records_length % _MESSAGE_INDEX_ENTRY):
        raise _Damage(offset, f'message index record of {records_length} entry bytes')
    return channel_id, records_length // _MESSAGE_INDEX_ENTRY


class BagReader:
    """
    Read one MCAP file: every valid layout, unfinished recordings, damage skipped and noted.

    A file whose summary indexes it is read chunk by chunk in log-time order; any other by a linear
    scan in file order (sorted in memory if that is not log-time order), an unfinished recording up
    to its last complete record. What cannot be read is one line in ``notes`` (after the scan, or
    once ``messages`` has read an indexed file); ``strict`` makes it, and an unfinished recording,
    a BagError. ``message_counts``: the file's own, or what a scan read; ``recovered``: the
    messages of an unfinished recording, else None.
    """

    def __init__(self, path: StrPath, *, strict: bool = False) -> None:
        self.path = os.fspath(path)
        self.recovered: Optional[int] = None
        self.notes: List[str] = []
        self._strict = strict
        try:
            self._stream = open(self.path, 'rb')
        except OSError as error:
            raise BagError(f'cannot open bag {self.path}: {error.strerror}') from None
        try:
            self._file = _File(self._stream)
            if self._file.size == 0:
                raise BagError(f'{self.path}: empty file (0 bytes), not an MCAP bag')
            magic = self._file.read(0, min(_MAGIC_SIZE, self._file.size), 'magic')
            if magic != MCAP_MAGIC:
                raise BagError(f'{self.path} is not a valid MCAP file: invalid magic {magic!r}')
            summary = self._summary()
            if summary is not None and self._indexable(summary):
                self._summary_section = summary
                self._scan_end: Optional[int] = None
                self.compression = compression_name({index.compression
                                                     for index in summary.chunk_indexes})
                self._set_topics(summary.channels.values(), summary.schemas, self._counted)
            else:
                self._open_scan(summary)
        except BaseException:
            self._stream.close()
            raise

    def _summary(self):
        """Return the summary section, None if the file has no footer (an unfinished recording)."""
        size = self._file.size
        footer_at = size - _MAGIC_SIZE - _FOOTER.size
        if footer_at < _MAGIC_SIZE or self._file.read(size - _MAGIC_SIZE, _MAGIC_SIZE,
                                                      'magic') != MCAP_MAGIC:
            return None
        footer = self._file.read(footer_at, _FOOTER.size, 'footer')
        opcode, length, summary_start, _, crc = _FOOTER.unpack(footer)
        if opcode != Opcode.FOOTER or length != _FOOTER.size - _RECORD_PREFIX.size:
            return None
        if summary_start == 0:
            return _Summary(footer_at)
        if not _MAGIC_SIZE <= summary_start <= footer_at:
            return _Summary(footer_at, damage=_Damage(
                footer_at, f'footer whose summary start ({summary_start}) is outside the file'))
        summary = _Summary(summary_start)
        try:
            if crc != 0:
                section = self._file.read(summary_start, footer_at - summary_start, 'summary')
                if zlib.crc32(footer[:-4], zlib.crc32(section)) != crc:
                    raise _Damage(summary_start, 'summary that fails its CRC')
            for offset, opcode, length in self._file.records(summary_start, footer_at):
                record_class = _SUMMARY_RECORDS.get(opcode)
                if record_class is None:
                    continue
                record = _parsed(record_class, self._file.read(
                    offset + _RECORD_PREFIX.size, length, 'record'), offset)
                if record_class is ChunkIndex:
                    summary.chunk_indexes.append(record)
                elif record_class is Statistics:
                    summary.statistics = record
                elif record_class is Schema:
                    summary.schemas[record.id] = record
                else:
                    summary.channels[record.id] = record
        except _Damage as damage:
            return _Summary(summary_start, damage=damage)
        return summary

    def _indexable(self, summary):
        """
        Whether the summary indexes the whole file: read it through the index, not a scan.

        Chunk indexes pointing at the chunks, counts (statistics or message indexes), and a Channel
        record (and Schema) for every channel counted.
        """
        if summary.damage is not None or not summary.chunk_indexes:
            return False
        if not all(text.isprintable() for text in itertools.chain(
                (schema.name for schema in summary.schemas.values()),
                (channel.topic for channel in summary.channels.values()))):
            return False   # zeroed bytes in a summary without CRC: the data section's records
        if any(not _MAGIC_SIZE <= index.chunk_start_offset
               or index.chunk_start_offset + index.chunk_length > summary.end
               for index in summary.chunk_indexes):
            return False
        try:   # chunks moved or swapped in the data section: found by a scan, not the index
            if any(self._moved(index, summary.end) for index in summary.chunk_indexes):
                return False
        except _Damage:
            return False
        self._indexed = {index.chunk_start_offset: self._index_counts(index)
                         for index in summary.chunk_indexes}
        counted = _summary_counts(summary.statistics)
        if None in self._indexed.values():
            if counted is None:
                return False
        else:
            totals: Counter = Counter()
            for counts in self._indexed.values():
                totals.update(counts)
            if counted is not None and ({c: n for c, n in counted.items() if n}
                                        != {c: n for c, n in totals.items() if n}):
                return False   # messages outside the indexed chunks
            counted = totals
        self._counted = counted
        return all(channel_id in summary.channels
                   and summary.channels[channel_id].schema_id in (0, *summary.schemas)
                   for channel_id in counted)

    def _moved(self, index, end):
        """Whether a chunk index points at another whole record (moved: a scan; else the index)."""
        opcode, length = _RECORD_PREFIX.unpack(self._file.read(
            index.chunk_start_offset, _RECORD_PREFIX.size, 'chunk'))
        return (opcode in _OPCODES
                and (opcode, length) != (Opcode.CHUNK, index.chunk_length - _RECORD_PREFIX.size)
                and index.chunk_start_offset + _RECORD_PREFIX.size + length <= end)

    def _index_counts(self, index):
        """``{channel id: messages}`` of a chunk by its message indexes; None if it has none."""
        offsets = index.message_index_offsets
        if not offsets:
            return None
        start = min(offsets.values())
        counts: Dict[int, int] = {}
        try:
            for offset, opcode, length in self._file.records(
                    start, start + index.message_index_length):
                if opcode == Opcode.MESSAGE_INDEX:
                    channel_id, count = _message_index_count(self._file.read(
                        offset + _RECORD_PREFIX.size, length, 'message index'), offset)
                    counts[channel_id] = counts.get(channel_id, 0) + count
        except _Damage:
            return None
        return counts if counts.keys() == offsets.keys() else None

    def _open_scan(self, summary):
        """Index a file by reading it once; decide how much to recover, say what is lost."""
        unfinished = summary is None
        end = self._file.size if unfinished else summary.end
        self._scan_summary = summary
        scan = _LinearScan(self._file, end, cut_ok=unfinished, summary=summary)
        counts: Counter = Counter()
        previous, self._scan_ordered = -1, True
        for channel, log_time, _, _ in scan:
            counts[channel.id] += 1
            self._scan_ordered = self._scan_ordered and log_time >= previous
            previous = log_time
        if unfinished:
            if self._strict:
                raise BagError(f'{self.path}: unfinished recording (no MCAP summary or footer), '
                               f'{sum(counts.values())} messages recoverable; refused (--strict)')
            self.recovered = sum(counts.values())
        self._scan_end = end
        self.compression = compression_name(scan.compressions)
        read = dict(counts)
        self._channel_topics: Dict[int, str] = {
            channel.id: channel.topic for channel in scan.channels.values()}
        counted = None if summary is None else _summary_counts(summary.statistics)
        if counted is not None and all(read.get(channel_id, 0) >= count
                                       for channel_id, count in counted.items()):
            # Every message the statistics count was read: chunks out of place, not lost.
            scan.losses = [loss for loss in scan.losses if not loss.index_only]
        self._report(scan.losses, read, counted, None)
        if not unfinished:   # counted as the file holds them, as through an index
            for loss in scan.losses:
                counts.update(loss.counts or {})
        self._set_topics(scan.channels.values(), scan.schemas, counts)

    def _report(self, losses, read, counted, wanted):
        """
        Say what could not be read, on one line in ``notes`` (a BagError with ``strict``).

        ``read``, ``counted`` (None: unknown): ``{channel id: messages}``; ``wanted``: None: all.
        Messages counted but neither read nor in a loss are lost outside the chunks indexed.
        """
        losses = list(losses)
        if counted is not None:
            known: Counter = Counter()
            for loss in losses:
                known.update(loss.counts or {})
            missing = {channel_id: count - read.get(channel_id, 0) - known.get(channel_id, 0)
                       for channel_id, count in counted.items()
                       if wanted is None or channel_id in wanted}
            missing = {channel_id: count for channel_id, count in missing.items() if count > 0}
            if missing:
                unknown = [loss for loss in losses if loss.counts is None]
                if unknown:   # the statistics say how many the unreadable parts held
                    unknown[0].counts = missing
                    for loss in unknown[1:]:
                        loss.counts = {}
                else:
                    losses.append(_Loss(None, 'not in any chunk or record that could be read',
                                        missing))
        losses = [loss for loss in losses if loss.counts is None or any(
            count for channel_id, count in loss.counts.items()
            if wanted is None or channel_id in wanted) or loss.offset is not None]
        if not losses:
            return
        note = f'{self.path}: {_loss_summary(losses, self._channel_topics, wanted)}'
        if self._strict:
            raise BagError(f'{note}; refused (--strict)')
        if note not in self.notes:
            self.notes.append(note)

    def _set_topics(self, channels, schemas, counts):
        self.topic_metadata: Dict[str, TopicMetadata] = {}
        self.message_counts: Dict[str, int] = {}
        self._type_names: Dict[int, str] = {}
        self._channel_topics = {}
        self._channels: Dict[int, Channel] = {}
        for channel in channels:
            metadata = self._topic_metadata(channel, schemas.get(channel.schema_id))
            add_topic(self.topic_metadata, self.message_counts, channel.topic, metadata,
                      counts.get(channel.id, 0), self.path)
            self._type_names[channel.id] = metadata.type_name
            self._channel_topics[channel.id] = channel.topic
            self._channels[channel.id] = channel
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
        Iterate over the messages of ``topics`` (default all) in log-time order (ties: file order).

        rosbag2's message compression is undone. What cannot be read is skipped and said in
        ``notes`` at the end; BagError at once for a topic not in the bag, with ``strict`` at
        damage.
        """
        if topics is not None:
            topics = checked_topics(topics, self.topics, self.path)
        wanted = {channel_id for channel_id, topic in self._channel_topics.items()
                  if topics is None or topic in topics}
        if self._scan_end is None:
            return self._indexed_messages(wanted)
        records = self._scanned_messages(wanted)
        return records if self._scan_ordered else iter(
            sorted(records, key=operator.attrgetter('log_time_ns')))

    def _message(self, channel, data, log_time, publish_time):
        if data[:4] == ZSTD_MAGIC and channel.message_encoding == MESSAGE_ENCODING:
            try:
                data = decompressed_message(data)
            except zstandard.ZstdError as error:
                raise BagError(f'{self.path}: message on {channel.topic} at {log_time} ns does '
                               f'not decompress (rosbag2 message compression): {error}') from None
        return BagMessage(channel.topic, self._type_names[channel.id], data, log_time,
                          publish_time)

    def _indexed_messages(self, wanted):
        losses: List[_Loss] = []
        read: Dict[int, int] = {}
        wanted_ids = np.array(sorted(wanted), np.uint16)
        chunks = sorted(self._summary_section.chunk_indexes,
                        key=lambda index: (index.message_start_time, index.chunk_start_offset))
        if _overlapping(chunks):
            yield from self._merged(chunks, wanted_ids, losses, read)
        else:
            for index in chunks:
                yield from self._chunk_messages(index, wanted_ids, losses, read)
        self._report(losses, read, {channel_id: count for channel_id, count
                                    in self._counted.items() if channel_id in wanted}, wanted)

    def _merged(self, chunks, wanted_ids, losses, read):
        """Merge overlapping chunks by (log time, chunk offset, place), loading them as needed."""
        heap: List[tuple] = []
        loaded = 0
        while True:
            while loaded < len(chunks) and (
                    not heap or chunks[loaded].message_start_time <= heap[0][0]):
                index = chunks[loaded]
                for place, message in enumerate(
                        self._chunk_messages(index, wanted_ids, losses, read)):
                    heapq.heappush(heap, (message.log_time_ns, index.chunk_start_offset, place,
                                          message))
                loaded += 1
            if not heap:
                return
            yield heapq.heappop(heap)[3]

    def _chunk_messages(self, index, wanted_ids, losses, read):
        """Return the messages of a chunk on the wanted channels, sorted by log time."""
        offset = index.chunk_start_offset
        indexed = self._indexed[offset]
        try:
            body = self._file.read(offset, index.chunk_length, 'chunk')
            opcode, length = _RECORD_PREFIX.unpack_from(body)
            if opcode != Opcode.CHUNK:   # (a wrong length is the index's: its CRC checks it)
                raise _Damage(offset, f'no chunk where the chunk index says (a record of '
                                      f'opcode {opcode:#04x}, {length} bytes)')
            try:
                _, data = chunk_data(memoryview(body)[_RECORD_PREFIX.size:], offset)
            except _Damage:
                data = _chunk_data_by_index(memoryview(body)[_RECORD_PREFIX.size:], index)
                if data is None:
                    raise
        except _Damage as damage:
            self._lose(losses, _Loss(offset, damage.what, indexed))
            return []
        records = chunk_records(data)
        headers, starts = records.headers, records.starts
        channel_ids = headers['channel_id']
        known = np.isin(channel_ids, list(self._channel_topics))
        present, numbers = np.unique(channel_ids[known], return_counts=True)
        got = dict(zip(present.tolist(), numbers.tolist()))
        for channel_id, count in got.items():
            read[channel_id] = read.get(channel_id, 0) + count
        lost = (None if indexed is None else
                {channel_id: count - got.get(channel_id, 0)
                 for channel_id, count in indexed.items() if count > got.get(channel_id, 0)})
        if records.damage is not None or not known.all() or lost:
            what = records.damage or (
                f'messages on channel {int(channel_ids[~known][0])}, which has no Channel '
                'record' if not known.all() else 'fewer messages than its message index lists')
            self._lose(losses, _Loss(offset, what, lost))
        kept = np.isin(channel_ids, wanted_ids)
        if not kept.all():
            headers, starts, channel_ids = headers[kept], starts[kept], channel_ids[kept]
        order = np.argsort(headers['log_time'], kind='stable')   # ties in file order
        headers, starts = headers[order], starts[order]
        ends = starts + (headers['length'].astype(np.int64) - MESSAGE_FIELDS)
        channel_ids = channel_ids[order].tolist()
        messages = list(map(BagMessage, map(self._channel_topics.__getitem__, channel_ids),
                            map(self._type_names.__getitem__, channel_ids),
                            map(data.__getitem__, map(slice, starts.tolist(), ends.tolist())),
                            headers['log_time'].tolist(), headers['publish_time'].tolist()))
        # rosbag2's message compression
        long_enough = np.nonzero(ends - starts >= _ZSTD_MAGIC.size)[0]
        first_bytes = np.frombuffer(data, np.uint8)[
            starts[long_enough, None] + np.arange(_ZSTD_MAGIC.size)]
        for place in long_enough[(first_bytes == _ZSTD_MAGIC).all(axis=1)].tolist():
            message = messages[place]
            messages[place] = self._message(self._channels[channel_ids[place]], message.data,
                                            message.log_time_ns, message.publish_time_ns)
        return messages

    def _lose(self, losses, loss):
        """Add a loss; with ``strict``, refuse the file at once."""
        losses.append(loss)
        if self._strict:
            self._report([loss], {}, None, None)

    def _scanned_messages(self, wanted):
        """Return the messages the opening scan read, no more (the file may still grow)."""
        scan = _LinearScan(self._file, self._scan_end, cut_ok=self.recovered is not None,
                           summary=self._scan_summary)
        for channel, log_time, publish_time, data in scan:
            if channel.id in wanted:
                yield self._message(channel, data, log_time, publish_time)

    def close(self) -> None:
        """Close the file."""
        self._stream.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _loss_summary(losses, topics, wanted):
    """``'9 messages could not be read (/imu 9): chunk at offset 1234 (...)'``."""
    lost: Dict[str, int] = {}
    for loss in losses:
        for channel_id, count in (loss.counts or {}).items():
            if count and (wanted is None or channel_id in wanted):
                name = topics.get(channel_id, f'channel {channel_id}')
                lost[name] = lost.get(name, 0) + count
    total = sum(lost.values())
    unknown = any(loss.counts is None for loss in losses)
    amount = (f'{"at least " if unknown else ""}{total} message{"s" if total != 1 else ""}'
              if total else 'messages')
    places = [f'{loss.what} at offset {loss.offset}' if loss.offset is not None else loss.what
              for loss in losses[:_LOSSES_SHOWN]]
    if len(losses) > _LOSSES_SHOWN:
        places.append(f'and {len(losses) - _LOSSES_SHOWN} more')
    by_topic = ', '.join(f'{topic} {count}' for topic, count in sorted(lost.items()))
    return (f'{amount} could not be read' + (f' ({by_topic})' if by_topic else '')
            + ': ' + '; '.join(places))


def compression_name(compressions: Collection[str]) -> str:
    """Return the one name for chunks compressed as ``compressions``: zstd, else lz4, else none."""
    return next((name for name in ('zstd', 'lz4') if name in compressions), 'none')
