"""
Tests of rotation_node.bag.writing.writer: rosbag2 layout, compression, crash safety, full disks.

Bags are read back with independent readers: ``rosbags`` (rosbag2 directories
and MCAP files) and the ``mcap`` library's linear stream reader (unfinished
files).
"""
import os
import pathlib

from fault_helpers import can_mount, FULL_DISKS, linear_scan, small_disk, small_filesystem
from mcap.data_stream import RecordBuilder
from mcap.reader import make_reader
import pytest
from rosbags.highlevel import AnyReader
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing import part_output as output_module
from rotation_node.bag.writing import writer as writer_module
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.errors import BagError, DiskFullError
from std_msgs.msg import String
import yaml

T0 = 1_700_000_000_000_000_000


def _strings(rng, count, size=200):
    """``count`` (topic, String, log time) with random payloads of about ``size`` bytes."""
    letters = 'abcdefghijklmnopqrstuvwxyz0123456789'
    return [('/text' if k % 3 else '/other',
             String(data=''.join(rng.choice(list(letters), size))), T0 + 1000 * k)
            for k in range(count)]


def _write(path, messages, **kwargs):
    with BagWriter(path, **kwargs) as writer:
        for topic, msg, stamp in messages:
            writer.write(topic, msg, stamp)


def _rosbags_messages(path):
    with AnyReader([pathlib.Path(path)]) as reader:
        return [(connection.topic, timestamp, bytes(data))
                for connection, timestamp, data in reader.messages()]


def _chunk_compressions(path):
    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
        return {index.compression for index in summary.chunk_indexes}


@pytest.mark.parametrize('compression, stored', [('zstd', 'zstd'), ('lz4', 'lz4'),
                                                 ('none', '')])
def test_directory_bag_as_ros2_bag_record_writes_it(tmp_path, rng, compression, stored):
    path = tmp_path / 'run1'
    messages = _strings(rng, 300)
    _write(path, messages, compression=compression)
    assert sorted(os.listdir(path)) == ['metadata.yaml', 'run1_0.mcap']
    assert not os.path.exists(f'{path}.part')
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert (info['version'], info['storage_identifier']) == (9, 'mcap')
    assert info['relative_file_paths'] == ['run1_0.mcap']
    assert info['files'][0]['path'] == 'run1_0.mcap'
    assert info['message_count'] == info['files'][0]['message_count'] == 300
    assert info['duration']['nanoseconds'] == messages[-1][2] - messages[0][2]
    assert {t['topic_metadata']['name']: t['message_count']
            for t in info['topics_with_message_count']} == {'/text': 200, '/other': 100}
    assert _chunk_compressions(path / 'run1_0.mcap') == {stored}
    # rosbags reads the directory through metadata.yaml: every message, byte for byte.
    from_rosbags = _rosbags_messages(path)
    assert [(t, s) for t, s, _ in from_rosbags] == [(t, s) for t, _, s in messages]
    with BagReader(path / 'run1_0.mcap') as reader:
        ours = [(r.topic, r.log_time_ns, r.data) for r in reader.messages()]
    assert ours == from_rosbags
    assert [(t, s, d) for t, s, _, d in linear_scan(path / 'run1_0.mcap')] == from_rosbags


def test_path_ending_in_mcap_is_a_single_file(tmp_path, rng):
    path = tmp_path / 'one.mcap'
    _write(path, _strings(rng, 10))
    assert os.listdir(tmp_path) == ['one.mcap']
    assert len(_rosbags_messages(path)) == 10


def test_unknown_compression_is_refused(tmp_path):
    with pytest.raises(BagError, match="compression must be one of zstd, lz4, none, got 'gz'"):
        BagWriter(tmp_path / 'x.mcap', compression='gz')
    assert os.listdir(tmp_path) == []


def test_same_messages_give_the_same_bytes_over_many_chunks(tmp_path, rng, monkeypatch):
    monkeypatch.setattr(writer_module, 'CHUNK_SIZE', 8192)
    messages = _strings(rng, 400)
    for name in ('a', 'b'):
        os.mkdir(tmp_path / name)
        _write(tmp_path / name / 'same.mcap', messages)
    with open(tmp_path / 'a' / 'same.mcap', 'rb') as stream:
        assert len(make_reader(stream).get_summary().chunk_indexes) >= 8
    assert ((tmp_path / 'a' / 'same.mcap').read_bytes()
            == (tmp_path / 'b' / 'same.mcap').read_bytes())


def test_bag_is_written_as_part_and_every_chunk_is_readable_before_close(tmp_path, rng,
                                                                         monkeypatch):
    monkeypatch.setattr(writer_module, 'CHUNK_SIZE', 4096)
    path = tmp_path / 'live.mcap'
    messages = _strings(rng, 200)
    writer = BagWriter(path)
    for topic, msg, stamp in messages[:150]:
        writer.write(topic, msg, stamp)
    assert not path.exists()
    recovered = linear_scan(f'{path}.part')
    # Everything up to the last full chunk, in order, byte-identical.
    assert len(recovered) == writer.message_count > 100
    assert [(t, s) for t, s, _, _ in recovered] == [(t, s) for t, _, s in
                                                    messages[:len(recovered)]]
    for topic, msg, stamp in messages[150:]:
        writer.write(topic, msg, stamp)
    writer.close()
    assert os.listdir(tmp_path) == ['live.mcap']
    assert len(_rosbags_messages(path)) == 200


def test_live_recording_writes_a_chunk_once_a_period(tmp_path, monkeypatch):
    clock = [100.0]
    monkeypatch.setattr(writer_module.time, 'monotonic', lambda: clock[0])
    writer = BagWriter(tmp_path / 'slow.mcap', chunk_period_s=1.0)
    writer.write('/text', String(data='first'), T0)
    writer.flush_if_due()
    assert writer.message_count == 0
    clock[0] += 1.0
    writer.flush_if_due()
    assert writer.message_count == 1
    assert [m[:2] for m in linear_scan(writer.part_path)] == [('/text', T0)]
    writer.abort()
    assert os.listdir(tmp_path) == []


def test_failure_removes_the_part_unless_keep_unfinished(tmp_path, rng):
    messages = _strings(rng, 50)
    with pytest.raises(RuntimeError):
        with BagWriter(tmp_path / 'gone') as writer:
            for topic, msg, stamp in messages:
                writer.write(topic, msg, stamp)
            raise RuntimeError('stop')
    assert os.listdir(tmp_path) == []
    with pytest.raises(RuntimeError):
        with BagWriter(tmp_path / 'kept.mcap', keep_unfinished=True) as writer:
            for topic, msg, stamp in messages:
                writer.write(topic, msg, stamp)
            writer.flush()
            raise RuntimeError('stop')
    assert os.listdir(tmp_path) == ['kept.mcap.part']
    assert len(linear_scan(tmp_path / 'kept.mcap.part')) == 50


@pytest.mark.slow
@pytest.mark.parametrize('disk', FULL_DISKS)
def test_full_disk_keeps_a_valid_bag_of_what_was_written(tmp_path, rng, monkeypatch, disk):
    limit = 256 * 1024
    monkeypatch.setattr(writer_module, 'CHUNK_SIZE', 16 * 1024)
    messages = _strings(rng, 4000)
    with small_disk(disk, tmp_path / 'small', limit, monkeypatch) as directory:
        path = directory / 'full'
        writer = BagWriter(path, compression='none', keep_unfinished=True)
        with pytest.raises(DiskFullError) as caught:
            for topic, msg, stamp in messages:
                writer.write(topic, msg, stamp)
        kept = caught.value.kept
        assert kept == writer.message_count and 0 < kept < len(messages)
        assert f'kept {kept} messages' in str(caught.value)
        writer.close()
        assert sorted(os.listdir(path)) == ['full_0.mcap', 'metadata.yaml']
        recovered = _rosbags_messages(path)
        assert len(recovered) == kept
        assert [(t, s) for t, s, _ in recovered] == [(t, s) for t, _, s in messages[:kept]]
        assert os.path.getsize(path / 'full_0.mcap') <= limit


def test_output_and_part_are_exclusive(tmp_path):
    path = tmp_path / 'out.mcap'
    first = BagWriter(path)
    with pytest.raises(BagError, match=r'out.mcap.part exists: another process is writing'):
        BagWriter(path)
    with pytest.raises(BagError, match=r'out.mcap.part exists'):
        BagWriter(path, overwrite=True)
    # Another writer finished the same output meanwhile: closing must not replace it.
    path.write_bytes(b'theirs')
    with pytest.raises(BagError, match='was created by another process while this one wrote'):
        first.close()
    assert path.read_bytes() == b'theirs'
    assert os.listdir(tmp_path) == ['out.mcap']


@pytest.mark.parametrize('name', ['bag', 'bag.mcap'])
def test_overwrite_replaces_a_file_or_directory_atomically(tmp_path, rng, name):
    path = tmp_path / name
    _write(path, _strings(rng, 5))
    messages = _strings(rng, 7)
    with pytest.raises(BagError, match='already exists'):
        BagWriter(path)
    _write(path, messages, overwrite=True)
    assert len(_rosbags_messages(path)) == 7
    assert os.listdir(tmp_path) == [name]


def test_metadata_yaml_qos_profiles_are_read_by_rosbags(tmp_path):
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosbags.interfaces import QosDurability, QosReliability
    from rotation_node.bag.records import TopicMetadata
    from rotation_node.wire.qos import qos_profiles_yaml

    offered = QoSProfile(depth=7, reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         deadline=Duration(seconds=2, nanoseconds=5))
    path = tmp_path / 'qos'
    with BagWriter(path) as writer:
        writer.add_topic(TopicMetadata('/text', 'std_msgs/msg/String',
                                       qos_profiles_yaml([offered])))
        writer.write('/text', String(data='x'), T0)
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    stored, = info['topics_with_message_count'][0]['topic_metadata']['offered_qos_profiles']
    assert (stored['reliability'], stored['durability'], stored['deadline']) == (
        'best_effort', 'transient_local', {'sec': 2, 'nsec': 5})
    with AnyReader([pathlib.Path(path)]) as reader:
        qos, = reader.connections[0].ext.offered_qos_profiles
    assert (qos.reliability, qos.durability, qos.depth) == (
        QosReliability.BEST_EFFORT, QosDurability.TRANSIENT_LOCAL, 7)
    assert (qos.deadline.sec, qos.deadline.nsec) == (2, 5)


@pytest.mark.slow
@pytest.mark.skipif(not can_mount(), reason='needs a tmpfs mount (root)')
@pytest.mark.parametrize('keep_unfinished', [True, False])
def test_full_disk_without_reservation_is_a_write_error(tmp_path, rng, monkeypatch,
                                                        keep_unfinished):
    """On a file system without fallocate a full disk shows as a failed write."""
    monkeypatch.setattr(output_module, 'allocate', lambda descriptor, offset, length: False)
    monkeypatch.setattr(writer_module, 'CHUNK_SIZE', 16 * 1024)
    messages = _strings(rng, 4000)
    with small_filesystem(tmp_path / 'small', 256 * 1024) as small:
        writer = BagWriter(small / 'full', compression='none', keep_unfinished=keep_unfinished)
        with pytest.raises(BagError, match='cannot write output .*full: No space left on '
                                           'device') as caught:
            with writer:
                for topic, msg, stamp in messages:
                    writer.write(topic, msg, stamp)
        if keep_unfinished:
            assert 'what was written is in' in str(caught.value)
            assert os.listdir(small) == ['full.part']
            recovered = linear_scan(small / 'full.part' / 'full_0.mcap')
            assert 0 < len(recovered) < len(messages)
            assert [(t, s) for t, s, _, _ in recovered] == [
                (t, s) for t, _, s in messages[:len(recovered)]]
        else:
            assert os.listdir(small) == []


def _serialized(rng, count):
    """``count`` (topic, type name, CDR data, log time, publish time) on three topics."""
    from rclpy.serialization import serialize_message
    messages = []
    for k, (topic, msg, stamp) in enumerate(_strings(rng, count, size=int(rng.integers(50, 400)))):
        if k % 7 == 0:
            topic = '/third'
        messages.append((topic, 'std_msgs/msg/String', serialize_message(msg), stamp,
                         stamp - 500))
    return messages


@pytest.mark.slow
@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_block_writes_the_bytes_of_message_by_message(tmp_path, rng, monkeypatch, compression):
    monkeypatch.setattr(writer_module, 'CHUNK_SIZE', 8192)
    messages = _serialized(rng, 1500)
    paths = []
    for name, block in (('each', None), ('blocks', 97), ('one block', len(messages))):
        os.mkdir(tmp_path / name)
        paths.append(tmp_path / name / 'bag.mcap')
        with BagWriter(paths[-1], compression=compression) as writer:
            writer.add_topic(TopicMetadata('/other', 'std_msgs/msg/String'))
            if block is None:
                for message in messages:
                    writer.write_serialized(*message)
            else:
                for start in range(0, len(messages), block):
                    # '/text' and '/third' are registered by the first block, as they come.
                    writer.write_serialized_block(messages[start:start + block])
                writer.write_serialized_block([])
    first = paths[0].read_bytes()
    assert all(path.read_bytes() == first for path in paths[1:])
    with open(paths[0], 'rb') as stream:
        assert len(make_reader(stream).get_summary().chunk_indexes) > 20
    assert [(t, log, publish, d) for t, log, publish, d in linear_scan(paths[0])] == [
        (t, log, publish, d) for t, _, d, log, publish in messages]


@pytest.mark.parametrize('bad, error', [
    ((-1, 5), 'log_time_ns must be in'),
    ((5, 1.5), 'publish_time_ns must be an integer number of nanoseconds, got 1.5'),
    ((2**64, 5), 'log_time_ns must be in'),
    ((5, None), None),
])
def test_block_stops_where_message_by_message_stops(tmp_path, rng, bad, error):
    messages = _serialized(rng, 50)
    topic, type_name, data, _, _ = messages[30]
    messages[30] = (topic, type_name, data, *bad)
    with BagWriter(tmp_path / 'bad.mcap') as writer:
        if error is None:        # publish time None: the log time, as write_serialized
            writer.write_serialized_block(messages)
        else:
            with pytest.raises(BagError, match=error):
                writer.write_serialized_block(messages)
            with pytest.raises(BagError, match='holds std_msgs/msg/String .* cannot write'):
                writer.write_serialized_block([(topic, 'std_msgs/msg/Int32', b'', 1, 1)])
    written = linear_scan(tmp_path / 'bad.mcap')
    assert len(written) == (50 if error is None else 30)
    if error is None:
        assert written[30][1:3] == (5, 5)


def test_live_recording_writes_a_chunk_every_period(tmp_path, monkeypatch):
    """Messages at 100 Hz, ``flush_if_due`` every 0.1 s: one chunk of each second, on disk."""
    clock = [100.0]
    monkeypatch.setattr(writer_module.time, 'monotonic', lambda: clock[0])
    writer = BagWriter(tmp_path / 'live.mcap', chunk_period_s=1.0, keep_unfinished=True)
    for k in range(350):
        writer.write('/text', String(data=str(k)), T0 + k * 10_000_000)
        clock[0] = 100.0 + (k + 1) / 100
        if k % 10 == 9:
            writer.flush_if_due()
            flushed = (k + 1) // 100 * 100
            assert len(linear_scan(writer.part_path)) == writer.message_count == flushed
    writer.close()
    with open(tmp_path / 'live.mcap', 'rb') as stream:
        summary = make_reader(stream, validate_crcs=True).get_summary()
    spans = [(index.message_start_time - T0, index.message_end_time - T0)
             for index in summary.chunk_indexes]
    assert spans == [(s * 10**9, s * 10**9 + 990_000_000) for s in range(3)] + [
        (3 * 10**9, 3_490_000_000)]


@pytest.mark.slow
@pytest.mark.parametrize('compression', ['zstd', 'none'])
def test_reservations_cover_every_chunk_and_the_close(tmp_path, rng, monkeypatch, compression):
    """Each reservation covers the chunk written after it and everything written to close."""
    monkeypatch.setattr(writer_module, 'CHUNK_SIZE', 2048)
    monkeypatch.setattr(writer_module, '_SUMMARY_FIXED', 0)
    reservations = []

    def reserve(self, length):
        reservations.append((self.stream.tell(), length))

    monkeypatch.setattr(output_module.BagOutput, 'reserve', reserve)
    # Many channels, schemas and chunks: the per-chunk and per-channel sizes add up.
    messages = [(f'/topic_{k % 40}', 'std_msgs/msg/String', data, log, publish)
                for k, (_, _, data, log, publish) in enumerate(_serialized(rng, 3000))]
    path = tmp_path / 'reserved'
    with BagWriter(path, compression=compression) as writer:
        for k, message in enumerate(messages):
            writer.write_serialized(*message)
            if k == 1500:
                writer.add_topic(TopicMetadata('/late', 'std_msgs/msg/Float64MultiArray'))
    size = os.path.getsize(path / 'reserved_0.mcap') + os.path.getsize(path / 'metadata.yaml')
    assert len(reservations) > 100
    for (offset, length), (next_offset, _) in zip(reservations, reservations[1:]):
        assert next_offset <= offset + length
    offset, length = reservations[-1]
    assert size <= offset + length
    # The summary's chunk indexes, reserved per chunk and per channel in it, on their own.
    with open(path / 'reserved_0.mcap', 'rb') as stream:
        chunk_indexes = make_reader(stream).get_summary().chunk_indexes
    builder = RecordBuilder()
    for index in chunk_indexes:
        index.write(builder)
    entries = sum(len(index.message_index_offsets) for index in chunk_indexes)
    assert builder.count <= (writer_module._SUMMARY_PER_CHUNK * len(chunk_indexes)
                             + writer_module._SUMMARY_PER_CHANNEL_IN_CHUNK * entries)
