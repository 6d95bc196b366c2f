"""
Tests of rotation_node.bag.reading.mcap_reader: BagWriter / BagReader.

Every bag is read back three ways: with BagReader, with the independent rosbags
AnyReader (which decodes from the definitions stored in the bag, with no type
store of its own), and record by record with the mcap library's validating
reader and mcap-ros2-support's decoder.
"""
import io
import os
import pathlib

from bag_helpers import plain, random_message
from mcap.reader import make_reader
from mcap.records import Channel, Footer, Header, Metadata, Schema, Statistics
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.errors import BagError
from rotation_node.wire.cdr import fixed_layout_codec
from rotation_node.wire.message_types import message_class, message_definition, type_hash
from rotation_node.wire.qos import qos_profiles_from_yaml
import yaml

TYPES = [
    'sensor_msgs/msg/Imu',
    'geometry_msgs/msg/Vector3Stamped',
    'geometry_msgs/msg/QuaternionStamped',
    'geometry_msgs/msg/PoseWithCovarianceStamped',
    'geometry_msgs/msg/PolygonStamped',
    'sensor_msgs/msg/JointState',
    'std_msgs/msg/String',
    'visualization_msgs/msg/MarkerArray',
]
T0 = 1_700_000_000_123_456_789
QOS_YAML = """- history: keep_last
  depth: 7
  reliability: reliable
  durability: transient_local
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 1
    nsec: 500
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false"""


def _records(type_name, rng, count=5):
    """(topic, message, log time, publish time) rows of one type on one topic, distinct times."""
    topic = '/' + type_name.split('/')[-1].lower()
    cls = message_class(type_name)
    offset = 1000 * TYPES.index(type_name)
    return [(topic, random_message(cls, rng), T0 + offset + 10_000_000 * i,
             T0 + offset + 10_000_000 * i - 1234) for i in range(count)]


@pytest.fixture
def mixed_bag(tmp_path, rng):
    """Return a bag with every type in TYPES, interleaved; returns (path, rows)."""
    rows = [row for type_name in TYPES for row in _records(type_name, rng)]
    rows.sort(key=lambda row: row[2])
    path = tmp_path / 'mixed.mcap'
    with BagWriter(path) as writer:
        writer.add_topic(TopicMetadata('/imu', 'sensor_msgs/msg/Imu', QOS_YAML))
        for topic, msg, log_time, publish_time in rows:
            writer.write(topic, msg, log_time, publish_time)
    return path, rows


def test_reader_returns_every_message(mixed_bag):
    path, rows = mixed_bag
    reader = BagReader(path)
    assert reader.topics == {topic: f'{type(msg).__module__.split(".")[0]}/msg/'
                             f'{type(msg).__name__}' for topic, msg, _, _ in rows}
    # Compared decoded: the types without a fixed layout are serialised by rclpy,
    # which leaves CDR alignment padding uninitialised.
    assert [(m.topic, plain(m.message()), m.log_time_ns, m.publish_time_ns)
            for m in reader.messages()] == [
        (topic, plain(msg), log_time, publish_time) for topic, msg, log_time, publish_time in rows]
    assert reader.message_counts == {topic: 5 for topic in reader.topics}
    reader.close()


@pytest.mark.slow
def test_rosbags_anyreader_reads_every_field(mixed_bag):
    path, rows = mixed_bag
    with AnyReader([pathlib.Path(path)]) as reader:   # no type store: definitions from the bag
        assert reader.message_count == len(rows)
        assert reader.start_time == rows[0][2]
        assert reader.end_time == rows[-1][2] + 1
        assert {c.topic: (c.msgtype, c.msgcount) for c in reader.connections} == {
            topic: (reader.topics[topic].msgtype, 5) for topic in {r[0] for r in rows}}
        decoded = [(c.topic, stamp, plain(reader.deserialize(raw, c.msgtype)))
                   for c, stamp, raw in reader.messages()]
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert decoded == [(topic, log_time, plain(msg)) for topic, msg, log_time, _ in rows]
    imu_qos, = qos['/imu']
    assert (imu_qos.depth, imu_qos.reliability.name, imu_qos.durability.name,
            imu_qos.lifespan.sec, imu_qos.lifespan.nsec) == (
        7, 'RELIABLE', 'TRANSIENT_LOCAL', 1, 500)
    assert qos['/string'] == []


def test_mcap_library_validates_file_layout(mixed_bag):
    path, rows = mixed_bag
    with open(path, 'rb') as stream:
        records = list(StreamReader(stream, validate_crcs=True).records)
    header, footer = records[0], records[-1]
    assert isinstance(header, Header) and header.profile == 'ros2'
    assert 'mcap-python' in header.library
    assert isinstance(footer, Footer) and footer.summary_start > 0
    schemas = {r.name: r for r in records if isinstance(r, Schema)}
    assert set(schemas) == set(TYPES)
    assert all(s.encoding == 'ros2msg' and s.data.decode() == message_definition(s.name)
               for s in schemas.values())
    channels = {r.topic: r for r in records if isinstance(r, Channel)}
    assert all(c.message_encoding == 'cdr' for c in channels.values())
    assert all(set(c.metadata) == {'offered_qos_profiles', 'topic_type_hash'}
               for c in channels.values())
    assert channels['/imu'].metadata['offered_qos_profiles'] == QOS_YAML
    assert all(c.metadata['topic_type_hash'] == type_hash(schemas[name].name)
               for name, c in ((s.name, c) for c in channels.values() for s in schemas.values()
                               if s.id == c.schema_id))
    statistics, = [r for r in records if isinstance(r, Statistics)]
    assert statistics.message_count == len(rows)
    assert (statistics.message_start_time, statistics.message_end_time) == (
        rows[0][2], rows[-1][2])

    with open(path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [(channel.topic, plain(msg))
                   for _, channel, _, msg in reader.iter_decoded_messages()]
    assert decoded == [(topic, plain(msg)) for topic, msg, _, _ in rows]


def test_rosbag2_metadata_record(mixed_bag):
    path, rows = mixed_bag
    with open(path, 'rb') as stream:
        metadata, = [r for r in StreamReader(stream).records if isinstance(r, Metadata)]
    assert metadata.name == 'rosbag2'
    info = yaml.safe_load(metadata.metadata['serialized_metadata'])
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['message_count'] == len(rows)
    assert info['starting_time']['nanoseconds_since_epoch'] == rows[0][2]
    assert info['duration']['nanoseconds'] == rows[-1][2] - rows[0][2]
    assert info['relative_file_paths'] == ['mixed.mcap']
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert {name: t['message_count'] for name, t in topics.items()} == {r[0]: 5 for r in rows}
    imu = topics['/imu']['topic_metadata']
    assert (imu['type'], imu['serialization_format']) == ('sensor_msgs/msg/Imu', 'cdr')
    assert imu['offered_qos_profiles'] == yaml.safe_load(QOS_YAML)


def test_message_order_and_topic_filter(tmp_path, rng):
    rows = _records('sensor_msgs/msg/Imu', rng, 6) + _records('std_msgs/msg/String', rng, 3)
    path = tmp_path / 'order.mcap'
    with BagWriter(path) as writer:
        for topic, msg, log_time, publish_time in reversed(rows):
            writer.write(topic, msg, log_time, publish_time)
    reader = BagReader(path)
    assert [m.log_time_ns for m in reader.messages()] == sorted(r[2] for r in rows)
    assert [m.log_time_ns for m in reader.messages(['/string'])] == [r[2] for r in rows[6:]]
    with pytest.raises(BagError, match='/nope not in .*order.mcap'):
        reader.messages(['/imu', '/nope'])


def test_write_serialized_copies_bytes_and_defaults_publish_time(tmp_path, rng):
    data = serialize_message(random_message(message_class('sensor_msgs/msg/Imu'), rng))
    path = tmp_path / 'raw.mcap'
    with BagWriter(path) as writer:
        writer.write_serialized('/imu', 'sensor_msgs/msg/Imu', data, T0)
    record, = BagReader(path).messages()
    assert (record.data, record.log_time_ns, record.publish_time_ns) == (data, T0, T0)


def test_copying_a_topic_keeps_its_schema_and_qos(tmp_path, mixed_bag):
    source, _ = mixed_bag
    reader = BagReader(source)
    copy = tmp_path / 'copy.mcap'
    with BagWriter(copy) as writer:
        for metadata in reader.topic_metadata.values():
            writer.add_topic(metadata)
        for m in reader.messages():
            writer.write_serialized(m.topic, m.type_name, m.data, m.log_time_ns, m.publish_time_ns)
    copied = BagReader(copy)
    assert copied.topic_metadata == reader.topic_metadata
    assert [(m.topic, m.data, m.log_time_ns, m.publish_time_ns) for m in copied.messages()] == [
        (m.topic, m.data, m.log_time_ns, m.publish_time_ns) for m in reader.messages()]


def test_file_appears_only_on_clean_close(tmp_path, rng):
    path = tmp_path / 'late.mcap'
    writer = BagWriter(path)
    writer.write('/s', random_message(message_class('std_msgs/msg/String'), rng), T0)
    assert not path.exists()
    writer.close()
    writer.close()
    assert path.exists() and os.listdir(tmp_path) == ['late.mcap']


def test_exception_inside_with_leaves_no_file(tmp_path, rng):
    path = tmp_path / 'failed.mcap'
    with pytest.raises(RuntimeError, match='boom'):
        with BagWriter(path) as writer:
            writer.write('/s', random_message(message_class('std_msgs/msg/String'), rng), T0)
            raise RuntimeError('boom')
    assert os.listdir(tmp_path) == []


def test_refuses_to_overwrite(tmp_path):
    path = tmp_path / 'exists.mcap'
    path.write_bytes(b'precious')
    with pytest.raises(BagError, match='exists.mcap already exists'):
        BagWriter(path)
    assert path.read_bytes() == b'precious' and os.listdir(tmp_path) == ['exists.mcap']


def test_overwrite_replaces_only_on_success(tmp_path, rng):
    path = tmp_path / 'exists.mcap'
    path.write_bytes(b'precious')
    msg = random_message(message_class('std_msgs/msg/String'), rng)
    with pytest.raises(RuntimeError):
        with BagWriter(path, overwrite=True) as writer:
            writer.write('/s', msg, T0)
            raise RuntimeError
    assert path.read_bytes() == b'precious'
    with BagWriter(path, overwrite=True) as writer:
        writer.write('/s', msg, T0)
    assert [plain(m.message()) for m in BagReader(path).messages()] == [plain(msg)]


def test_one_type_per_topic(tmp_path, rng):
    with BagWriter(tmp_path / 'types.mcap') as writer:
        writer.write('/x', random_message(message_class('std_msgs/msg/String'), rng), T0)
        with pytest.raises(BagError, match='/x holds std_msgs/msg/String.*Imu'):
            writer.write('/x', random_message(message_class('sensor_msgs/msg/Imu'), rng), T0)
        with pytest.raises(BagError, match='already registered'):
            writer.add_topic(TopicMetadata('/x', 'std_msgs/msg/String'))


@pytest.mark.parametrize('log_time, match', [
    (-1, r'log_time_ns must be in \[0, 2\*\*64\)'),
    (2**64, r'log_time_ns must be in'),
    (1.5, 'log_time_ns must be an integer'),
    ('1', 'log_time_ns must be an integer'),
])
def test_bad_timestamps_rejected_without_damage(tmp_path, rng, log_time, match):
    msg = random_message(message_class('std_msgs/msg/String'), rng)
    path = tmp_path / 'times.mcap'
    with BagWriter(path) as writer:
        writer.write('/s', msg, T0)
        with pytest.raises(BagError, match=match):
            writer.write('/s', msg, log_time)
        with pytest.raises(BagError, match=match.replace('log_time', 'publish_time')):
            writer.write('/s', msg, T0, publish_time_ns=log_time)
    assert [m.log_time_ns for m in BagReader(path).messages()] == [T0]


@pytest.mark.parametrize('type_name, match', [
    ('nonexistent_msgs/msg/Foo', "no message definition for 'nonexistent_msgs/msg/Foo'"),
    ('sensor_msgs/msg/NoSuchType', "no message definition for 'sensor_msgs/msg/NoSuchType'"),
    ('Imu', "invalid message type name 'Imu'"),
])
def test_unknown_type_on_write(tmp_path, type_name, match):
    with BagWriter(tmp_path / 'unknown.mcap') as writer:
        with pytest.raises(BagError, match=match):
            writer.write_serialized('/x', type_name, b'\0\1\0\0', T0)


def test_unknown_type_on_read(tmp_path):
    path = tmp_path / 'foreign.mcap'
    with BagWriter(path) as writer:
        writer.add_topic(TopicMetadata('/x', 'foreign_msgs/msg/Thing', definition='int32 a\n',
                                       type_hash=''))
        writer.write_serialized('/x', 'foreign_msgs/msg/Thing', b'\0\1\0\0\7\0\0\0', T0)
    reader = BagReader(path)
    assert reader.topics == {'/x': 'foreign_msgs/msg/Thing'}
    record, = reader.messages()
    with pytest.raises(BagError, match="unknown message type 'foreign_msgs/msg/Thing'"):
        record.message()


def test_invalid_cdr_is_reported(tmp_path):
    path = tmp_path / 'bad_cdr.mcap'
    with BagWriter(path) as writer:
        writer.write_serialized('/imu', 'sensor_msgs/msg/Imu', b'\0\1\0\0\1', T0)
    record, = BagReader(path).messages()
    with pytest.raises(BagError, match='not a valid sensor_msgs/msg/Imu'):
        record.message()
    with pytest.raises(BagError, match=f'/imu at {T0} ns is not a valid .* truncated'):
        record.message(fixed_layout_codec('sensor_msgs/msg/Imu').decode)


def test_message_decodes_with_a_given_decoder(tmp_path, rng):
    msg = random_message(message_class('sensor_msgs/msg/Imu'), rng)
    path = tmp_path / 'imu.mcap'
    with BagWriter(path) as writer:
        writer.write('/imu', msg, T0)
    record, = BagReader(path).messages()
    view = record.message(fixed_layout_codec('sensor_msgs/msg/Imu').decode)
    assert view.header.frame_id == msg.header.frame_id
    assert view.orientation_covariance == tuple(msg.orientation_covariance)


def test_write_encodes_fixed_layouts_with_zero_padding(tmp_path, rng):
    """Same messages, same bytes: cdr for fixed layouts, rclpy for the others."""
    vector = random_message(message_class('geometry_msgs/msg/Vector3Stamped'), rng)
    vector.header.frame_id = 'a'   # 2 bytes of padding before the vector
    joints = random_message(message_class('sensor_msgs/msg/JointState'), rng)
    path = tmp_path / 'padding.mcap'
    with BagWriter(path) as writer:
        writer.write('/vector', vector, T0)
        writer.write('/joints', joints, T0)
    records = {m.topic: m for m in BagReader(path).messages()}
    assert records['/vector'].data == (
        fixed_layout_codec('geometry_msgs/msg/Vector3Stamped').encode(vector))
    assert records['/vector'].data[4 + 14:4 + 16] == bytes(2)
    assert records['/joints'].message() == joints


def _damaged(source, how):
    data = bytearray(source.read_bytes())
    if how == 'empty':
        return b''
    if how == 'text':
        return b'not an mcap file at all\n' * 10
    if how.startswith('truncated'):
        return bytes(data[:int(len(data) * float(how.split('_')[1]))])
    # Overwrite bytes in the middle of a chunk: caught by its CRC (or, the
    # chunk being zstd-compressed, by zstd's own frame checks first).
    middle = len(data) // 3
    data[middle:middle + 16] = b'\xff' * 16
    return bytes(data)


@pytest.mark.parametrize('how, reason', [
    ('empty', r'damaged.mcap: empty file \(0 bytes\)'),
    ('text', 'damaged.mcap is not a valid MCAP file: .*invalid magic'),
    ('overwritten_chunk', 'damaged.mcap: 40 messages could not be read .*chunk that '
                          '(fails its CRC|does not decompress).*refused \\(--strict\\)')])
def test_damaged_file_raises_bag_error(tmp_path, mixed_bag, how, reason):
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(_damaged(mixed_bag[0], how))
    with pytest.raises(BagError, match=reason):
        reader = BagReader(path, strict=True)
        list(reader.messages())


def test_damaged_chunk_is_skipped_with_a_note(tmp_path, mixed_bag):
    """Without --strict the other chunks are read; the note counts what the damaged one held."""
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(_damaged(mixed_bag[0], 'overwritten_chunk'))
    with BagReader(path) as reader:
        read = list(reader.messages())
        note, = reader.notes
    lost = len(mixed_bag[1]) - len(read)
    assert lost > 0
    assert f'damaged.mcap: {lost} message{"s" if lost > 1 else ""} could not be read' in note
    assert ('chunk that fails its CRC' in note or 'does not decompress' in note) and (
        ' at offset ' in note)


@pytest.mark.parametrize('fraction', [0.1, 0.5, 0.999])
def test_truncated_file_reads_as_unfinished_recording(tmp_path, mixed_bag, fraction):
    """A file cut short (no summary, no footer) gives the messages of its complete chunks."""
    path = tmp_path / 'cut.mcap'
    path.write_bytes(_damaged(mixed_bag[0], f'truncated_{fraction}'))
    with pytest.raises(BagError, match=r'cut.mcap: unfinished recording .*\(--strict\)'):
        BagReader(path, strict=True)
    with BagReader(mixed_bag[0]) as complete:
        every = [(m.topic, m.data, m.log_time_ns, m.publish_time_ns)
                 for m in complete.messages()]
    with BagReader(path) as reader:
        recovered = [(m.topic, m.data, m.log_time_ns, m.publish_time_ns)
                     for m in reader.messages()]
        assert reader.recovered == len(recovered) == sum(reader.message_counts.values())
    # Whatever was recovered is the start of the recording, byte for byte.
    assert recovered == every[:len(recovered)]
    if fraction == 0.999:   # only the summary and footer are missing
        assert recovered == every


@pytest.mark.parametrize('make', ['missing', 'directory'])
def test_unreadable_path_raises_bag_error(tmp_path, make):
    path = tmp_path / 'x.mcap'
    if make == 'directory':
        path.mkdir()
    with pytest.raises(BagError, match='cannot open bag .*x.mcap'):
        BagReader(path)


def test_non_cdr_channel_listed_and_read_as_stored(tmp_path):
    """A channel of another recorder is read as it is (to be copied), not decoded."""
    from mcap.writer import Writer
    path = tmp_path / 'json.mcap'
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='', library='test')
        schema = writer.register_schema('Thing', 'jsonschema', b'{}')
        channel = writer.register_channel('/json', 'json', schema)
        writer.add_message(channel, log_time=1, data=b'{}', publish_time=1)
        writer.finish()
    reader = BagReader(path)
    metadata = reader.topic_metadata['/json']
    assert (metadata.type_name, metadata.definition, metadata.definition_encoding,
            metadata.serialization_format) == ('Thing', '{}', 'jsonschema', 'json')
    record, = reader.messages()
    assert (record.data, record.log_time_ns) == (b'{}', 1)
    with pytest.raises(BagError, match="invalid message type name 'Thing'"):
        record.message()


def test_qos_yaml_from_bag_parses_to_profiles(mixed_bag):
    reader = BagReader(mixed_bag[0])
    profile, = qos_profiles_from_yaml(reader.topic_metadata['/imu'].offered_qos_profiles)
    assert profile.depth == 7 and profile.lifespan.nanoseconds == 1_000_000_500


@pytest.mark.slow
@pytest.mark.parametrize('compression', ['ZSTD', 'LZ4'])
def test_reads_compressed_chunks_and_detects_their_damage(tmp_path, rng, compression):
    """rosbag2's zstd presets (and other writers) compress chunks."""
    from mcap.writer import CompressionType, Writer
    rows = _records('sensor_msgs/msg/Imu', rng, 1000)
    path = tmp_path / 'compressed.mcap'
    with open(path, 'wb') as stream:
        writer = Writer(stream, compression=CompressionType[compression])
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('sensor_msgs/msg/Imu', 'ros2msg',
                                        message_definition('sensor_msgs/msg/Imu').encode())
        channel = writer.register_channel('/imu', 'cdr', schema)
        for _, msg, log_time, publish_time in rows:
            writer.add_message(channel, log_time=log_time, data=serialize_message(msg),
                               publish_time=publish_time)
        writer.finish()
    assert [plain(m.message()) for m in BagReader(path).messages()] == [
        plain(msg) for _, msg, _, _ in rows]
    data = bytearray(path.read_bytes())
    data[len(data) // 3:len(data) // 3 + 16] = b'\xff' * 16
    path.write_bytes(bytes(data))
    with pytest.raises(BagError, match='compressed.mcap: .* could not be read .*--strict'):
        list(BagReader(path, strict=True).messages())
    with BagReader(path) as reader:
        assert len(rows) - len(list(reader.messages())) > 0
        assert 'does not decompress' in reader.notes[0] or 'CRC' in reader.notes[0]


@pytest.mark.slow
@pytest.mark.parametrize('layout', ['in_order', 'overlapping', 'equal_boundaries'])
def test_reading_gives_the_mcap_library_log_time_order(tmp_path, layout):
    """Chunk after chunk where chunks do not overlap, else through mcap's heap: the same order."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    rng = np.random.default_rng(5)
    count = 3000
    if layout == 'in_order':
        times = np.sort(rng.integers(0, 10**6, count))
    elif layout == 'overlapping':
        times = rng.integers(0, 10**6, count)
    else:
        times = np.repeat(np.arange(count // 100), 100)   # ties across chunk boundaries
    path = tmp_path / 'chunks.mcap'
    with open(path, 'wb') as stream:
        writer = Writer(stream, chunk_size=4096)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/Empty', 'ros2msg', b'')
        channels = [writer.register_channel(f'/t{k}', 'cdr', schema) for k in range(3)]
        for index, time in enumerate(times.tolist()):
            writer.add_message(channels[index % 3], log_time=time,
                               data=index.to_bytes(4, 'little') + bytes(20), publish_time=time)
        writer.finish()
    with open(path, 'rb') as stream:
        expected = [(channel.topic, message.data, message.log_time)
                    for _, channel, message in make_reader(stream).iter_messages()]
    with BagReader(path) as reader:
        got = [(record.topic, record.data, record.log_time_ns) for record in reader.messages()]
        some = [(record.topic, record.data, record.log_time_ns)
                for record in reader.messages(['/t0', '/t2'])]
    assert got == expected
    assert some == [message for message in expected if message[0] != '/t1']


def _chunks_of(data):
    from mcap.records import Chunk
    return [record for record in StreamReader(io.BytesIO(data), emit_chunks=True).records
            if isinstance(record, Chunk)]


@pytest.mark.parametrize('compression', ['ZSTD', 'LZ4', 'NONE'])
def test_chunk_records_are_the_mcap_librarys_messages(rng, compression):
    """Every Message of each chunk, in file order, as the library's breakup_chunk reads it."""
    from mcap.records import Message
    from mcap.stream_reader import breakup_chunk
    from mcap.writer import CompressionType, Writer
    from rotation_node.bag.reading.mcap_reader import chunk_data, chunk_records
    stream = io.BytesIO()
    writer = Writer(stream, compression=CompressionType[compression], chunk_size=4096)
    writer.start()
    schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
    channels = [writer.register_channel('/a', 'cdr', schema)]
    for k in range(600):
        if k in (100, 350):   # channels in the middle of a chunk
            channels.append(writer.register_channel(f'/c{k}', 'cdr', schema))
        writer.add_message(channels[int(rng.integers(len(channels)))],
                           log_time=int(rng.integers(0, 2**64, dtype=np.uint64)),
                           data=bytes(int(rng.integers(0, 100))), publish_time=2**64 - 1 - k,
                           sequence=k)
    writer.finish()
    data = stream.getvalue()
    chunks = _chunks_of(data)
    assert len(chunks) > 5
    bodies = [data[offset + 9:] for offset in _chunk_offsets(data)]
    for chunk, body in zip(chunks, bodies):
        compression_name, records = chunk_data(body)
        assert compression_name == chunk.compression
        headers, starts, definitions, damage = chunk_records(records)
        assert damage is None
        expected = [r for r in breakup_chunk(chunk, validate_crc=True) if isinstance(r, Message)]
        assert [(int(h['channel_id']), int(h['sequence']), int(h['log_time']),
                 int(h['publish_time']), records[start:start + int(h['length']) - 22])
                for h, start in zip(headers, starts)] == [
            (m.channel_id, m.sequence, m.log_time, m.publish_time, m.data) for m in expected]


def _chunk_offsets(data):
    """Offsets of the Chunk records of an MCAP file, by a walk of its records."""
    import struct
    position, offsets = 8, []
    while position < len(data) - 8:
        opcode, length = struct.unpack_from('<BQ', data, position)
        if opcode == 0x06:
            offsets.append(position)
        position += 9 + length
    return offsets


def test_chunk_records_skip_unknown_records_and_stop_at_damage():
    import struct
    import zlib

    from rotation_node.bag.reading.mcap_reader import _Damage, chunk_data, chunk_records

    def message(channel_id, log_time, data):
        return struct.pack('<BQHIQQ', 0x05, 22 + len(data), channel_id, 0, log_time, 7) + data

    def chunk(data, crc=None, size=None, compression=b''):
        return struct.pack('<QQQII', 0, 0, len(data) if size is None else size,
                           zlib.crc32(data) if crc is None else crc,
                           len(compression)) + compression + struct.pack('<Q', len(data)) + data

    unknown = struct.pack('<BQ', 0x90, 3) + b'xyz'
    data = message(1, 5, b'first') + unknown + message(2, 3, b'') + message(1, 4, b'third')
    _, stored = chunk_data(chunk(data))
    headers, starts, _, damage = chunk_records(stored)
    assert damage is None
    assert [(int(h['channel_id']), int(h['log_time']),
             stored[start:start + int(h['length']) - 22])
            for h, start in zip(headers, starts)] == [(1, 5, b'first'), (2, 3, b''),
                                                      (1, 4, b'third')]
    # The records before the damage are kept; what stopped the walk is said.
    for damaged, reason in [(data[:-2], 'ends at'), (data + b'\x05\0', 'cut short'),
                            (data[:30] + bytes(64) + data[30:], 'opcode 0'),
                            (data + struct.pack('<BQ', 0x05, 21) + bytes(21), 'is 21 bytes')]:
        headers, _, _, damage = chunk_records(damaged)
        kept = {'opcode 0': 1, 'ends at': 2}.get(reason, 3)
        assert reason in damage and len(headers) == kept
    with pytest.raises(_Damage, match='fails its CRC'):
        chunk_data(chunk(data, crc=zlib.crc32(data) ^ 1))
    with pytest.raises(_Damage, match='unknown compression'):
        chunk_data(chunk(data, compression=b'brotli'))
    with pytest.raises(_Damage, match='runs past the chunk'):
        chunk_data(chunk(data)[:-1])
