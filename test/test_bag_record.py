"""Tests of rotation_bag record (rotation_node.bag.record) against live publishers."""
import os
import pathlib
import signal
import subprocess

from bag_helpers import imu_messages, plain
from fault_helpers import can_mount, linear_scan, small_filesystem, wait_for
import pytest
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from ros_harness import RosProcess, script, TestNode
from rosbags.highlevel import AnyReader
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.wire.qos import qos_profiles_from_yaml
from sensor_msgs.msg import Imu
from std_msgs.msg import String

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]   # starts processes


def _record(path, *args):
    # The tests publish once the publisher has matched the recorder (wait_for_subscriber): its
    # subscription appears in the graph before the match, and a volatile publisher's messages
    # before the match are never delivered.
    return RosProcess([script('rotation_bag'), 'record', path, *args])


@pytest.mark.parametrize('stop_signal', [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
def test_records_every_message_and_closes_on_signal(tmp_path, rng, stop_signal):
    path = tmp_path / 'live.mcap'
    messages = imu_messages(rng, 100)
    latched = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    with TestNode('publisher') as client, _record(path, '--topics', '/imu', 'chatter') as recorder:
        imu = client.node.create_publisher(Imu, '/imu', latched)
        chatter = client.node.create_publisher(String, '/chatter', 10)
        assert client.wait_for_subscriber(imu, timeout=30)
        assert client.wait_for_subscriber(chatter, timeout=30)
        assert not path.exists()   # written to a temporary file until closed
        for msg in messages:
            imu.publish(msg)
        chatter.publish(String(data='hello'))
        assert imu.wait_for_all_acked(Duration(seconds=20))
        assert chatter.wait_for_all_acked(Duration(seconds=20))
        recorder.proc.send_signal(stop_signal)
        assert recorder.stop() == 0, recorder.output
    assert 'wrote 101 messages' in recorder.output
    with BagReader(path) as reader:
        assert reader.topics == {'/imu': 'sensor_msgs/msg/Imu', '/chatter': 'std_msgs/msg/String'}
        records = list(reader.messages(['/imu']))
        offered, = qos_profiles_from_yaml(reader.topic_metadata['/imu'].offered_qos_profiles)
    assert [plain(r.message()) for r in records] == [plain(m) for m in messages]
    assert all(r.publish_time_ns <= r.log_time_ns for r in records)
    assert (offered.reliability, offered.durability) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)
    with AnyReader([pathlib.Path(path)]) as reader:
        assert reader.message_count == 101


def test_duration_without_publishers_gives_an_empty_valid_bag(tmp_path):
    path = tmp_path / 'empty.mcap'
    with _record(path, '--topics', '/nobody', '--duration', '1') as recorder:
        recorder.proc.wait(timeout=60)
        assert recorder.stop() == 0
    assert '/nobody never had a publisher' in recorder.output
    assert BagReader(path).topics == {}


def test_relative_topics_resolve_in_the_namespace(tmp_path):
    path = tmp_path / 'ns.mcap'
    with TestNode('publisher') as client, \
            _record(path, '--topics', 'status', '--ros-args', '-r', '__ns:=/robot') as recorder:
        publisher = client.node.create_publisher(String, '/robot/status', 10)
        assert client.wait_for_subscriber(publisher, timeout=30)
        publisher.publish(String(data='ok'))
        assert publisher.wait_for_all_acked(Duration(seconds=20))
        assert recorder.stop() == 0, recorder.output
    record, = BagReader(path).messages()
    assert (record.topic, record.message().data) == ('/robot/status', 'ok')


def test_refuses_to_overwrite(tmp_path):
    path = tmp_path / 'exists.mcap'
    path.write_bytes(b'keep')
    with _record(path, '--topics', '/x', '--duration', '1') as recorder:
        recorder.proc.wait(timeout=60)
        assert recorder.stop() == 1
    assert 'rotation_bag record: error: output' in recorder.output
    assert path.read_bytes() == b'keep'


def test_sigkill_keeps_every_message_written_a_second_before(tmp_path, rng):
    """After SIGKILL the .part holds what was received more than about a second before."""
    path = tmp_path / 'live'
    storage = tmp_path / 'live.part' / 'live_0.mcap'
    first, second = imu_messages(rng, 150), imu_messages(rng, 150)
    reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    with TestNode('publisher') as client, _record(path, '--topics', '/imu') as recorder:
        imu = client.node.create_publisher(Imu, '/imu', reliable)
        assert client.wait_for_subscriber(imu, timeout=30)
        for msg in first:
            imu.publish(msg)
        # Written within about a second of reception (a bounded wait, not a speed test).
        assert wait_for(lambda: len(linear_scan(storage)) >= len(first), timeout=20)
        for msg in second:
            imu.publish(msg)
        recorder.proc.send_signal(signal.SIGKILL)
        assert recorder.stop() == -signal.SIGKILL
    assert not path.exists()
    recovered = linear_scan(storage)
    published = first + second
    assert len(first) <= len(recovered) <= len(published)
    assert [plain(deserialize_message(data, Imu)) for _, _, _, data in recovered] == [
        plain(m) for m in published[:len(recovered)]]


@pytest.mark.skipif(not can_mount(), reason='needs a tmpfs mount (root); the writer tests '
                                            'cover the full disk without one')
def test_full_disk_stops_and_keeps_a_valid_bag(tmp_path, rng):
    messages = imu_messages(rng, 3000)
    reliable = QoSProfile(depth=len(messages), reliability=ReliabilityPolicy.RELIABLE)
    with small_filesystem(tmp_path / 'small', 512 * 1024) as small:
        path = small / 'live'
        with TestNode('publisher') as client, \
                _record(path, '--topics', '/imu', '--compression', 'none') as recorder:
            imu = client.node.create_publisher(Imu, '/imu', reliable)
            assert client.wait_for_subscriber(imu, timeout=30)
            for msg in messages:
                imu.publish(msg)
            assert wait_for(lambda: not recorder.alive(), timeout=30)
            assert recorder.stop() == 1
        line, = [line for line in recorder.output.splitlines() if 'error' in line]
        kept = int(line.split('kept ')[1].split()[0])
        assert line.startswith('rotation_bag record: error: disk full: recording stopped, '
                               f'kept {kept} messages in {path}')
        assert sorted(os.listdir(small)) == ['live']
        with AnyReader([pathlib.Path(path)]) as reader:
            assert reader.message_count == kept > 500
            recorded = [plain(deserialize_message(bytes(data), Imu))
                        for _, _, data in reader.messages()]
    assert recorded == [plain(m) for m in messages[:kept]]


@pytest.mark.parametrize('args, match', [
    (['--topics', '/imu-raw'], "'/imu-raw' is not a valid ROS 2 topic name"),
    (['--topics', '/imu', '--duration', 'inf'], 'duration must be a finite number of seconds'),
], ids=['invalid_topic_name', 'infinite_duration'])
def test_bad_arguments_are_one_line_and_create_nothing(tmp_path, args, match):
    result = subprocess.run([script('rotation_bag'), 'record', tmp_path / 'out', *args],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    line, = result.stderr.splitlines()
    assert line.startswith('rotation_bag record: error: ') and match in line
    assert os.listdir(tmp_path) == []
