"""Tests of rotation_node.wire.message_types: classes, fields, rosbag2 definitions, type hashes."""
import pytest
from rosbags.typesys import get_typestore, Stores
from rosidl_parser.definition import (
    AbstractNestedType, AbstractSequence, Array, BasicType, BoundedSequence, BoundedString,
    BoundedWString, NamespacedType, UnboundedString, UnboundedWString)
from rotation_node.errors import BagError
from rotation_node.wire.message_types import (
    message_class, message_definition, message_fields, MessageField, split_type_name, type_hash,
    type_name_of)
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


# Every kind of field: values, fixed arrays, bounded and unbounded sequences (of numbers, strings
# and messages), bounded strings, byte and char, nested messages, no field at all.
FIELD_TYPES = TYPES + [
    'nav_msgs/msg/Odometry', 'diagnostic_msgs/msg/DiagnosticStatus', 'std_msgs/msg/Byte',
    'std_msgs/msg/Char', 'std_msgs/msg/Empty', 'std_msgs/msg/Float64MultiArray',
    'shape_msgs/msg/SolidPrimitive', 'shape_msgs/msg/MeshTriangle',
    'rcl_interfaces/msg/ParameterDescriptor', 'rcl_interfaces/msg/ParameterValue',
    'rmw_dds_common/msg/NodeEntitiesInfo', 'unique_identifier_msgs/msg/UUID',
    'sensor_msgs/msg/NavSatFix', 'sensor_msgs/msg/PointCloud2']
# rosidl's names of the basic types that type descriptions name otherwise
_DESCRIPTION_NAMES = {'octet': 'byte'}


def _rosidl_field(name, slot):
    """Return a field as message_fields gives it, from the class's rosidl type (SLOT_TYPES)."""
    container, capacity = '', 0
    if isinstance(slot, AbstractNestedType):
        if isinstance(slot, Array):
            container, capacity = 'array', slot.size
        elif isinstance(slot, BoundedSequence):
            container, capacity = 'bounded_sequence', slot.maximum_size
        else:
            assert isinstance(slot, AbstractSequence)
            container = 'sequence'
        slot = slot.value_type
    if isinstance(slot, NamespacedType):
        return MessageField(name, 'nested_type', container, capacity,
                            '/'.join((*slot.namespaces, slot.name)))
    kind = {UnboundedString: 'string', BoundedString: 'bounded_string',
            UnboundedWString: 'wstring', BoundedWString: 'bounded_wstring'}.get(type(slot))
    if kind is None:
        assert isinstance(slot, BasicType)
        kind = _DESCRIPTION_NAMES.get(slot.typename, slot.typename)
    return MessageField(name, kind, container, capacity, '')


@pytest.mark.parametrize('type_name', FIELD_TYPES)
def test_fields_are_those_of_the_python_class(type_name):
    cls = message_class(type_name)
    assert message_fields(type_name) == tuple(
        _rosidl_field(name, slot)
        for name, slot in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES))


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
    assert message_fields('prefix_test_msgs/msg/Outer') is None   # no type description


def test_missing_dependency_is_named(tmp_path, monkeypatch):
    share = tmp_path / 'share' / 'broken_test_msgs' / 'msg'
    share.mkdir(parents=True)
    (share / 'Thing.msg').write_text('missing_msgs/Gone g\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    with pytest.raises(BagError, match="no message definition for 'missing_msgs/Gone'"):
        message_definition('broken_test_msgs/msg/Thing')


@pytest.mark.parametrize('text, match', [
    ('{"type_description_msg": {"type_description": {"type_name": "other_msgs/msg/Thing", '
     '"fields": []}}}', 'describes other_msgs/msg/Thing'),
    ('{"type_hashes": []}', "is malformed .KeyError 'type_description_msg'"),
    ('{"type_description_msg": ', 'is unreadable: Expecting value'),
], ids=['other_type', 'no_description', 'not_json'])
def test_a_broken_type_description_is_named(tmp_path, monkeypatch, text, match, request):
    package = f'broken_{request.node.callspec.id}_msgs'   # one per case: descriptions are cached
    share = tmp_path / 'share' / package / 'msg'
    share.mkdir(parents=True)
    (share / 'Thing.json').write_text(text)
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    with pytest.raises(BagError, match=f'type description .*{package}/msg/Thing[ .].*{match}'):
        message_fields(f'{package}/msg/Thing')
