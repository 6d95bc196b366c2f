"""
Tests of rotation_node.bag.reading.mcap_reader on every layout MCAP allows, and on damage.

The MCAP project's conformance suite (foxglove/mcap, ``tests/conformance``)
varies the optional parts of a file: chunks, message indexes, chunk indexes,
statistics, Schema and Channel records repeated in the summary, summary
offsets, attachment and metadata indexes, padded records. Here the independent
``mcap`` writer writes every combination of the options it has for them (with
zstd, lz4 and uncompressed chunks, and without chunks; padding is added to the
records afterwards), and the reader must return exactly the messages written
(topic, log time, publish time, bytes, in log-time order), count them honestly
(also without statistics) and add no note.

Then damage, as a power loss or a bad disk leaves it: zeroed bytes inside a
chunk, length fields set past the end of the file, swapped chunks. What can be
read is read; the rest is said on one note line with how many messages of
which topics were lost and where (an error with ``strict``); memory stays
bounded whatever a length says (checked in a forked child under an
address-space limit).
"""
import io
import itertools
import os
import pickle
import resource
import struct

from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer
import numpy as np
import pytest
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.reading.reader import open_bag
from rotation_node.errors import BagError

CHUNKINGS = ['unchunked', 'none', 'lz4', 'zstd']
INDEXES = {
    'chx': IndexType.CHUNK, 'mx': IndexType.MESSAGE,
    'ax+mdx': IndexType.ATTACHMENT | IndexType.METADATA,
}
SUMMARY_OPTIONS = ['repeat_channels', 'repeat_schemas', 'use_statistics', 'use_summary_offsets']
TOPICS = ['/a', '/b', '/late', '/raw']


def _rows(rng, count, *, overlapping=False):
    """``[(topic, log time, publish time, data)]`` in write order, distinct random payloads."""
    times = (rng.integers(0, 10**6, count) if overlapping
             else np.sort(rng.integers(0, count // 3 + 1, count)))   # ties across chunks
    rows = []
    for index, time in enumerate(times.tolist()):
        topic = TOPICS[index % 4] if index >= count // 2 else TOPICS[index % 2]
        rows.append((topic, time, time + 7, index.to_bytes(4, 'little')
                     + rng.bytes(int(rng.integers(0, 60)))))
    return rows


def _write(rows, *, chunking='zstd', index_types=IndexType.ALL, crcs=True, chunk_size=700,
           **options):
    """
    Return an MCAP file written by the mcap library holding ``rows``, as bytes.

    Schemas and channels as other recorders write them: /a and /b first,
    /late registered half-way (its Channel record inside a later chunk),
    /raw without a schema; an attachment and a metadata record in between.
    """
    stream = io.BytesIO()
    writer = Writer(stream, chunk_size=chunk_size,
                    compression=(CompressionType.NONE if chunking == 'unchunked'
                                 else CompressionType[chunking.upper()]),
                    use_chunking=chunking != 'unchunked', index_types=index_types,
                    enable_crcs=crcs, **options)
    writer.start(profile='ros2', library='test')
    string = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
    empty = writer.register_schema('std_msgs/msg/Empty', 'ros2msg', b'')
    channels = {'/a': writer.register_channel('/a', 'cdr', string, {'k': 'v'}),
                '/b': writer.register_channel('/b', 'cdr', empty)}
    for index, (topic, log_time, publish_time, data) in enumerate(rows):
        if index == len(rows) // 2:
            channels['/late'] = writer.register_channel('/late', 'cdr', string)
            channels['/raw'] = writer.register_channel('/raw', 'cdr', 0)
            writer.add_attachment(create_time=1, log_time=2, name='calibration',
                                  media_type='text/plain', data=b'k: 1\n')
            writer.add_metadata('rig', {'name': 'test'})
        writer.add_message(channels[topic], log_time=log_time, data=data,
                           publish_time=publish_time, sequence=index)
    writer.finish()
    return stream.getvalue()


def _expected(rows):
    """Return the rows as the reader must return them: log-time order, ties in write order."""
    return sorted(rows, key=lambda row: row[1])


def _read(path, *, strict=True):
    """``(messages as rows, message_counts, notes)`` of an MCAP file."""
    with BagReader(path, strict=strict) as reader:
        got = [(m.topic, m.log_time_ns, m.publish_time_ns, m.data) for m in reader.messages()]
        return got, reader.message_counts, reader.notes


def _counts(rows):
    counts = {}
    for topic, *_ in rows:
        counts[topic] = counts.get(topic, 0) + 1
    return counts


def _layouts(chunking):
    """Every combination of indexes and summary options the writer has, with their names."""
    for index_names in itertools.chain.from_iterable(
            itertools.combinations(INDEXES, k) for k in range(len(INDEXES) + 1)):
        index_types = IndexType.NONE
        for name in index_names:
            index_types |= INDEXES[name]
        for flags in itertools.product([False, True], repeat=len(SUMMARY_OPTIONS)):
            options = dict(zip(SUMMARY_OPTIONS, flags))
            name = '-'.join([chunking, *index_names,
                             *(option for option, on in options.items() if on)])
            yield name, dict(chunking=chunking, index_types=index_types, **options)


@pytest.mark.slow
@pytest.mark.parametrize('chunking', CHUNKINGS)
def test_every_layout_reads_every_message_exactly(tmp_path, chunking):
    """128 layouts per chunking; files with messages, with channels only, with nothing."""
    rng = np.random.default_rng(CHUNKINGS.index(chunking))
    failures = []
    for number, (name, options) in enumerate(_layouts(chunking)):
        for rows in (_rows(rng, 60, overlapping=number % 3 == 0), []):
            path = tmp_path / f'{name}.mcap'
            path.write_bytes(_write(rows, crcs=number % 2 == 0, **options))
            got, counts, notes = _read(path)
            # The writer leaves out a chunk without messages, and the channels in it.
            listed = (TOPICS if rows else ['/a', '/b'] if chunking == 'unchunked'
                      or options['repeat_channels'] else [])
            expected_counts = {topic: _counts(rows).get(topic, 0) for topic in listed}
            if (got, counts, notes) != (_expected(rows), expected_counts, []):
                failures.append(f'{name} ({len(rows)} messages): read {len(got)}, '
                                f'counts {counts}, notes {notes}')
    assert not failures, '\n'.join(failures)


def _records(data, start=8):
    """``[(offset, opcode, length)]`` of the records of an MCAP file, from ``start``."""
    records, position = [], start
    while position < len(data) - 8:
        opcode, length = struct.unpack_from('<BQ', data, position)
        records.append((position, opcode, length))
        position += 9 + length
    return records


def _padded(data, extra=b'\xa5' * 5):
    """Return the file with bytes added to the end of every record (not Message records)."""
    out = bytearray(data[:8])
    for offset, opcode, length in _records(data):
        body = data[offset + 9:offset + 9 + length]
        pad = extra if opcode not in (0x05, 0x02) else b''   # a Message's data is the rest
        out += struct.pack('<BQ', opcode, length + len(pad)) + body + pad
    return bytes(out + data[-8:])


@pytest.mark.parametrize('chunking', CHUNKINGS)
def test_padded_records_read_as_written(tmp_path, chunking):
    """Records may grow new fields: a reader skips what follows the fields it knows."""
    rows = _rows(np.random.default_rng(3), 60)
    data = _write(rows, chunking=chunking, index_types=IndexType.NONE, repeat_channels=False,
                  repeat_schemas=False, use_statistics=False, use_summary_offsets=False)
    path = tmp_path / 'padded.mcap'
    path.write_bytes(_padded(data))
    assert path.stat().st_size > len(data)
    assert _read(path) == (_expected(rows), _counts(rows), [])


def test_description_counts_without_statistics(tmp_path):
    """'MCAP file, 0 messages' was printed for a file without a Statistics record."""
    rows = _rows(np.random.default_rng(4), 90)
    for index_types in (IndexType.ALL, IndexType.NONE):
        path = tmp_path / 'nostats.mcap'
        path.write_bytes(_write(rows, use_statistics=False, index_types=index_types))
        with open_bag(path) as bag:
            assert sum(bag.message_counts.values()) == len(rows) == len(list(bag.messages()))
            assert bag.notes == []


def test_channels_only_in_chunks_are_read_by_open_bag(tmp_path):
    """A file whose summary does not repeat its channels (Foxglove's repeatChannels: false)."""
    rows = _rows(np.random.default_rng(5), 90)
    path = tmp_path / 'norepeat.mcap'
    path.write_bytes(_write(rows, repeat_channels=False, repeat_schemas=False))
    with open_bag(path) as bag:
        assert bag.topics == {'/a': 'std_msgs/msg/String', '/b': 'std_msgs/msg/Empty',
                              '/late': 'std_msgs/msg/String', '/raw': ''}
        assert [(m.topic, m.data) for m in bag.messages(['/late'])] == [
            (topic, data) for topic, _, _, data in _expected(rows) if topic == '/late']


# Damage


def _chunk_offsets(data):
    with io.BytesIO(data) as stream:
        return sorted(index.chunk_start_offset
                      for index in make_reader(stream).get_summary().chunk_indexes)


def _lost_by_topic(rows, got):
    """``{topic: written but not read}``; every message read must be one written, unchanged."""
    remaining = list(rows)
    for row in got:
        remaining.remove(row)   # ValueError if a message was read that was not written
    return _counts(remaining)


def _note_counts(note):
    """``(total, {topic: count})`` from a loss note."""
    head, _, rest = note.partition(' could not be read')
    total = int(head.rsplit(': ', 1)[1].split()[0])
    by_topic = rest[rest.index('(') + 1:rest.index(')')].split(', ')
    return total, {part.rsplit(' ', 1)[0]: int(part.rsplit(' ', 1)[1]) for part in by_topic}


# A compressed chunk without a CRC may decompress to other bytes: only a CRC tells.
@pytest.mark.parametrize('chunking, crcs', [('none', True), ('none', False), ('lz4', True),
                                            ('zstd', True)])
@pytest.mark.parametrize('zeroed', [64, 4096])
def test_zeroed_bytes_in_a_chunk_are_a_note_or_with_strict_an_error(
        tmp_path, chunking, crcs, zeroed):
    """The usual damage after a power loss: what is lost is counted, by topic, with its chunk."""
    rows = _rows(np.random.default_rng(6), 300)
    data = bytearray(_write(rows, chunking=chunking, crcs=crcs))
    chunks = _chunk_offsets(bytes(data))
    # Uncompressed chunks without a CRC: zero from a record's start (bytes zeroed in the
    # middle of a message's data cannot be told from data).
    start = chunks[2] + 200 if crcs or chunking != 'none' else (
        bytes(data).index(_expected(rows)[60][3]) - 22 - 9)
    chunk = max(offset for offset in chunks if offset < start)
    data[start:start + zeroed] = bytes(zeroed)
    path = tmp_path / 'zeroed.mcap'
    path.write_bytes(bytes(data))
    got, counts, notes = _read(path, strict=False)
    lost = _lost_by_topic(rows, got)
    assert sum(lost.values()) > 0 and sum(counts.values()) == len(rows)
    note, = notes
    assert note.startswith(f'{path}: ') and f'at offset {chunk}' in note
    assert _note_counts(note) == (sum(lost.values()), lost)
    with pytest.raises(BagError, match=f'^{path}: .* could not be read.*at offset {chunk}.*'
                                       r'refused \(--strict\)$'):
        _read(path)


def _with(data, offset, fmt, value):
    data = bytearray(data)
    struct.pack_into(fmt, data, offset, value)
    return bytes(data)


def _damaged_files(tmp_path):
    """``{name: path}`` of files whose lengths say more than the file holds."""
    rows = _rows(np.random.default_rng(8), 300)
    zstd = _write(rows)
    chunks = _chunk_offsets(zstd)
    unchecked = _write(rows, crcs=False)   # the same layout, chunks without CRCs
    assert _chunk_offsets(unchecked) == chunks
    unchunked = _write(rows, chunking='unchunked')
    channel = next(offset for offset, opcode, _ in _records(unchunked) if opcode == 0x04)
    message = [offset for offset, opcode, _ in _records(unchunked) if opcode == 0x05][100]
    summary_channel = next(offset for offset, opcode, _ in _records(zstd)
                           if opcode == 0x04 and offset > chunks[-1])
    first, second = chunks[0], chunks[1]
    second_end = second + 9 + struct.unpack_from('<Q', zstd, second + 1)[0]
    swapped = (zstd[:first] + zstd[second:second_end] + zstd[first:second]
               + zstd[second_end:])
    files = {
        # chunk: compression name length, bit-flipped
        'compression_length': _with(zstd, second + 9 + 28, '<I', 0x80000004),
        'record_length_2^64-1': _with(zstd, second + 1, '<Q', 2**64 - 1),
        'records_length_2^63': _with(zstd, second + 9 + 32 + 4, '<Q', 2**63 + 5),
        'uncompressed_size_2^62': _with(zstd, second + 9 + 16, '<Q', 2**62),
        # the same without a CRC to vouch for what the chunk index says instead
        'compression_length_unchecked': _with(unchecked, second + 9 + 28, '<I', 0x80000004),
        'records_length_2^63_unchecked': _with(unchecked, second + 9 + 32 + 4, '<Q', 2**63 + 5),
        'uncompressed_size_2^62_unchecked': _with(unchecked, second + 9 + 16, '<Q', 2**62),
        'summary_channel_length_2^31': _with(zstd, summary_channel + 1, '<Q', 2**31),
        'topic_length_2^32-1': _with(unchunked, channel + 9 + 4, '<I', 2**32 - 1),
        'message_length_2^64-1': _with(unchunked, message + 1, '<Q', 2**64 - 1),
        'swapped_chunks': swapped,
    }
    paths = {}
    for name, data in files.items():
        paths[name] = tmp_path / f'{name}.mcap'
        paths[name].write_bytes(data)
    return rows, paths


def _outcomes_in_a_child(paths, strict, limit_bytes=512 << 20):
    """
    Read each file in a forked child whose address space may grow by ``limit_bytes`` only.

    Returns ``{name: ('read', messages as rows, notes) or ('BagError', line) or
    ('escaped', exception type)}``: what the parent cannot test in its own
    process (a MemoryError there would not be one under the limit).
    """
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:   # the child: reads under the limit, sends what happened, exits
        try:
            with open('/proc/self/statm') as stream:
                mapped = int(stream.read().split()[0]) * resource.getpagesize()
            resource.setrlimit(resource.RLIMIT_AS, (mapped + limit_bytes, mapped + limit_bytes))
            outcomes = {}
            for name, path in paths.items():
                try:
                    outcomes[name] = ('read', *_read(path, strict=strict)[::2])
                except BagError as error:
                    outcomes[name] = ('BagError', str(error))
                except BaseException as error:   # what the test reports as escaping
                    outcomes[name] = ('escaped', type(error).__name__)
            with os.fdopen(write_end, 'wb') as stream:
                pickle.dump(outcomes, stream)
        finally:
            os._exit(0)
    os.close(write_end)
    with os.fdopen(read_end, 'rb') as stream:
        outcomes = pickle.load(stream)
    os.waitpid(pid, 0)
    return outcomes


@pytest.mark.slow
def test_lengths_past_the_end_never_allocate_and_are_said(tmp_path):
    """A MemoryError, an OverflowError: what these lengths gave; now a note, or one line."""
    rows, paths = _damaged_files(tmp_path)
    lenient = _outcomes_in_a_child(paths, strict=False)
    strict = _outcomes_in_a_child(paths, strict=True)
    for name, path in paths.items():
        kind, *details = lenient[name]
        assert kind == 'read', (name, lenient[name])
        got, notes = details
        lost = _lost_by_topic(rows, got)
        # Read in full: a damaged summary (the data section is intact: a linear scan), chunks
        # out of place (also a scan), a wrong size or length where the chunk's CRC vouches for
        # its data as the chunk index describes it, a damaged Channel record repeated in the
        # summary.
        if not name.endswith('_unchecked') and name != 'message_length_2^64-1':
            assert (lost, notes) == ({}, []), name
            assert strict[name][0] == 'read'
            continue
        note, = notes
        assert _note_counts(note) == (sum(lost.values()), lost), (name, note)
        kind, line = strict[name]
        assert kind == 'BagError' and line.startswith(f'{path}: ') and '\n' not in line
        assert ' at offset ' in line and line.endswith('refused (--strict)'), (name, line)


def test_a_recording_cut_inside_an_uncompressed_chunk_keeps_its_complete_messages(tmp_path):
    """A writer that writes a chunk as it fills it, killed: the messages before the cut."""
    rows = _rows(np.random.default_rng(9), 60)
    data = _write(rows, chunking='none', chunk_size=10**6)   # one chunk
    path = tmp_path / 'cut.mcap'
    path.write_bytes(data[:data.index(rows[40][3]) + 2])   # inside the 41st message
    with pytest.raises(BagError, match='unfinished recording'):
        BagReader(path, strict=True)
    with BagReader(path) as reader:
        assert reader.recovered == 40 and reader.notes == []
        assert [(m.topic, m.log_time_ns, m.publish_time_ns, m.data)
                for m in reader.messages()] == _expected(rows[:40])


@pytest.mark.parametrize('damage', ['zeroed_schema_name', 'unknown_channel_opcode'])
def test_a_damaged_summary_without_crc_gives_way_to_the_data_section(tmp_path, damage):
    """The summary's records were taken as they were: a topic of type 'std_msgs/m' and zeros."""
    rows = _rows(np.random.default_rng(10), 90)
    data = bytearray(_write(rows))
    struct.pack_into('<I', data, len(data) - 8 - 4, 0)   # a summary without CRC
    last_chunk = _chunk_offsets(bytes(data))[-1]
    kind = 0x03 if damage == 'zeroed_schema_name' else 0x04
    record = next(offset for offset, opcode, _ in _records(bytes(data))
                  if opcode == kind and offset > last_chunk)
    if damage == 'zeroed_schema_name':
        data[record + 9 + 2 + 4 + 10:record + 9 + 2 + 4 + 19] = bytes(9)
    else:
        data[record] = 0x84   # a bit flipped: a record of unknown kind, skipped
    path = tmp_path / 'summary.mcap'
    path.write_bytes(bytes(data))
    assert _read(path) == (_expected(rows), _counts(rows), [])
    with open_bag(path) as bag:
        assert bag.topics['/a'] == 'std_msgs/msg/String'
