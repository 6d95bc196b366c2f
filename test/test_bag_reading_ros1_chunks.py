"""
Tests of rotation_node.bag.reading.ros1_chunks: ROS 1 bags read one chunk group at a time.

The bags are written by the rosbags ROS 1 writer with small chunks; rosbags'
own reader (which indexes every message when it opens the bag) is the oracle:
the same messages, bytes and order, also where chunks overlap in time and
where timestamps are equal across chunks.
"""
from io import BytesIO
import os
import struct
import weakref

import numpy as np
import pytest
from rosbags.rosbag1 import Reader, Writer
from rosbags.rosbag1.reader import ChunkInfo
from rosbags.typesys import get_typestore, Stores
from rotation_node.bag.reading import ros1_chunks
from rotation_node.bag.reading.ros1_chunks import ChunkedReader, overlapping_chunk_groups

TOPICS = ('/a', '/b', '/c')


def _write_bag(path, rows, chunk_bytes=2000, compression=None):
    """Write ``(topic index, time ns, data)`` rows in their order; chunks of ~``chunk_bytes``."""
    store = get_typestore(Stores.ROS1_NOETIC)
    writer = Writer(path)
    writer.chunk_threshold = chunk_bytes
    if compression is not None:
        writer.set_compression(compression)
    with writer:
        connections = [writer.add_connection(topic, 'std_msgs/msg/String', typestore=store)
                       for topic in TOPICS]
        for topic, time_ns, data in rows:
            writer.write(connections[topic], time_ns, data)
    return path


def _string_rows(rng, times):
    """Rows on random topics at ``times``, each a std_msgs/String of random length."""
    rows = []
    for k, time_ns in enumerate(times):
        text = f'{k}:'.encode() + bytes(rng.integers(97, 123, rng.integers(0, 60)).tolist())
        rows.append((int(rng.integers(len(TOPICS))), int(time_ns),
                     len(text).to_bytes(4, 'little') + text))
    return rows


def _read(reader_class, path, topics=None, **window):
    """Return ``(connection id, time, data)`` of every message read, the reader's connections."""
    with reader_class(path) as reader:
        connections = reader.connections if topics is None else [
            next(c for c in reader.connections if c.topic == topic) for topic in topics]
        messages = [(c.id, time_ns, data)
                    for c, time_ns, data in reader.messages(connections, **window)]
        return messages, [(c.id, c.topic, c.msgcount) for c in reader.connections]


def _assert_read_as_rosbags_reads(path, topics=None, **window):
    expected, expected_connections = _read(Reader, path, topics, **window)
    messages, connections = _read(ChunkedReader, path, topics, **window)
    assert connections == expected_connections
    assert messages == expected and all(isinstance(m[2], bytes) for m in messages)
    return messages


@pytest.mark.parametrize('compression', [None, Writer.CompressionFormat.BZ2,
                                         Writer.CompressionFormat.LZ4])
def test_a_recording_in_time_order_is_read_as_rosbags_reads_it(tmp_path, rng, compression):
    rows = _string_rows(rng, 1_600_000_000 * 10**9 + np.arange(600) * 10_000_000)
    path = _write_bag(tmp_path / 'recording.bag', rows, compression=compression)
    messages = _assert_read_as_rosbags_reads(path)
    assert [m[1:] for m in messages] == [row[1:] for row in rows]
    with ChunkedReader(path) as reader:
        assert len(reader.chunk_infos) > 10   # one chunk per group
        assert overlapping_chunk_groups(reader.chunk_infos) == [
            [i] for i in range(len(reader.chunk_infos))]


def test_chunks_overlapping_in_time_are_read_in_rosbags_order(tmp_path, rng):
    """Out-of-order times on three connections: every subset, order and window as rosbags."""
    times = np.concatenate([1_000_000 + rng.integers(0, 3000, 300) * 1000,
                            5_000_000 + np.arange(100),   # a stretch recorded in order
                            6_000_000 + rng.integers(0, 3000, 400) * 1000])
    path = _write_bag(tmp_path / 'shuffled.bag', _string_rows(rng, times), chunk_bytes=900)
    with ChunkedReader(path) as reader:
        groups = overlapping_chunk_groups(reader.chunk_infos)
        assert len(groups) > 3 and max(len(g) for g in groups) > 1
    messages = _assert_read_as_rosbags_reads(path)
    assert len(messages) == 800
    _assert_read_as_rosbags_reads(path, ['/c', '/a'])
    _assert_read_as_rosbags_reads(path, ['/b'])
    _assert_read_as_rosbags_reads(path, start=1_500_000, stop=2_500_000)
    _assert_read_as_rosbags_reads(path, ['/a', '/c'], start=5_000_050, stop=7_000_000)


def test_equal_times_across_chunks_keep_rosbags_order(tmp_path, rng):
    """Ties are broken by the connection asked for first, then by the chunks' order."""
    times = np.repeat(10**9 + np.arange(4), 150)
    path = _write_bag(tmp_path / 'ties.bag', _string_rows(rng, times), chunk_bytes=700)
    with ChunkedReader(path) as reader:
        assert [len(g) for g in overlapping_chunk_groups(reader.chunk_infos)] == [
            len(reader.chunk_infos)]   # every chunk shares a time with the next
    for topics in (None, ['/b', '/a', '/c'], ['/c', '/b']):
        messages = _assert_read_as_rosbags_reads(path, topics)
        assert len({m[1] for m in messages}) == 4


class _ChunkStreams:
    """The decompressed chunks the reader holds, counted through the streams that wrap them."""

    def __init__(self, monkeypatch):
        self.alive, self.created = weakref.WeakSet(), 0
        streams = self

        class Counted(BytesIO):
            def __init__(self, data=b''):
                super().__init__(data)
                if data:
                    streams.alive.add(self)
                    streams.created += 1

        monkeypatch.setattr(ros1_chunks, 'BytesIO', Counted)


def test_only_one_chunk_group_is_indexed_at_a_time(tmp_path, rng, monkeypatch):
    """No per-message index at open; the largest index held is the largest chunk's."""
    rows = _string_rows(rng, 10**12 + np.arange(3000) * 1000)
    path = _write_bag(tmp_path / 'long.bag', rows, chunk_bytes=1500)
    streams = _ChunkStreams(monkeypatch)
    sizes = []
    group_index = ChunkedReader.group_index

    def counted(self, group, ranks):
        index = group_index(self, group, ranks)
        sizes.append(len(index))
        return index

    monkeypatch.setattr(ChunkedReader, 'group_index', counted)
    with ChunkedReader(path) as reader:
        assert reader.indexes == {}
        chunk_sizes = [sum(info.connection_counts.values()) for info in reader.chunk_infos]
        assert len(chunk_sizes) > 50 and sum(c.msgcount for c in reader.connections) == 3000
        read = 0
        for _ in reader.messages():
            read += 1
            assert reader.indexes == {} and sum(sizes) - sizes[-1] < read <= sum(sizes)
            assert len(streams.alive) <= 1
    assert sizes == chunk_sizes and streams.created == len(chunk_sizes)


@pytest.mark.parametrize('bytes_held', [ros1_chunks.CHUNK_BYTES_HELD, 3000, 1])
def test_overlapping_chunks_are_held_within_the_bound(tmp_path, rng, monkeypatch, bytes_held):
    """Every chunk overlaps: at most CHUNK_BYTES_HELD (and the one read) held, same messages."""
    path = _write_bag(tmp_path / 'scrambled.bag',
                      _string_rows(rng, rng.integers(0, 10**6, 1000)), chunk_bytes=1000)
    monkeypatch.setattr(ros1_chunks, 'CHUNK_BYTES_HELD', bytes_held)
    streams = _ChunkStreams(monkeypatch)
    with ChunkedReader(path) as reader:
        chunks = len(reader.chunk_infos)
        assert overlapping_chunk_groups(reader.chunk_infos) == [list(range(chunks))]
        most = 0
        for _ in reader.messages():
            most = max(most, len(streams.alive))
            assert sum(len(s.getvalue()) for s in streams.alive) <= bytes_held + 2000
    if bytes_held > 10**6:
        assert (most, streams.created) == (chunks, chunks)   # all held, each decompressed once
    else:
        assert most <= bytes_held // 1000 + 1 and streams.created > chunks
    _assert_read_as_rosbags_reads(path)


def test_overlapping_chunk_groups_merge_time_ranges():
    def info(start, last):   # as rosbags reads it: end_time one after the last message
        return ChunkInfo(0, start, last + 1, {0: 1})

    empty = ChunkInfo(0, 2**63 - 1, 0, {})
    assert overlapping_chunk_groups([]) == []
    assert overlapping_chunk_groups([info(0, 9), info(10, 19), empty, info(20, 29)]) == [
        [0], [1], [3]]
    assert overlapping_chunk_groups([info(0, 10), info(10, 19)]) == [[0, 1]]
    # A long chunk swallows those within its range; groups come in time order.
    assert overlapping_chunk_groups([info(50, 60), info(0, 100), info(10, 20), info(30, 40),
                                     info(101, 101), info(95, 99)]) == [[0, 1, 2, 3, 5], [4]]
    assert overlapping_chunk_groups([info(200, 300), info(0, 10), info(100, 150)]) == [
        [1], [2], [0]]


def _record(fields, data):
    header = b''.join(struct.pack('<I', len(name) + 1 + len(value)) + name + b'=' + value
                      for name, value in fields)
    return struct.pack('<I', len(header)) + header + struct.pack('<I', len(data)) + data


MESSAGE_FIELDS = [(b'op', b'\x02'), (b'conn', struct.pack('<I', 3)),
                  (b'time', struct.pack('<II', 5, 7))]


@pytest.mark.parametrize('fields', [MESSAGE_FIELDS, MESSAGE_FIELDS[::-1]])
def test_message_data_of_a_plain_message_record(fields):
    chunk = b'xx' + _record(fields, b'payload') + b'rest'
    assert ros1_chunks.message_data(chunk, 2, 3, 5 * 10**9 + 7) == b'payload'


@pytest.mark.parametrize('chunk, connection, time', [
    (_record(MESSAGE_FIELDS, b'payload'), 4, 5 * 10**9 + 7),               # another connection
    (_record(MESSAGE_FIELDS, b'payload'), 3, 5 * 10**9 + 8),               # another time
    (_record(MESSAGE_FIELDS, b'payload')[:-1], 3, 5 * 10**9 + 7),          # cut short
    (_record(MESSAGE_FIELDS, b'')[:-2], 3, 5 * 10**9 + 7),                 # length cut
    (_record([(b'op', b'\x07')] + MESSAGE_FIELDS[1:], b''), 3, 5 * 10**9 + 7),   # connection
    (_record(MESSAGE_FIELDS + [(b'\xff', b'')], b''), 3, 5 * 10**9 + 7),   # another field
    (_record([(b'op', b'\x02\x00')] + MESSAGE_FIELDS[1:], b''), 3, 5 * 10**9 + 7),
    (b'\xff\x00\x00\x00', 3, 5 * 10**9 + 7),                               # header too long
])
def test_anything_else_is_left_to_rosbags(chunk, connection, time):
    assert ros1_chunks.message_data(chunk, 0, connection, time) is None


def _connection_record(connection):
    fields = [(b'op', b'\x07'), (b'conn', struct.pack('<I', connection)), (b'topic', b'/a')]
    return _record(fields, b'\x04\x00\x00\x00type')


def test_plain_message_records_find_what_message_data_finds(rng):
    """All at once, each record as message_data reads it alone; anything else is left to it."""
    records, entries = [], []
    position = 0
    for k in range(200):
        time = (5 + k) * 10**9 + 7
        fields = [(b'op', b'\x02'), (b'conn', struct.pack('<I', k % 3)),
                  (b'time', struct.pack('<II', 5 + k, 7))]
        kind = rng.integers(12)
        connection = k % 3
        if kind == 0:
            fields = fields[::-1]                        # another order: another layout
        elif kind == 1:
            fields = fields + [(b'x', b'')]              # another field
        elif kind == 2:
            connection += 1                              # not the index's connection
        elif kind == 3:
            time += 1                                    # not the index's time
        elif kind == 4:
            records.append(_connection_record(k % 3))   # a connection record before it
        data = bytes(rng.integers(0, 256, rng.integers(0, 40)).tolist())
        record = _record(fields, data)
        if kind == 5:   # a data length past the chunk's end
            record = record[:-len(data) - 4] + struct.pack('<I', 10**6) + data
        entries.append((position, connection, time))
        records.append(record)
        position = sum(len(r) for r in records)
    chunk = b''.join(records) + b'\x00\x00\x00\xff'
    entries.append((len(chunk) - 4, 0, 0))               # a header running past the chunk
    offsets, connections, times = (np.array(column, np.int64) for column in zip(*entries))
    plain, starts, lengths = ros1_chunks.plain_message_records(chunk, offsets, connections, times)
    found = [chunk[s:s + n] if p else None for p, s, n in zip(plain, starts, lengths)]
    assert found == [ros1_chunks.message_data(chunk, *entry) for entry in entries]
    assert 100 < plain.sum() < len(entries) - 50


def _count_decompressions(monkeypatch):
    """Return the list the chunk indices decompressed are appended to (in any thread)."""
    decompressed = []
    real = ros1_chunks._decompressed

    def counted(reader, i, data):
        decompressed.append(i)
        return real(reader, i, data)

    monkeypatch.setattr(ros1_chunks, '_decompressed', counted)
    return decompressed


def test_the_next_chunk_is_decompressed_ahead_and_no_further(tmp_path, rng, monkeypatch):
    rows = _string_rows(rng, 10**12 + np.arange(1500) * 1000)
    path = _write_bag(tmp_path / 'bz2.bag', rows, chunk_bytes=1500,
                      compression=Writer.CompressionFormat.BZ2)
    decompressed = _count_decompressions(monkeypatch)
    with ChunkedReader(path) as reader:
        chunks = len(reader.chunk_infos)
        positions = {info.pos: i for i, info in enumerate(reader.chunk_infos)}
        assert chunks > 20
        read = []
        for batch in reader.message_batches():
            i = next(k for k, info in enumerate(reader.chunk_infos)
                     if info.start_time <= batch.times[0] < info.end_time)
            read.append(i)
            assert decompressed[:len(read)] == read and len(decompressed) <= len(read) + 1
        assert read == list(range(chunks)) and sorted(decompressed) == read
        assert len(positions) == chunks


def test_a_chunk_decompressed_ahead_fails_where_it_is_reached(tmp_path, rng):
    rows = _string_rows(rng, 10**12 + np.arange(600) * 1000)
    path = _write_bag(tmp_path / 'bz2.bag', rows, compression=Writer.CompressionFormat.BZ2)
    with ChunkedReader(path) as reader:
        damaged = reader.chunks[reader.chunk_infos[3].pos]
        before = sum(sum(info.connection_counts.values()) for info in reader.chunk_infos[:3])
    data = bytearray(path.read_bytes())
    data[damaged.datapos + 20:damaged.datapos + 40] = b'\xff' * 20
    path.write_bytes(bytes(data))
    read = 0
    with ChunkedReader(path) as reader:
        with pytest.raises(ros1_chunks.ReaderError,
                           match=f'The chunk at byte {reader.chunk_infos[3].pos} cannot be '
                                 'decompressed'):
            for _ in reader.messages():
                read += 1
    assert read == before


def test_a_chunk_read_ahead_that_is_cut_short_fails_where_it_is_reached(tmp_path, rng):
    """The file is cut inside chunk 3 after the bag was opened: chunks 0 to 2 are read whole."""
    rows = _string_rows(rng, 10**12 + np.arange(600) * 1000)
    path = _write_bag(tmp_path / 'bz2.bag', rows, compression=Writer.CompressionFormat.BZ2)
    read = 0
    with ChunkedReader(path) as reader:
        chunk = reader.chunks[reader.chunk_infos[3].pos]
        before = sum(sum(info.connection_counts.values()) for info in reader.chunk_infos[:3])
        os.truncate(path, chunk.datapos + 10)
        # (its index, after the chunk's data, is read first)
        with pytest.raises(ros1_chunks.ReaderError,
                           match=f'after the chunk at byte {reader.chunk_infos[3].pos} cannot'):
            for _ in reader.messages():
                read += 1
    assert read == before
