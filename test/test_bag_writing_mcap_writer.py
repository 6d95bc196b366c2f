"""
Tests of rotation_node.bag.writing.mcap_writer: whole chunks against the mcap library's writer.

The oracle is the ``mcap`` library: its ``Writer`` given the same calls must
write the same file byte for byte, and its indexed reader (CRCs validated),
its linear stream reader and ``rosbags`` must read back every message, with
a summary (statistics, chunk indexes, message indexes) that agrees with them.
"""
import io
import pathlib
import struct
import zlib

from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Chunk, Footer, Message, MessageIndex
from mcap.stream_reader import get_chunk_data_stream, StreamReader
from mcap.writer import CompressionType, Writer
import pytest
from rosbags.highlevel import AnyReader
from rotation_node.bag.writing.mcap_writer import ChunkWriter
from rotation_node.wire.message_types import message_definition

COMPRESSIONS = ['zstd', 'lz4', 'none']
T0 = 1_700_000_000_000_000_000
TOPICS = [('/text', 'std_msgs/msg/String'), ('/other', 'std_msgs/msg/String'),
          ('/count', 'std_msgs/msg/Int32')]


def _cdr_string(text):
    encoded = text.encode() + b'\0'
    return b'\0\1\0\0' + struct.pack('<I', len(encoded)) + encoded


def _plan(rng):
    """
    Return the calls to make on a writer: topics registered as they come, interleaved chunks.

    ``('topic', name, type)`` registers a schema (once per type) and a
    channel; ``('chunk', [(topic, log, publish, data)...])`` writes a chunk;
    ``('metadata', name, dict)`` a metadata record. The last topic is
    registered after the first chunk (it goes into the second one), and a
    topic registered last never has a message (it is only in the summary).
    """
    plan = [('topic', *TOPICS[0]), ('topic', *TOPICS[1])]
    time = T0
    for chunk in range(6):
        if chunk == 1:
            plan.append(('topic', *TOPICS[2]))
        topics = [t for t, _ in TOPICS[:2 if chunk == 0 else 3]]
        messages = []
        for _ in range(int(rng.integers(1, 300))):
            topic = topics[int(rng.integers(len(topics)))]
            time += int(rng.integers(0, 2_000_000))
            # Log times out of order now and then, as a recording's may be.
            log = time - int(rng.integers(0, 5_000_000)) if rng.random() < 0.1 else time
            if topic == '/count':
                data = b'\0\1\0\0' + struct.pack('<i', int(rng.integers(-1000, 1000)))
            else:
                data = _cdr_string('x' * int(rng.integers(0, 500)))
            messages.append((topic, log, time + 7, data))
        plan.append(('chunk', messages))
    plan.append(('topic', '/silent', 'std_msgs/msg/String'))
    plan.append(('metadata', 'rosbag2', {'serialized_metadata': 'version: 9\n'}))
    return plan


def _play(plan, writer, library_writer):
    """Make the calls of ``plan`` on ``writer`` (ours, or the library's: ``library_writer``)."""
    schemas, channels = {}, {}
    writer.start(profile='ros2', library='test')
    for step in plan:
        if step[0] == 'topic':
            _, topic, type_name = step
            if type_name not in schemas:
                schemas[type_name] = writer.register_schema(
                    type_name, 'ros2msg', message_definition(type_name).encode())
            channels[topic] = writer.register_channel(
                topic, 'cdr', schemas[type_name], {'offered_qos_profiles': ''})
        elif step[0] == 'chunk':
            if library_writer:
                for topic, log, publish, data in step[1]:
                    writer.add_message(channels[topic], log, data, publish)
                writer.flush()
            else:
                writer.write_chunk([channels[topic] for topic, *_ in step[1]],
                                   [log for _, log, _, _ in step[1]],
                                   [publish for _, _, publish, _ in step[1]],
                                   [data for *_, data in step[1]])
        else:
            writer.add_metadata(step[1], step[2])
    writer.finish()


def _written(plan, compression, library_writer=False):
    stream = io.BytesIO()
    if library_writer:
        writer = Writer(stream, compression=CompressionType[compression.upper()],
                        chunk_size=2**62)
    else:
        writer = ChunkWriter(stream, compression=compression)
    _play(plan, writer, library_writer)
    return stream.getvalue()


def _messages(plan):
    return [message for step in plan if step[0] == 'chunk' for message in step[1]]


@pytest.mark.parametrize('compression', COMPRESSIONS, ids=str)
def test_file_is_the_mcap_writers_byte_for_byte(rng, compression):
    plan = _plan(rng)
    assert _written(plan, compression) == _written(plan, compression, library_writer=True)


@pytest.mark.parametrize('compression', COMPRESSIONS, ids=str)
def test_indexed_linear_and_rosbags_readers_read_every_message(tmp_path, rng, compression):
    plan = _plan(rng)
    expected = _messages(plan)
    path = tmp_path / 'chunks.mcap'
    path.write_bytes(_written(plan, compression))
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        indexed = [(channel.topic, message.log_time, message.publish_time, message.data)
                   for _, channel, message in reader.iter_messages(log_time_order=False)]
    assert indexed == expected
    with open(path, 'rb') as stream:
        records = list(StreamReader(stream, validate_crcs=True).records)
    topics = {record.id: record.topic for record in records if hasattr(record, 'topic')}
    linear = [(topics[r.channel_id], r.log_time, r.publish_time, r.data)
              for r in records if isinstance(r, Message)]
    assert linear == expected
    with AnyReader([pathlib.Path(path)]) as reader:
        from_rosbags = [(connection.topic, log_time, bytes(data))
                        for connection, log_time, data in reader.messages()]
    assert from_rosbags == sorted(((t, log, d) for t, log, _, d in expected),
                                  key=lambda message: message[1])


@pytest.mark.parametrize('compression', COMPRESSIONS, ids=str)
def test_summary_agrees_with_the_messages(rng, compression):
    plan = _plan(rng)
    expected = _messages(plan)
    data = _written(plan, compression)
    summary = make_reader(io.BytesIO(data)).get_summary()
    ids = {channel.topic: channel.id for channel in summary.channels.values()}
    statistics = summary.statistics
    assert statistics.message_count == len(expected)
    assert (statistics.message_start_time, statistics.message_end_time) == (
        min(log for _, log, _, _ in expected), max(log for _, log, _, _ in expected))
    assert statistics.channel_message_counts == {
        ids[topic]: sum(1 for t, *_ in expected if t == topic) for topic, _ in TOPICS}
    assert (statistics.schema_count, statistics.channel_count, statistics.chunk_count,
            statistics.metadata_count) == (2, 4, 6, 1)
    chunks = [step[1] for step in plan if step[0] == 'chunk']
    assert len(summary.chunk_indexes) == len(chunks)
    for index, messages in zip(summary.chunk_indexes, chunks):
        chunk_stream = io.BytesIO(data[index.chunk_start_offset:
                                       index.chunk_start_offset + index.chunk_length])
        chunk_stream.read(9)
        chunk = Chunk.read(_stream(chunk_stream))
        assert (index.message_start_time, index.message_end_time) == (
            chunk.message_start_time, chunk.message_end_time) == (
            min(m[1] for m in messages), max(m[1] for m in messages))
        assert index.compressed_size == len(chunk.data)
        uncompressed, size = get_chunk_data_stream(chunk, validate_crc=True)
        uncompressed = uncompressed.read(size)
        assert index.uncompressed_size == len(uncompressed)
        assert chunk.uncompressed_crc == zlib.crc32(uncompressed)
        # Every message index entry points at its message in the uncompressed chunk.
        assert sum(index.message_index_offsets.values()) > 0
        found = []
        for channel_id, offset in index.message_index_offsets.items():
            record_stream = io.BytesIO(data[offset:])
            assert record_stream.read(1)[0] == Opcode.MESSAGE_INDEX
            record_stream.read(8)
            message_index = MessageIndex.read(_stream(record_stream))
            assert message_index.channel_id == channel_id
            for log_time, position in message_index.records:
                record = io.BytesIO(uncompressed[position:])
                opcode, length = struct.unpack('<BQ', record.read(9))
                assert opcode == Opcode.MESSAGE
                message = Message.read(_stream(record), length)
                assert (message.channel_id, message.log_time) == (channel_id, log_time)
                found.append((position, message.channel_id, message.log_time,
                              message.publish_time, message.data))
        assert [(log, publish, d) for _, _, log, publish, d in sorted(found)] == [
            (log, publish, d) for _, log, publish, d in messages]
        # The message indexes are the records right after the chunk, together.
        assert min(index.message_index_offsets.values()) == (index.chunk_start_offset
                                                             + index.chunk_length)
    footer_stream = io.BytesIO(data[-8 - 29:-8])
    footer_stream.read(9)
    footer = Footer.read(_stream(footer_stream))
    summary_bytes = data[footer.summary_start:len(data) - 8 - 29]
    assert footer.summary_crc == zlib.crc32(
        data[len(data) - 8 - 29:len(data) - 8 - 4], zlib.crc32(summary_bytes))


def _stream(stream):
    from mcap.data_stream import ReadDataStream
    return ReadDataStream(stream)


def test_no_messages_write_no_chunk_and_a_valid_file():
    plan = [('topic', *TOPICS[0]), ('chunk', []), ('topic', *TOPICS[1])]
    data = _written(plan, 'zstd')
    assert data == _written(plan, 'zstd', library_writer=True)
    summary = make_reader(io.BytesIO(data), validate_crcs=True).get_summary()
    assert summary.chunk_indexes == []
    assert summary.statistics.message_count == 0
    assert [channel.topic for channel in summary.channels.values()] == ['/text', '/other']
    assert list(make_reader(io.BytesIO(data)).iter_messages()) == []
