"""
Tests of rotation_node.bag.reading.rosbag2_sqlite3: rosbag2 sqlite3 storage, damaged ones included.

The bags are written by the rosbags writer from messages serialized by rclpy and
damaged here with SQLite itself (a row whose ``data`` is TEXT, a topic name that
is not UTF-8) or by zeroing bytes of a page, as a disk does. Every damage must
end ``convert`` and ``plot`` with one line naming the file, the table and the
row, exit status 1, and nothing written; rosbags' own reader is the oracle of
what a good file holds.
"""
import os
import sqlite3
import subprocess

from bag_helpers import (
    file_snapshot, imu_messages, main_in, rosbags_rows, serialized_rows, write_rosbag2)
import pytest
from ros_harness import script
from rotation_node.bag.reading.reader import open_bag

PARAMS_YAML = """rotation_node:
  ros__parameters:
    input_type: imu
    outputs: [euler]
"""


@pytest.fixture
def bag(tmp_path, rng):
    """Return a rosbag2 sqlite3 directory of 300 Imu messages on /imu, and its rows."""
    rows = serialized_rows('/imu', imu_messages(rng, 300))
    return write_rosbag2(tmp_path / 'run', rows, storage='sqlite3'), rows


def _sql(path, statement, *arguments):
    with sqlite3.connect(path) as database:
        database.execute(statement, arguments)
    database.close()


def test_messages_are_what_rosbags_reads(bag):
    path, rows = bag
    with open_bag(path) as reader:
        read = [(m.topic, m.data, m.log_time_ns) for m in reader.messages()]
    assert read == rosbags_rows(path) == [(topic, data, time) for topic, _, data, time in rows]


@pytest.mark.parametrize('mode', ['message', 'file'])
def test_compression_is_described_also_without_metadata(tmp_path, rng, mode):
    """rosbag2's message and file compression, said by the files themselves."""
    rows = serialized_rows('/imu', imu_messages(rng, 20))
    path = write_rosbag2(tmp_path / 'run', rows, storage='sqlite3', compression=mode)
    storage_file, = [name for name in os.listdir(path) if name != 'metadata.yaml']
    with open_bag(path / storage_file) as bag:
        assert (bag.description, bag.compression) == (
            f'sqlite3 file (zstd {mode} compression)', 'zstd')
    (path / 'metadata.yaml').unlink()
    with open_bag(path) as bag:
        assert (bag.description, bag.compression) == (
            f'rosbag2 directory (sqlite3, 1 file, zstd {mode} compression)', 'zstd')
        assert [m.data for m in bag.messages()] == [data for _, _, data, _ in rows]


def _zeroed(path, data, *, page_header):
    """Zero 512 bytes: the header of the page that holds ``data``, or from 100 bytes before it."""
    content = bytearray(path.read_bytes())
    position = content.index(data)
    start = position - position % 4096 if page_header else position - 100
    content[start:start + 512] = bytes(512)
    path.write_bytes(bytes(content))


DAMAGES = {
    'TEXT data': (lambda path, rows: _sql(
        path, "UPDATE messages SET data = 'not a message' WHERE id = 12"),
        'run.db3 is corrupt: messages table, row id 12: data is TEXT, not a BLOB'),
    'INTEGER data': (lambda path, rows: _sql(
        path, 'UPDATE messages SET data = 42 WHERE id = 7'),
        'run.db3 is corrupt: messages table, row id 7: data is INTEGER, not a BLOB'),
    'REAL timestamp': (lambda path, rows: _sql(
        path, 'UPDATE messages SET timestamp = 1.5 WHERE id = 3'),
        'messages table, row id 3: timestamp 1.5 is not a time (an INTEGER >= 0 ns)'),
    'negative timestamp': (lambda path, rows: _sql(
        path, 'UPDATE messages SET timestamp = -5 WHERE id = 9'),
        'messages table, row id 9: timestamp -5 is not a time'),
    'topic name not UTF-8': (lambda path, rows: _sql(
        path, "UPDATE topics SET name = CAST(X'2F696D75FF' AS TEXT)"),
        'run.db3: cannot read rosbag2 sqlite3 storage: the topics or message_definitions '
        "table is damaged: UnicodeDecodeError: 'utf-8' codec can't decode byte 0xff"),
    'QoS profiles not a list': (lambda path, rows: _sql(
        path, "UPDATE topics SET offered_qos_profiles = '- 3'"),
        'the topics or message_definitions table is damaged'),
    # Not CDR: a message that cannot be decoded names the bag too.
    'truncated message': (lambda path, rows: _sql(
        path, 'UPDATE messages SET data = substr(data, 1, 20) WHERE id = 5'),
        'error: run: message on /imu at {} ns is not a valid sensor_msgs/msg/Imu'),
    # SQLite meets the damage when it opens the file (a page of the table)...
    'zeroed page header': (lambda path, rows: _zeroed(path, rows[200][2], page_header=True),
                           'run.db3: cannot read rosbag2 sqlite3 storage: database disk image '
                           'is malformed (messages table, after row id 19'),
    # ... or only when the messages reach it (rows).
    'zeroed rows': (lambda path, rows: _zeroed(path, rows[200][2], page_header=False),
                    'run.db3 is corrupt: messages table, after row id 19'),
}


@pytest.mark.parametrize('damage', DAMAGES)
def test_a_damaged_database_is_one_line_naming_the_row(tmp_path, capsys, bag, damage):
    path, rows = bag
    make, reason = DAMAGES[damage]
    make(path / 'run.db3', rows)
    reason = reason.format(rows[4][3])
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    before = file_snapshot(tmp_path)
    for command in (['convert', 'run', 'out.mcap', '--params', 'params.yaml'],
                    ['plot', 'run', '--topic', '/imu', '-o', 'out.png']):
        status = main_in(tmp_path, command)
        lines = capsys.readouterr().err.splitlines()
        assert status == 1 and len(lines) == 1, lines
        assert lines[0].startswith(f'rotation_bag {command[0]}: error: ') and reason in lines[0]
        assert file_snapshot(tmp_path) == before


@pytest.mark.slow
def test_play_stops_at_a_damaged_row_with_one_line(bag):
    """The row is reached while playing: one line, exit status 1, no traceback."""
    path, _ = bag
    _sql(path / 'run.db3', "UPDATE messages SET data = 'not a message' WHERE id = 12")
    result = subprocess.run([script('rotation_bag'), 'play', str(path), '--rate', '1000'],
                            capture_output=True, text=True, timeout=120)
    assert (result.returncode, result.stderr) == (1, (
        f'rotation_bag play: error: {path}/run.db3 is corrupt: messages table, row id 12: '
        'data is TEXT, not a BLOB\n'))


def test_rows_of_no_topic_are_a_note_or_with_strict_an_error(tmp_path, capsys, bag):
    """Rows whose topic_id is not a topic cannot be read: never lost without a word."""
    path, rows = bag
    _sql(path / 'run.db3', 'UPDATE messages SET topic_id = 99 WHERE id IN (18, 40)')
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    note = ('run/run.db3: 2 messages of the messages table name no topic (the first: row id 18, '
            'topic_id 99)')
    assert main_in(tmp_path, ['convert', 'run', 'out.mcap', '--params', 'params.yaml']) == 0
    lines = capsys.readouterr().err.splitlines()
    assert f'{note}, not read' in lines
    assert '/imu: 298 messages -> /imu/euler: 298 messages' in lines
    status = main_in(tmp_path, ['convert', 'run', 'strict.mcap', '--params', 'params.yaml',
                                '--strict'])
    assert status == 1 and capsys.readouterr().err.splitlines() == [
        f'rotation_bag convert: error: {note}; refused (--strict)']
    assert not (tmp_path / 'strict.mcap').exists()


def _rosbags_topics(path):
    """Return the topics rosbags' own sqlite3 reader reads, in this module's terms."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
    from bag_helpers import rosbags_qos_yaml
    encodings = {MessageDefinitionFormat.MSG: 'ros2msg', MessageDefinitionFormat.IDL: 'ros2idl',
                 MessageDefinitionFormat.NONE: None}
    reader = Sqlite3Reader(path)
    reader.open()
    try:
        return [(c.id, c.topic, c.msgtype, (encodings[c.msgdef.format], c.msgdef.data), c.digest,
                 c.msgcount, c.ext.serialization_format,
                 rosbags_qos_yaml(c.ext.offered_qos_profiles))
                for c in reader.connections], reader.metadata.message_count
    finally:
        reader.close()


QOS_PROFILES = [
    '',
    '- history: keep_last\n  depth: 10\n  reliability: best_effort\n  durability: volatile\n'
    '  deadline:\n    sec: 0\n    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n'
    '  liveliness: automatic\n  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n'
    '  avoid_ros_namespace_conventions: false',
    # Humble's numbers, an unknown number and name, durations of "infinity", two profiles.
    '- history: 3\n  depth: 0\n  reliability: 1\n  durability: 9\n'
    '  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n'
    '  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: sometimes\n'
    '  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n'
    '  avoid_ros_namespace_conventions: true\n'
    '- history: 1\n  depth: 5\n  reliability: 2\n  durability: 2\n'
    '  deadline:\n    sec: 1\n    nsec: 2\n  lifespan:\n    sec: 3\n    nsec: 4\n'
    '  liveliness: 1\n  liveliness_lease_duration:\n    sec: 5\n    nsec: 6\n'
    '  avoid_ros_namespace_conventions: false',
]


@pytest.mark.parametrize('schema', ['jazzy', 'no message_definitions', 'no QoS'])
def test_topics_are_what_rosbags_reads(tmp_path, rng, schema):
    """Every schema of the topics table, QoS profiles of each distribution: as rosbags reads."""
    from rotation_node.bag.reading.rosbag2_sqlite3 import Sqlite3Storage
    rows = (serialized_rows('/imu', imu_messages(rng, 5))
            + serialized_rows('/b', imu_messages(rng, 3)))
    path = write_rosbag2(tmp_path / 'run', rows, storage='sqlite3') / 'run.db3'
    _sql(path, 'INSERT INTO topics (name, type, serialization_format, offered_qos_profiles, '
               "type_description_hash) VALUES ('/none', 'pkg/msg/T', 'cdr', '', 'x')")
    for topic_id, profiles in enumerate(QOS_PROFILES[::-1], start=1):
        _sql(path, 'UPDATE topics SET offered_qos_profiles = ? WHERE id = ?', profiles, topic_id)
    if schema != 'jazzy':
        _sql(path, 'DROP TABLE schema')
        _sql(path, 'DROP TABLE message_definitions')
    if schema == 'no QoS':
        _sql(path, 'ALTER TABLE topics DROP COLUMN offered_qos_profiles')
    storage = Sqlite3Storage(path)
    storage.open()
    try:
        assert ([tuple(c) for c in storage.connections], storage.message_count) == \
            _rosbags_topics(path)
    finally:
        storage.close()
    assert len(storage.connections) == 3
