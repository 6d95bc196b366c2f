"""
Tests of rotation_node.bag.reading.reader: every bag a ROS user has, read as one stream.

The bags are written here by independent writers (the rosbags package for
rosbag2 directories with mcap and sqlite3 storage, split, each compression
mode; the mcap library for unfinished recordings and odd schemas) from
messages serialized by rclpy. Every message read must be byte-identical to
what was written, with its log time; the rosbags reader reads the same bags
as a second opinion; converted values are checked against scipy.
"""
import os
import sqlite3
import subprocess

from bag_helpers import (
    file_snapshot, imu_messages, interleaved, main_in, random_message, rosbags_rows,
    serialized_rows, write_rosbag2, write_split_rosbag2)
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
import numpy as np
import pytest
from ros_harness import script
from rosbags.typesys import get_typestore, Stores
from rotation_node.bag.cli import main
from rotation_node.bag.convert import convert
from rotation_node.bag.reading.reader import open_bag
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters
from rotation_node.wire.message_types import message_definition
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import JointState
import zstandard

PARAMS = NodeParameters(input_type='imu', outputs=('euler', 'matrix'), euler_sequence='ZYX')
PARAMS_YAML = """rotation_node:
  ros__parameters:
    input_type: imu
    outputs: [euler, matrix]
    euler: {sequence: ZYX}
"""
LAYOUTS = [('mcap', None), ('mcap', 'file'), ('mcap', 'message'), ('mcap', 'storage'),
           ('sqlite3', None), ('sqlite3', 'file'), ('sqlite3', 'message')]
LAYOUT_IDS = [f'{storage}-{mode or "plain"}' for storage, mode in LAYOUTS]


@pytest.fixture
def rows(rng):
    """Return rows of an Imu topic and a JointState topic (copied unchanged), interleaved."""
    joints = []
    for i in range(40):
        msg = random_message(JointState, rng)
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 2_500_000 + i * 25_000_000
        joints.append(msg)
    return interleaved(serialized_rows('/imu', imu_messages(rng, 120)),
                       serialized_rows('/joints', joints, log_offset_ns=7))


def _read(path, **options):
    """``[(topic, data, log time, publish time)]`` and the bag's attributes."""
    with open_bag(path, **options) as bag:
        records = [(m.topic, m.data, m.log_time_ns, m.publish_time_ns) for m in bag.messages()]
        return records, bag


def _expected(rows):
    return [(topic, data, log_time, log_time) for topic, _, data, log_time in rows]


def _storage_files(path):
    return sorted(name for name in os.listdir(path) if name != 'metadata.yaml')


@pytest.mark.parametrize('storage, mode', LAYOUTS, ids=LAYOUT_IDS)
def test_rosbag2_directory_and_its_storage_file_read_byte_for_byte(tmp_path, rows, storage,
                                                                   mode):
    path = write_rosbag2(tmp_path / 'bag', rows, storage=storage, compression=mode)
    records, bag = _read(path)
    assert records == _expected(rows)
    assert [(t, d, lt) for t, d, lt, _ in records] == rosbags_rows(path)
    assert bag.topics == {'/imu': 'sensor_msgs/msg/Imu', '/joints': 'sensor_msgs/msg/JointState'}
    assert bag.message_counts == {'/imu': 120, '/joints': 40}
    assert bag.compression == ('none' if mode is None else 'zstd')
    assert bag.recovered is None and bag.notes == []
    # The definition as the writer stored it.
    assert bag.topic_metadata['/imu'].definition == get_typestore(
        Stores.ROS2_JAZZY).generate_msgdef('sensor_msgs/msg/Imu', ros_version=2)[0]
    file_records, file_bag = _read(path / _storage_files(path)[0])
    if mode == 'message':   # a lone storage file does not say it is message-compressed
        assert file_records == records
    else:
        assert file_records == records and file_bag.compression == bag.compression


@pytest.mark.slow
@pytest.mark.parametrize('storage, mode', LAYOUTS, ids=LAYOUT_IDS)
def test_split_bag_is_one_stream_and_converts_as_unsplit(tmp_path, rows, storage, mode):
    split = write_split_rosbag2(tmp_path / 'split', rows, 3, storage=storage, compression=mode)
    assert len(_storage_files(split)) == 3
    assert rosbags_rows(split) == [(t, d, lt) for t, _, d, lt in rows]   # the layout is sound
    records, bag = _read(split)
    assert records == _expected(rows) and bag.description.startswith(
        f'rosbag2 directory ({storage}, 3 files')
    whole = write_rosbag2(tmp_path / 'whole', rows, storage=storage, compression=mode)
    convert(split, tmp_path / 'from_split.mcap', PARAMS)
    convert(whole, tmp_path / 'from_whole.mcap', PARAMS)
    from_split, _ = _read(tmp_path / 'from_split.mcap')
    assert from_split == _read(tmp_path / 'from_whole.mcap')[0]
    _check_against_scipy(from_split, rows)


def _check_against_scipy(records, rows, publish_offset=0):
    """Check copied topics byte-identical, /imu/euler and /imu/matrix equal to scipy's."""
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64MultiArray
    by_topic = {}
    for topic, data, log_time, publish_time in records:
        by_topic.setdefault(topic, []).append((data, log_time, publish_time))
    for topic in ('/imu', '/joints'):
        assert by_topic[topic] == [(d, lt, lt - publish_offset)
                                   for t, _, d, lt in rows if t == topic]
    inputs = [deserialize_message(d, Imu) for t, _, d, _ in rows if t == '/imu']
    rotations = Rotation.from_quat([[m.orientation.x, m.orientation.y, m.orientation.z,
                                     m.orientation.w] for m in inputs])
    euler = [deserialize_message(d, Vector3Stamped) for d, _, _ in by_topic['/imu/euler']]
    matrix = [deserialize_message(d, Float64MultiArray) for d, _, _ in by_topic['/imu/matrix']]
    assert [m.header for m in euler] == [m.header for m in inputs]
    assert [lt for _, lt, _ in by_topic['/imu/euler']] == [
        lt for t, _, _, lt in rows if t == '/imu']
    angles = np.array([[m.vector.x, m.vector.y, m.vector.z] for m in euler])
    wrapped = np.angle(np.exp(1j * (angles - rotations.as_euler('ZYX'))))
    assert np.abs(wrapped).max() < 1e-12
    assert np.abs(np.array([m.data for m in matrix]).reshape(-1, 3, 3)
                  - rotations.as_matrix()).max() < 1e-14


def test_lz4_and_zstd_chunked_mcap_files(tmp_path, rows):
    for compression in ('LZ4', 'ZSTD'):
        path = tmp_path / f'{compression}.mcap'
        _mcap_file(path, rows, compression=CompressionType[compression])
        records, bag = _read(path)
        assert records == [(t, d, lt, lt - 5) for t, _, d, lt in rows]
        assert bag.compression == compression.lower()


def _mcap_file(path, rows, *, compression=CompressionType.NONE, chunk_size=1024 * 1024,
               finish=True, schemas=None):
    """Write rows with the mcap library; returns the (file size, messages) after each chunk."""
    schemas = schemas or {}
    boundaries = []
    with open(path, 'wb') as stream:
        writer = Writer(stream, compression=compression, chunk_size=chunk_size)
        writer.start(profile='ros2', library='test')
        channels = {}
        for count, (topic, type_name, data, log_time) in enumerate(rows, 1):
            if topic not in channels:
                name, encoding, text, message_encoding = schemas.get(topic) or (
                    type_name, 'ros2msg', message_definition(type_name), 'cdr')
                schema = writer.register_schema(name, encoding, text.encode())
                channels[topic] = writer.register_channel(
                    topic, message_encoding, schema,
                    metadata={'offered_qos_profiles': '', 'topic_type_hash': f'hash of {topic}'})
            before = stream.tell()
            writer.add_message(channels[topic], log_time=log_time, data=data,
                               publish_time=log_time - 5)
            if stream.tell() != before:
                boundaries.append((stream.tell(), count))
        if finish:
            writer.finish()
        else:
            stream.flush()
    return boundaries


def test_unfinished_recording_recovers_every_complete_chunk(tmp_path, rows, capsys):
    """A recording killed mid-way (no summary, no footer): every chunk written is read."""
    path = tmp_path / 'killed.mcap'
    boundaries = _mcap_file(path, rows, chunk_size=2000, finish=False)
    assert len(boundaries) > 5
    data = path.read_bytes()
    for (end, count), (next_end, _) in zip(boundaries[2:5], boundaries[3:6]):
        cut = tmp_path / f'cut{count}.mcap'
        cut.write_bytes(data[:(end + next_end) // 2])   # in the middle of the next chunk
        records, bag = _read(cut)
        assert bag.recovered == count == len(records)
        assert records == [(t, d, lt, lt - 5) for t, _, d, lt in rows[:count]]
        assert bag.notes == [f'{cut}: unfinished recording, recovered {count} messages']
        with pytest.raises(BagError, match='unfinished recording .* refused'):
            open_bag(cut, strict=True)
    # The command line says so on one line and converts what was recovered.
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    status = main(['convert', str(path), str(tmp_path / 'out.mcap'), '--params',
                   str(tmp_path / 'params.yaml')])
    stderr = capsys.readouterr().err
    assert status == 0
    assert f'{path}: unfinished recording, recovered {boundaries[-1][1]} messages' in stderr
    out, _ = _read(tmp_path / 'out.mcap')
    _check_against_scipy(out, rows[:boundaries[-1][1]], publish_offset=5)


def test_directory_without_metadata_is_an_unfinished_recording(tmp_path, rows):
    split = write_split_rosbag2(tmp_path / 'split', rows, 2)
    (split / 'metadata.yaml').unlink()
    records, bag = _read(split)
    assert records == _expected(rows)
    assert bag.notes == [f'{split}: unfinished recording, recovered {len(rows)} messages '
                         '(no metadata.yaml)']
    with pytest.raises(BagError, match='no metadata.yaml.*refused'):
        open_bag(split, strict=True)


def test_odd_schemas_matter_only_for_converted_topics(tmp_path, rows, rng):
    """Schema encoding 'unknown', a short type name, another serialization: copied as stored."""
    odd = [('/custom', 'my_msgs/msg/Custom', b'\x00\x01\x00\x00\x2a\x00\x00\x00', 10),
           ('/short', 'test_msgs/BasicTypes', b'\x00\x01\x00\x00\x01\x00\x00\x00', 11),
           ('/json', 'Thing', b'{"a": 1}', 12)]
    schemas = {'/custom': ('my_msgs/msg/Custom', 'unknown', '', 'cdr'),
               '/short': ('test_msgs/BasicTypes', 'ros2msg', 'bool bool_value\n', 'cdr'),
               '/json': ('Thing', 'jsonschema', '{"type": "object"}', 'json')}
    source = tmp_path / 'odd.mcap'
    _mcap_file(source, odd + rows, schemas=schemas)
    convert(source, tmp_path / 'out.mcap', PARAMS)
    with open(source, 'rb') as a, open(tmp_path / 'out.mcap', 'rb') as b:
        before, after = make_reader(a), make_reader(b)
        originals = {c.topic: (c, before.get_summary().schemas[c.schema_id])
                     for c in before.get_summary().channels.values()}
        copies = {c.topic: (c, after.get_summary().schemas[c.schema_id])
                  for c in after.get_summary().channels.values()}
        for topic in schemas:
            (channel, schema), (copy, copy_schema) = originals[topic], copies[topic]
            assert (copy.message_encoding, copy.metadata) == (channel.message_encoding,
                                                              channel.metadata)
            assert (copy_schema.name, copy_schema.encoding, copy_schema.data) == (
                schema.name, schema.encoding, schema.data)
        copied = [(c.topic, m.data, m.log_time, m.publish_time)
                  for _, c, m in after.iter_messages(topics=list(schemas))]
    assert copied == [(t, d, lt, lt - 5) for t, _, d, lt in odd]
    # Converting one of them is what fails, naming it.
    with pytest.raises(BagError, match='topic /custom .* is my_msgs/msg/Custom, but input_type'):
        convert(source, tmp_path / 'again.mcap', PARAMS, topics=['/custom'])


def test_format_errors_are_bag_errors_and_bugs_are_not(tmp_path, rows, monkeypatch):
    """Only what the format libraries raise for bad data becomes a BagError."""
    from rotation_node.bag.reading import mcap_reader as mcap_io
    path = tmp_path / 'bag.mcap'
    _mcap_file(path, rows)

    def broken_chunk(*args, **kwargs):
        raise KeyError('a programming error')

    monkeypatch.setattr(mcap_io, 'chunk_records', broken_chunk)
    with open_bag(path) as bag, pytest.raises(KeyError, match='a programming error'):
        list(bag.messages())


def _sqlite_without_tables(path):
    with sqlite3.connect(path) as database:
        database.execute('CREATE TABLE notes (text TEXT)')
    database.close()


BAD_INPUTS = {
    'empty.mcap': (lambda path: path.write_bytes(b''), 'empty.mcap: empty file (0 bytes)'),
    'notes.txt': (lambda path: path.write_text('just some text\n' * 20),
                  'notes.txt: text file, not a bag'),
    'other.db3': (_sqlite_without_tables, 'other.db3: sqlite3 database without rosbag2 tables'),
    'old.bag': (lambda path: path.write_bytes(b'#ROSBAG V1.2\n' + bytes(range(256)) * 4),
                'old.bag: ROS 1 bag, version 1.2 (supported: 2.0)'),
    'text.mcap.zstd': (lambda path: path.write_bytes(zstandard.compress(b'hello\n' * 100)),
                       'text.mcap.zstd: zstd-compressed file that does not hold a bag '
                       '(it holds a text file)'),
    'plugin': (lambda path: (path.mkdir(), (path / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: cdr_file\n'
        '  relative_file_paths: [plugin_0.cdr]\n')),
        "plugin: rosbag2 storage plugin 'cdr_file' is not installed"),
    'killed.mcap': (None, 'killed.mcap: unfinished recording (no MCAP summary or footer)'),
    'lost': (lambda path: (path.mkdir(), (path / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n'
        '  relative_file_paths: [lost_0.mcap]\n')),
        'lost: storage file lost_0.mcap listed in metadata.yaml is missing'),
    'folder': (lambda path: (path.mkdir(), (path / 'readme.txt').write_text('hi\n')),
               'folder: directory without metadata.yaml or storage files'),
}


@pytest.mark.parametrize('name', BAD_INPUTS)
def test_bad_input_is_one_line_exit_1_nothing_written(tmp_path, capsys, rows, name):
    make, reason = BAD_INPUTS[name]
    path = tmp_path / name
    if make is None:
        _mcap_file(path, rows, chunk_size=2000, finish=False)
    else:
        make(path)
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    before = file_snapshot(tmp_path)
    for command in (['convert', name, 'out.mcap', '--params', 'params.yaml', '--strict'],
                    ['plot', name, '--topic', '/imu', '-o', 'out.png', '--strict']):
        status = main_in(tmp_path, command)
        lines = capsys.readouterr().err.splitlines()
        assert status == 1 and len(lines) == 1, lines
        assert lines[0].startswith(f'rotation_bag {command[0]}: error: ') and reason in lines[0]
        assert file_snapshot(tmp_path) == before


@pytest.mark.slow
def test_play_maps_invalid_topic_names_and_does_not_die(tmp_path, rows):
    """Play publishes /imu-raw as /imu_raw with a note, never InvalidTopicNameException."""
    renamed = [('/imu-raw' if t == '/imu' else t, *rest) for t, *rest in rows[:30]]
    path = write_rosbag2(tmp_path / 'bag', renamed)
    result = subprocess.run([script('rotation_bag'), 'play', str(path), '--rate', '1000'],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert f"{path}: topic '/imu-raw' is not a valid ROS 2 name; using /imu_raw" in result.stderr
    assert 'Traceback' not in result.stderr and 'Exception' not in result.stderr


@pytest.mark.slow
def test_relative_topic_names_stay_relative(tmp_path, rows, capsys):
    """``groundtruth`` (evo's example bag) is a name rclpy accepts: kept, outputs beside it."""
    relative = [('groundtruth' if t == '/imu' else t, *rest) for t, *rest in rows]
    path = write_rosbag2(tmp_path / 'bag', relative)
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    assert main_in(tmp_path, ['convert', 'bag', 'out.mcap', '--params', 'params.yaml',
                              '--topic', 'groundtruth']) == 0
    lines = capsys.readouterr().err.splitlines()
    assert not any('not a valid ROS 2 name' in line for line in lines), lines
    assert 'groundtruth: 120 messages -> groundtruth/euler, groundtruth/matrix: 240 messages' \
        in lines
    with open_bag(path) as bag:
        assert bag.renames == {} and bag.notes == []
    with open_bag(tmp_path / 'out.mcap') as bag:
        assert sorted(bag.topics) == ['/joints', 'groundtruth', 'groundtruth/euler',
                                      'groundtruth/matrix']
    capsys.readouterr()
    assert main_in(tmp_path, ['plot', 'out.mcap', '--topic', 'groundtruth/euler']) == 0
    assert capsys.readouterr().err.splitlines() == [
        'plotted 120 messages of groundtruth/euler to out_groundtruth_euler.png']
