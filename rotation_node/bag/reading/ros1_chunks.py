"""
ROS 1 bags read one chunk group at a time, in the order of rosbags' reader (docs/bags.md).

rosbags' reader holds a Python tuple per message from the moment it opens a bag;
:class:`ChunkedReader` reads a chunk's index data (as numpy arrays) when the messages reach it,
and decompresses the next chunk in another thread meanwhile. A damaged bag raises
``ReaderError`` naming the byte where it is; no read asks for more than the file holds.
"""
import ast
from collections import Counter, OrderedDict
import io
from io import BytesIO
import os
from pathlib import Path
import struct
import threading
from typing import (BinaryIO, Collection, Dict, Generator, List, NamedTuple, Optional,
                    Sequence, Tuple)

import numpy as np
from rosbags.interfaces import Connection
from rosbags.rosbag1 import ReaderError
from rosbags.rosbag1.reader import ChunkInfo, Header, read_bytes, read_uint32, Reader, RecordType
from rosbags.rosbag1.reader import decompressors as ros1_decompressors

#: One entry of an index data record (version 1): the message's time and its offset in the chunk.
INDEX_ENTRY = np.dtype([('sec', '<u4'), ('nsec', '<u4'), ('offset', '<u4')])
#: Bytes of decompressed overlapping chunks held besides the one read (others read again).
CHUNK_BYTES_HELD = 64 * 2**20
# What the chunk decompressors (bz2, lz4) raise for data they cannot decompress.
_DECOMPRESSION_ERRORS = (OSError, ValueError, EOFError, RuntimeError)


class BoundedReads(io.BufferedReader):
    """
    A file whose reads never ask for more bytes than remain in it; ``read_at``: the last's start.

    rosbags reads a record with its own length field: a damaged one would allocate up to 4 GiB.
    """

    def __init__(self, path: 'os.PathLike[str] | str') -> None:
        super().__init__(io.FileIO(path, 'rb'))
        self._size = os.fstat(self.fileno()).st_size
        self.read_at = 0

    def read(self, size: Optional[int] = -1) -> bytes:
        """Read at most ``size`` bytes, and never more than remain in the file."""
        self.read_at = self.tell()
        if size is not None and size > 0:
            size = max(0, min(size, self._size - self.read_at))
        return super().read(size)

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        """Move to a position in the file; ReaderError if it is outside the file."""
        if whence in (os.SEEK_SET, os.SEEK_CUR):
            target = offset + (self.tell() if whence == os.SEEK_CUR else 0)
            if not 0 <= target <= self._size:
                raise ReaderError(f'position {target} is outside the file ({self._size} '
                                  'bytes)')
        return super().seek(offset, whence)


class _BoundedPath:
    """What rosbags' ``Reader.open`` calls ``open('rb')`` on: gives a :class:`BoundedReads`."""

    def __init__(self, path: 'os.PathLike[str]') -> None:
        self.path = path
        self.file: Optional[BoundedReads] = None

    def open(self, mode: str = 'rb') -> BoundedReads:  # noqa: A003  (pathlib's name)
        self.file = BoundedReads(self.path)
        return self.file

    def __str__(self) -> str:
        return str(self.path)


def overlapping_chunk_groups(chunk_infos: Sequence[ChunkInfo]) -> List[List[int]]:
    """
    Return the indices of the chunks to read together (time ranges overlapping), in time order.

    Each group in the order of ``chunk_infos``; chunks without messages are left out.
    """
    by_start = sorted((i for i, info in enumerate(chunk_infos) if info.connection_counts),
                      key=lambda i: chunk_infos[i].start_time)
    groups: List[List[int]] = []
    end = 0
    for i in by_start:
        info = chunk_infos[i]
        if groups and info.start_time < end:
            groups[-1].append(i)
            end = max(end, info.end_time)
        else:
            groups.append([i])
            end = info.end_time
    return [sorted(group) for group in groups]


class ChunkedReader(Reader):
    """
    rosbags' ROS 1 reader that reads the message index one chunk group at a time.

    Its ``indexes`` stay empty; each connection's ``msgcount`` is the sum of the chunk infos'.
    """

    def open(self) -> None:  # noqa: A003  (rosbags names it so)
        """Open the bag: its header, connections, chunk infos and headers (ReaderError: where)."""
        path = self.path
        bounded = _BoundedPath(Path(str(path)))
        # rosbags opens self.path: its reads are bounded by the file.
        self.path = bounded  # type: ignore[assignment]
        try:
            super().open()   # read_index_data below skips every index data record
        except (ReaderError, UnicodeDecodeError) as error:   # a record's field name not UTF-8
            where = bounded.file.read_at if bounded.file is not None else 0
            reason = error.args[0] if isinstance(error, ReaderError) and error.args else error
            raise ReaderError(f'the read at byte {where} failed: {_unwrapped(reason)}') from None
        finally:
            self.path = path
        counts: Counter = Counter()
        for info in self.chunk_infos:
            counts.update(info.connection_counts)
        self.connections = [c._replace(msgcount=counts[c.id]) for c in self.connections]
        self.indexes.clear()

    def read_index_data(self, pos: int, indexes: Dict[int, list]) -> None:
        """Skip at open: a chunk's index data records are read when it is reached."""

    def messages(self, connections: Collection[Connection] = (), start: Optional[int] = None,
                 stop: Optional[int] = None
                 ) -> Generator[Tuple[Connection, int, bytes], None, None]:
        """
        Yield ``(connection, time_ns, data)`` as rosbags' ``Reader.messages`` does, in its order.

        By time; at equal times, by the order of ``connections`` (default all); then as indexed.
        """
        by_id = {c.id: c for c in self.connections}
        for batch in self.message_batches(connections, start, stop):
            chunk = batch.chunk
            for connection, time, begin, length in zip(
                    batch.connections.tolist(), batch.times.tolist(), batch.starts.tolist(),
                    batch.lengths.tolist()):
                yield by_id[connection], time, chunk[begin:begin + length]

    def message_batches(self, connections: Collection[Connection] = (),
                        start: Optional[int] = None, stop: Optional[int] = None
                        ) -> Generator['MessageBatch', None, None]:
        """
        Yield the messages of :meth:`messages`, in its order, in batches (:class:`MessageBatch`).

        A batch: the next plain message records of one chunk (:func:`plain_message_records`), or
        one message stored otherwise, read as rosbags reads it.
        """
        self._check_open()
        ranks: Dict[int, int] = {}
        for rank, connection in enumerate(connections or self.connections):
            ranks.setdefault(connection.id, rank)
        infos = self.chunk_infos
        groups = []
        for group in overlapping_chunk_groups(infos):
            if stop is not None and min(infos[i].start_time for i in group) >= stop:
                break
            if ((start is None or max(infos[i].end_time for i in group) > start)
                    and any(c in ranks for i in group for c in infos[i].connection_counts)):
                groups.append(group)
        ahead = _ChunksAhead(self)
        for number, group in enumerate(groups):
            # The first chunk of the next group is likely the one that starts first.
            following = (min(groups[number + 1], key=lambda i: infos[i].start_time)
                         if number + 1 < len(groups) else None)
            yield from self._group_batches(group, ranks, start, stop, ahead, following)

    def group_index(self, group: Sequence[int], ranks: Dict[int, int]) -> np.ndarray:
        """
        Return the index entries of the connections ``ranks`` in the chunks ``group``, as rosbags'.

        ``time`` (ns), ``connection``, ``chunk`` (into ``chunk_infos``), ``offset`` (in the chunk).
        """
        parts = [(i, connection, times, offsets) for i in group
                 for connection, times, offsets in self._chunk_index(i, ranks)]
        index = np.empty(sum(len(times) for _, _, times, _ in parts),
                         [('time', '<i8'), ('connection', '<i8'), ('chunk', '<i8'),
                          ('offset', '<i8')])
        rank = np.empty(len(index), np.int64)
        end = 0
        for i, connection, times, offsets in parts:
            part = slice(end, end + len(times))
            index['time'][part] = times
            index['connection'][part] = connection
            index['chunk'][part] = i
            index['offset'][part] = offsets
            rank[part] = ranks[connection]
            end = part.stop
        # rosbags: each connection's entries by time, merged by time, ties by connection rank
        return index[np.lexsort((np.arange(len(index)), rank, index['time']))]

    def _chunk_index(self, i, ranks):
        """Return ``(connection, times, offsets)`` of chunk ``i``'s index data in ``ranks``."""
        info = self.chunk_infos[i]
        chunk = self.chunks[info.pos]
        bio = self._file()
        records = []
        try:
            bio.seek(chunk.datapos + chunk.datasize)
            for _ in range(len(info.connection_counts)):
                header = Header.read(bio, RecordType.IDXDATA)
                version = header.get_uint32('ver')
                if version != 1:
                    raise ReaderError(f'IDXDATA version {version} is not supported.')
                connection, count = header.get_uint32('conn'), header.get_uint32('count')
                size = read_uint32(bio)
                expected = info.connection_counts.get(connection, 0)
                if size != count * INDEX_ENTRY.itemsize or count != expected:
                    raise ReaderError(f'connection {connection}: {count} entries in {size} '
                                      f'bytes, the chunk info counts {expected}.')
                if connection not in ranks:
                    bio.seek(size, os.SEEK_CUR)
                    continue
                entries = np.frombuffer(read_bytes(bio, size), INDEX_ENTRY)
                times = entries['sec'].astype(np.int64) * 10**9 + entries['nsec']
                # The groups' order relies on the chunk info's times.
                if count and (times.min() < info.start_time or times.max() >= info.end_time):
                    raise ReaderError(f'connection {connection}: a time outside the chunk '
                                      "info's time range.")
                records.append((connection, times, entries['offset']))
        except (ReaderError, UnicodeDecodeError) as error:
            raise ReaderError(f'The index data after the chunk at byte {info.pos} cannot be '
                              f'read: {error}') from None
        return records

    def _file(self) -> BinaryIO:
        """Return the bag's file, open."""
        if self.bio is None:
            raise ReaderError('Reader is not open.')
        return self.bio

    def stored_chunk(self, i: int) -> bytes:
        """Return chunk ``i`` as stored (compressed); ReaderError if it is cut short."""
        pos = self.chunk_infos[i].pos
        chunk = self.chunks[pos]
        bio = self._file()
        try:
            bio.seek(chunk.datapos)
            return read_bytes(bio, chunk.datasize)
        except ReaderError as error:
            raise ReaderError(f'The chunk at byte {pos} is cut short: {error}') from None

    def _group_batches(self, group, ranks, start, stop, ahead, following):
        """
        Yield the batches of one chunk group; ``following``: the chunk to decompress after it.

        Chunks are let go after their last message, and beyond ``CHUNK_BYTES_HELD`` (read again).
        """
        index = self.group_index(group, ranks)
        if start is not None:
            index = index[index['time'] >= start]
        if stop is not None:
            index = index[index['time'] < stop]
        chunk_of = index['chunk']
        chunks, counts = np.unique(chunk_of, return_counts=True)
        unread = dict(zip(chunks.tolist(), counts.tolist()))
        ahead.keep_only(unread)
        held: 'OrderedDict[int, Tuple[BytesIO, int]]' = OrderedDict()   # stream, size
        held_bytes = 0
        # Runs of entries in one chunk.
        edges = [0, *(np.flatnonzero(chunk_of[1:] != chunk_of[:-1]) + 1).tolist(), len(index)]
        runs = [(chunk_of[a].item(), a, b) for a, b in zip(edges, edges[1:]) if b > a]
        for number, (i, a, b) in enumerate(runs):
            if i in held:
                stream = held[i][0]
                held.move_to_end(i)
            else:
                chunk = ahead.take(i)
                held[i] = stream, size = BytesIO(chunk), len(chunk)
                held_bytes += size
                while held_bytes > CHUNK_BYTES_HELD and len(held) > 1:
                    held_bytes -= held.popitem(last=False)[1][1]
            later = next((j for j, _, _ in runs[number + 1:] if j not in held), following)
            if later is not None:
                ahead.start(later)
            yield from self._run_batches(i, stream, index[a:b])
            unread[i] -= b - a
            if not unread[i]:   # its last message: let the chunk go
                held_bytes -= held.pop(i)[1]
            del stream

    def _run_batches(self, i, stream, entries):
        """Yield the batches of index ``entries`` of chunk ``i`` (held by ``stream``)."""
        chunk = stream.getvalue()   # the chunk's bytes themselves, not a copy
        connections, times, offsets = entries['connection'], entries['time'], entries['offset']
        plain, starts, lengths = plain_message_records(chunk, offsets, connections, times)
        done = 0
        for k in [*np.flatnonzero(~plain).tolist(), len(entries)]:   # runs of plain records
            if k > done:
                part = slice(done, k)
                yield MessageBatch(connections[part], times[part], chunk, starts[part],
                                   lengths[part])
            if k == len(entries):
                return
            offset, connection, time = offsets[k].item(), connections[k].item(), times[k].item()
            data = message_data(chunk, offset, connection, time)
            if data is None:   # anything but a plain message record: rosbags' reading
                stream.seek(offset)
                try:
                    header, data = _message_record(stream)
                    if (header.get_uint32('conn') != connection
                            or header.get_time('time') != time):
                        raise ReaderError('it is not the message its index names.')
                except (ReaderError, UnicodeDecodeError) as error:
                    raise ReaderError(f'The message at offset {offset} of the chunk at byte '
                                      f'{self.chunk_infos[i].pos} cannot be read: '
                                      f'{error}') from None
            part = slice(k, k + 1)
            yield MessageBatch(connections[part], times[part], data, _ZERO_START,
                               np.array([len(data)], np.int64))
            done = k + 1


class MessageBatch(NamedTuple):
    """
    Messages read together: message ``k`` is ``chunk[starts[k]:starts[k] + lengths[k]]``.

    ``connections`` (ids), ``times`` (ns), ``starts`` and ``lengths``: int64, in reading order.
    """

    connections: np.ndarray
    times: np.ndarray
    chunk: bytes
    starts: np.ndarray
    lengths: np.ndarray


_ZERO_START = np.zeros(1, np.int64)
_NO_DECOMPRESSION = ros1_decompressors['none']


def _decompressed(reader: ChunkedReader, i: int, data: bytes) -> bytes:
    """Return chunk ``i``'s stored ``data`` decompressed; ReaderError if it cannot be."""
    try:
        return reader.chunks[reader.chunk_infos[i].pos].decompressor(data)
    except _DECOMPRESSION_ERRORS as error:
        raise ReaderError(f'The chunk at byte {reader.chunk_infos[i].pos} cannot be '
                          f'decompressed: {error}') from None


class _ChunksAhead:
    """At most one chunk decompressed ahead, in a thread (bz2, lz4 free the GIL)."""

    def __init__(self, reader: ChunkedReader) -> None:
        self._reader = reader
        #: The chunk read ahead, its thread (None if reading it failed) and its outcome.
        self._ahead: Optional[Tuple[int, Optional[threading.Thread], dict]] = None

    def start(self, i: int) -> None:
        """Start decompressing chunk ``i`` unless a chunk is being decompressed already."""
        reader = self._reader
        if (self._ahead is not None
                or reader.chunks[reader.chunk_infos[i].pos].decompressor is _NO_DECOMPRESSION):
            return
        outcome: dict = {}
        try:   # read here: the file is not shared with the thread
            stored = reader.stored_chunk(i)
        except ReaderError as error:   # raised where the chunk is used
            self._ahead = i, None, {'error': error}
            return

        def decompress() -> None:
            try:
                outcome['chunk'] = _decompressed(reader, i, stored)
            except BaseException as error:   # noqa: B902  (raised where the chunk is used)
                outcome['error'] = error

        thread = threading.Thread(target=decompress, name=f'ROS 1 chunk {i}', daemon=True)
        thread.start()
        self._ahead = i, thread, outcome

    def take(self, i: int) -> bytes:
        """Return chunk ``i`` decompressed: the one read ahead, or read now."""
        if self._ahead is None or self._ahead[0] != i:
            return _decompressed(self._reader, i, self._reader.stored_chunk(i))
        _, thread, outcome = self._ahead
        self._ahead = None
        if thread is not None:
            thread.join()
        if 'error' in outcome:
            raise outcome['error']
        return outcome['chunk']

    def keep_only(self, needed: Collection[int]) -> None:
        """Forget the chunk read ahead unless it is ``needed`` (its thread ends by itself)."""
        if self._ahead is not None and self._ahead[0] not in needed:
            self._ahead = None


def _unwrapped(reason: object) -> object:
    """Return rosbags' ``Bag index looks damaged: ('...',)`` without the tuple around it."""
    prefix = 'Bag index looks damaged: '
    text = str(reason)
    if text.startswith(prefix):
        try:
            inner = ast.literal_eval(text[len(prefix):])
        except (ValueError, SyntaxError):   # not the tuple rosbags writes: as it is
            return reason
        if isinstance(inner, tuple):
            return prefix + ' '.join(map(str, inner))
    return reason


_UINT32 = struct.Struct('<I')
_TIME = struct.Struct('<II')
_MESSAGE_DATA_OP = bytes([RecordType.MSGDATA])


def plain_record_layout(chunk: bytes, offset: int) -> Optional[Tuple[int, int, int]]:
    """
    Return ``(header length, conn offset, time offset)`` of a plain message record, else None.

    Plain: exactly the header fields ``op`` (message data), ``conn`` and ``time``, in the chunk.
    """
    unpack = _UINT32.unpack_from
    try:
        header_length, = unpack(chunk, offset)
        position, end = offset + 4, offset + 4 + header_length
        fields = {}
        while position < end:
            size, = unpack(chunk, position)
            position += 4
            field_end = position + size
            separator = chunk.find(b'=', position, field_end)
            if field_end > end or separator < 0:
                return None
            fields[chunk[position:separator]] = (separator + 1, field_end)
            position = field_end
        if len(fields) != 3 or fields.keys() != {b'op', b'conn', b'time'}:
            return None
        (op, op_end), (conn, conn_end), (time, time_end) = (
            fields[b'op'], fields[b'conn'], fields[b'time'])
        if (chunk[op:op_end] != _MESSAGE_DATA_OP or conn_end - conn < 4
                or time_end - time != 8 or len(chunk) < end + 4):
            return None
    except struct.error:
        return None
    return header_length, conn - offset, time - offset


def message_data(chunk: bytes, offset: int, connection: int, time: int) -> Optional[bytes]:
    """
    Return the data of the plain message record of ``connection`` and ``time`` at ``offset``.

    None for anything else (a connection record before it, a damaged length...): rosbags reads it.
    """
    layout = plain_record_layout(chunk, offset)
    if layout is None:
        return None
    header_length, conn, time_at = layout
    sec, nsec = _TIME.unpack_from(chunk, offset + time_at)
    if _UINT32.unpack_from(chunk, offset + conn)[0] != connection or sec * 10**9 + nsec != time:
        return None
    end = offset + 4 + header_length
    length, = _UINT32.unpack_from(chunk, end)
    data = chunk[end + 4:end + 4 + length]
    return data if len(data) == length else None


#: Plain record layouts tried on a chunk's messages before the rest are read one by one.
_RECORD_LAYOUTS_TRIED = 8


def plain_message_records(chunk: bytes, offsets: np.ndarray, connections: np.ndarray,
                          times: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Find what :func:`message_data` finds for many index entries of a chunk at once.

    Returns ``(plain, starts, lengths)`` (0 where not plain): records laid out as one before them
    are found by comparing their bytes but ``conn``, ``time`` and the data length.
    """
    n = len(offsets)
    plain = np.zeros(n, bool)
    starts = np.zeros(n, np.int64)
    lengths = np.zeros(n, np.int64)
    buffer = np.frombuffer(chunk, np.uint8)
    pending = np.arange(n)
    seed = 0   # the place in ``pending`` of the record whose layout is tried next
    tried = 0
    while seed < len(pending) and tried < _RECORD_LAYOUTS_TRIED:
        first = pending[seed].item()
        at_seed = offsets[first].item()
        layout = plain_record_layout(chunk, at_seed)
        if layout is None:   # left to message_data
            seed += 1
            continue
        tried += 1
        header_length, conn, time_at = layout
        size = 4 + header_length + 4   # through the data's length
        at = offsets[pending]
        fits = at <= len(chunk) - size
        rows = buffer[np.where(fits, at, at_seed)[:, None] + np.arange(size)]
        compared = np.ones(size, bool)
        compared[conn:conn + 4] = compared[time_at:time_at + 8] = compared[-4:] = False
        # conn, time (sec, nsec) in the order they are stored, then the data's length
        values = rows[:, ~compared].copy().view('<u4')
        conn_column, sec_column = (0, 1) if conn < time_at else (2, 0)
        begin = at + size
        length = values[:, 3].astype(np.int64)
        found = (fits & (rows[:, compared] == buffer[at_seed:at_seed + size][compared]).all(axis=1)
                 & (values[:, conn_column] == connections[pending])
                 & (values[:, sec_column].astype(np.int64) * 10**9 + values[:, sec_column + 1]
                    == times[pending])
                 & (begin + length <= len(chunk)))
        which = pending[found]
        plain[which], starts[which], lengths[which] = True, begin[found], length[found]
        pending = pending[~found]
        # The seed itself stays when it is not its index entry's message.
        seed = int(np.searchsorted(pending, first)) + (not found[seed])
    return plain, starts, lengths


def _message_record(stream):
    """Return the header and data of the message data record at the stream's position."""
    while True:   # connection records may stand before the message data
        header = Header.read(stream)
        op = header.get_uint8('op')
        if op != RecordType.CONNECTION:
            break
        stream.seek(read_uint32(stream), os.SEEK_CUR)
    if op != RecordType.MSGDATA:
        raise ReaderError('Expected to find message data.')
    return header, read_bytes(stream, read_uint32(stream))
