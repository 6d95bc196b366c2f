"""Tests of rotation_node.wire.message_types: classes, rosbag2 definitions, type hashes."""
import pytest
from rosbags.typesys import get_typestore, Stores
from rotation_node.errors import BagError
from rotation_node.wire.message_types import (
    message_class, message_definition, split_type_name, type_hash, type_name_of)
from sensor_msgs.msg import Imu

TYPES = ['sensor_msgs/msg/Imu', 'geometry_msgs/msg/Vector3Stamped',
         'geometry_msgs/msg/QuaternionStamped', 'geometry_msgs/msg/PoseWithCovarianceStamped',
         'sensor_msgs/msg/JointState', 'visualization_msgs/msg/MarkerArray']
DELIMITER = '=' * 80


def test_imu_definition_is_rosbag2_concatenation():
    text = message_definition('sensor_msgs/msg/Imu')
    sections = text.split('\n' + DELIMITER + '\n')
    assert sections[0] == open(_msg_file('sensor_msgs', 'Imu')).read()
    # Dependencies depth first, each definition's own dependencies in sorted order.
    assert [s.split('\n', 1)[0] for s in sections[1:]] == [
        'MSG: geometry_msgs/Quaternion', 'MSG: geometry_msgs/Vector3',
        'MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time']
    assert sections[3].split('\n', 1)[1] == open(_msg_file('std_msgs', 'Header')).read()


def _msg_file(package, name):
    import sys
    return f'{sys.prefix}/share/{package}/msg/{name}.msg'


@pytest.mark.parametrize('type_name', TYPES)
def test_definition_lists_every_dependency_once(type_name):
    text = message_definition(type_name)
    names = [line[5:] for line in text.splitlines() if line.startswith('MSG: ')]
    assert len(names) == len(set(names)) == text.count(DELIMITER)


@pytest.mark.parametrize('type_name', TYPES)
def test_type_hash_matches_rosbags(type_name):
    assert type_hash(type_name) == get_typestore(Stores.ROS2_JAZZY).hash_rihs01(type_name)


def test_class_lookup_and_name_round_trip():
    assert message_class('sensor_msgs/msg/Imu') is Imu
    assert type_name_of(Imu) == 'sensor_msgs/msg/Imu'
    assert split_type_name('sensor_msgs/msg/Imu') == ('sensor_msgs', 'msg', 'Imu')


@pytest.mark.parametrize('not_a_message', [dict, int, BagError])
def test_type_name_of_rejects_other_classes(not_a_message):
    with pytest.raises(BagError, match='is not a ROS message class'):
        type_name_of(not_a_message)


@pytest.mark.parametrize('type_name, match', [
    ('Imu', "invalid message type name 'Imu'"),
    ('sensor_msgs/Imu', "invalid message type name 'sensor_msgs/Imu'"),
    (42, 'invalid message type name 42'),
    ('sensor_msgs/msg/NoSuch', "unknown message type 'sensor_msgs/msg/NoSuch'"),
    ('no_such_msgs/msg/Thing', "unknown message type 'no_such_msgs/msg/Thing': .*not installed"),
])
def test_bad_type_names(type_name, match):
    with pytest.raises(BagError, match=match):
        message_class(type_name)


def test_definitions_found_through_ament_prefix_path(tmp_path, monkeypatch):
    share = tmp_path / 'share' / 'prefix_test_msgs' / 'msg'
    share.mkdir(parents=True)
    (share / 'Outer.msg').write_text('Inner[] items  # same-package type\nint32 n\n')
    (share / 'Inner.msg').write_text('std_msgs/Header header\nfloat64 x\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    text = message_definition('prefix_test_msgs/msg/Outer')
    assert [line for line in text.splitlines() if line.startswith('MSG: ')] == [
        'MSG: prefix_test_msgs/Inner', 'MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time']
    assert type_hash('prefix_test_msgs/msg/Outer') == ''


def test_missing_dependency_is_named(tmp_path, monkeypatch):
    share = tmp_path / 'share' / 'broken_test_msgs' / 'msg'
    share.mkdir(parents=True)
    (share / 'Thing.msg').write_text('missing_msgs/Gone g\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    with pytest.raises(BagError, match="no message definition for 'missing_msgs/Gone'"):
        message_definition('broken_test_msgs/msg/Thing')
