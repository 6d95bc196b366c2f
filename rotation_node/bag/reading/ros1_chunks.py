"""
ROS 1 bags read one chunk at a time, in the order of rosbags' reader.

rosbags' ROS 1 reader (:class:`rosbags.rosbag1.reader.Reader`) reads, when it
opens a bag, the index data records of every chunk into one Python tuple per
message: its memory grows with the bag's length. :class:`ChunkedReader` opens
the bag with the same code but keeps only what does not grow with the number
of messages: the bag header, the connection records, the chunk info records
(their per-connection message counts give each connection's count) and the
chunk records' headers (position, size, compression). A chunk's index data
records, which follow the chunk in the file, are read (as numpy arrays) when
the messages reach the chunk, and the chunk is decompressed then.

Chunks whose time ranges overlap are read together, as one group
(:func:`overlapping_chunk_groups`): a recording whose chunks follow each other
in time holds one chunk at a time; a bag whose chunks all overlap holds them
all, as rosbags does. The messages come in the order of rosbags'
``Reader.messages``: by time; at equal times by the place of their connection
in the ``connections`` asked for; then in the order rosbags indexes them
(chunk info records in file order, index entries in record order). A
damaged bag raises :class:`rosbags.rosbag1.ReaderError` when the damage is
reached, naming the byte where it is; whatever a damaged length field says, a
read never asks for more than the file holds (:class:`BoundedReads`).
"""
import ast
from collections import Counter, OrderedDict
import io
from io import BytesIO
import os
from pathlib import Path
import struct
from typing import BinaryIO, Collection, Dict, Generator, List, Optional, Sequence, Tuple

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection
from rosbags.rosbag1 import ReaderError
from rosbags.rosbag1.reader import ChunkInfo, Header, read_bytes, read_uint32, Reader, RecordType
from rosbags.typesys import get_typestore, Stores

#: One entry of an index data record (version 1): the message's time and its offset in the chunk.
INDEX_ENTRY = np.dtype([('sec', '<u4'), ('nsec', '<u4'), ('offset', '<u4')])
#: What ``messages`` yields: the connection, the time (ns) and the message's ROS 1 data.
Message = Tuple[Connection, int, bytes]
#: At most this many bytes of decompressed chunks are held while the messages of overlapping
#: chunks are read (besides the chunk being read); a chunk let go is decompressed again if needed.
CHUNK_BYTES_HELD = 64 * 2**20
# What the chunk decompressors (bz2, lz4) raise for data they cannot decompress.
_DECOMPRESSION_ERRORS = (OSError, ValueError, EOFError, RuntimeError)


class BoundedReads(io.BufferedReader):
    """
    A file whose reads never ask for more bytes than remain in it.

    rosbags reads a record as ``read(length)`` with the record's own length
    field: a damaged length (up to 4 GiB) would allocate that much before the
    short read is noticed. Here it gets the rest of the file, and rosbags
    reports the short read. ``read_at`` is where the last read started (for
    the error line), also once the file is closed.
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
        """
        Move to a position in the file, never past its end.

        Raises
        ------
        rosbags.rosbag1.ReaderError
            If the position (a damaged record position or size) is outside the file.

        """
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
    Return the chunks that must be read together: those whose time ranges overlap.

    Parameters
    ----------
    chunk_infos : sequence of rosbags.rosbag1.reader.ChunkInfo
        As rosbags reads them: ``end_time`` one nanosecond after the chunk's
        last message; a chunk without messages is left out.

    Returns
    -------
    list of list of int
        Indices into ``chunk_infos``: the groups in time order (every message
        of a group is earlier than every message of the next), each group in
        the order of ``chunk_infos``.

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

    Its ``indexes`` stay empty; each connection's ``msgcount`` is the sum of
    the chunk infos' counts. ``messages`` yields what rosbags' ``messages``
    yields, in the same order.
    """

    def open(self) -> None:  # noqa: A003  (rosbags names it so)
        """
        Open the bag and read its header, connections, chunk infos and chunk headers.

        Raises
        ------
        rosbags.rosbag1.ReaderError
            If they are damaged, naming the byte where the read that failed started.

        """
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
                 stop: Optional[int] = None) -> Generator[Message, None, None]:
        """
        Yield ``(connection, time_ns, data)`` in the order of rosbags' ``Reader.messages``.

        Parameters
        ----------
        connections : collection of rosbags.interfaces.Connection, optional
            Those to read (default: all), their order deciding between
            messages of equal times.
        start, stop : int, optional
            Only messages at or after ``start`` and before ``stop`` (ns).

        Raises
        ------
        rosbags.rosbag1.ReaderError
            If the bag is not open or its data are damaged.

        """
        self._check_open()
        ranks: Dict[int, int] = {}
        for rank, connection in enumerate(connections or self.connections):
            ranks.setdefault(connection.id, rank)
        infos = self.chunk_infos
        by_id = {c.id: c for c in self.connections}
        for group in overlapping_chunk_groups(infos):
            if stop is not None and min(infos[i].start_time for i in group) >= stop:
                return
            if ((start is None or max(infos[i].end_time for i in group) > start)
                    and any(c in ranks for i in group for c in infos[i].connection_counts)):
                yield from self._group_messages(group, ranks, by_id, start, stop)

    def group_index(self, group: Sequence[int], ranks: Dict[int, int]) -> np.ndarray:
        """
        Return the index entries of the connections ``ranks`` in the chunks ``group``, in order.

        Parameters
        ----------
        group : sequence of int
            Indices into ``chunk_infos``, in increasing order.
        ranks : dict of int to int
            The place of each connection (by id) in the order asked for.

        Returns
        -------
        numpy.ndarray
            Structured: ``time`` (ns), ``connection`` (id), ``chunk`` (index
            into ``chunk_infos``), ``offset`` (in the decompressed chunk),
            sorted as rosbags sorts its index.

        Raises
        ------
        rosbags.rosbag1.ReaderError
            If an index data record is damaged or has a time outside the time
            range of its chunk info.

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
        # rosbags: each connection's entries stably sorted by time, then merged by time
        # with ties going to the connection asked for first.
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

    def decompressed_chunk(self, i: int) -> bytes:
        """
        Return the decompressed data of chunk ``i`` (an index into ``chunk_infos``).

        Raises
        ------
        rosbags.rosbag1.ReaderError
            If the chunk is cut short or cannot be decompressed.

        """
        pos = self.chunk_infos[i].pos
        chunk = self.chunks[pos]
        bio = self._file()
        try:
            bio.seek(chunk.datapos)
            data = read_bytes(bio, chunk.datasize)
        except ReaderError as error:
            raise ReaderError(f'The chunk at byte {pos} is cut short: {error}') from None
        try:
            return chunk.decompressor(data)
        except _DECOMPRESSION_ERRORS as error:
            raise ReaderError(f'The chunk at byte {pos} cannot be decompressed: '
                              f'{error}') from None

    def _group_messages(self, group, ranks, by_id, start, stop):
        """
        Yield the messages of one chunk group (``by_id``: the connections by id).

        A chunk is freed after its last message, and the least recently read
        ones when more than ``CHUNK_BYTES_HELD`` are held (read again if
        needed).
        """
        index = self.group_index(group, ranks)
        if start is not None:
            index = index[index['time'] >= start]
        if stop is not None:
            index = index[index['time'] < stop]
        chunks, counts = np.unique(index['chunk'], return_counts=True)
        unread = dict(zip(chunks.tolist(), counts.tolist()))
        held: 'OrderedDict[int, Tuple[BytesIO, int]]' = OrderedDict()   # stream, size
        held_bytes, current, stream, chunk = 0, -1, BytesIO(), b''
        for time, connection, i, offset in zip(*(index[name].tolist() for name in (
                'time', 'connection', 'chunk', 'offset'))):
            if i != current:
                current = i
                if i in held:
                    stream = held[i][0]
                    held.move_to_end(i)
                else:
                    chunk = self.decompressed_chunk(i)
                    held[i] = stream, size = BytesIO(chunk), len(chunk)
                    held_bytes += size
                    while held_bytes > CHUNK_BYTES_HELD and len(held) > 1:
                        held_bytes -= held.popitem(last=False)[1][1]
                chunk = stream.getvalue()   # the chunk's bytes themselves, not a copy
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
            unread[i] -= 1
            if not unread[i]:   # its last message: let the chunk go
                held_bytes -= held.pop(i)[1]
                current, stream, chunk = -1, BytesIO(), b''
            yield by_id[connection], time, data


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


def message_data(chunk: bytes, offset: int, connection: int, time: int) -> Optional[bytes]:
    """
    Return the data of the message record at ``offset`` of a chunk, or None to read it as rosbags.

    The fast path of :func:`_message_record` and the index check after it:
    the data of a message data record whose header holds exactly ``op``,
    ``conn`` and ``time`` (in any order), of the connection and time its index
    entry gives, with nothing cut short. Anything else (a connection record
    before it, another field, a damaged length, another connection or time)
    gives None: rosbags' reading then says what it is, as it did.
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
            fields[chunk[position:separator]] = chunk[separator + 1:field_end]
            position = field_end
        if (len(fields) != 3 or fields.get(b'op') != _MESSAGE_DATA_OP
                or len(fields.get(b'conn', b'')) < 4 or len(fields.get(b'time', b'')) != 8):
            return None
        sec, nsec = _TIME.unpack(fields[b'time'])
        if unpack(fields[b'conn'])[0] != connection or sec * 10**9 + nsec != time:
            return None
        length, = unpack(chunk, end)
    except struct.error:
        return None
    data = chunk[end + 4:end + 4 + length]
    return data if len(data) == length else None


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


class ChunkedAnyReader(AnyReader):
    """
    rosbags' ``AnyReader`` over one ROS 1 bag read by :class:`ChunkedReader`.

    ``AnyReader`` builds the bag's types from the definitions stored in it
    (``typestore``) and checks their MD5 sums; its own constructor would pick
    the reader by the file name's suffix, this one is a ROS 1 bag whatever
    its name.

    Parameters
    ----------
    path : pathlib.Path
        A ROS 1 bag, format version 2.0.

    """

    def __init__(self, path: Path) -> None:
        # What AnyReader.__init__ sets, for one ROS 1 bag.
        self.paths = [path]
        self.is2 = False
        self.stack = None
        self.connections = []
        self.default_typestore = None
        self.typestore = get_typestore(Stores.EMPTY)
        self.readers = [ChunkedReader(path)]
