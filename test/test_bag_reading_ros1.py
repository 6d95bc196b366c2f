"""
Tests of rotation_node.bag.reading.ros1: ROS 1 bags read as ROS 2 messages.

The bags are written by the rosbags ROS 1 writer from ROS 1 (Noetic) message
types; every value read back through rclpy must be the value written (header
``seq`` dropped), converted values are checked against scipy.
"""
import os
import re
import struct

import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from rotation_node.bag.cli import main
from rotation_node.bag.convert import convert
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.reading.ros1_chunks import ChunkedReader
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters
from rotation_node.wire.qos import qos_profiles_from_yaml
from scipy.spatial.transform import Rotation

T0 = 1_600_000_000


@pytest.fixture
def ros1_bag(tmp_path, rng):
    """Write a ROS 1 bag (lz4): /imu, a latched /ORB-SLAM/pose, a /custom type; its values."""
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg('int32 a\nstring b\n', 'my_msgs/msg/Thing'))
    types = store.types
    header = types['std_msgs/msg/Header']
    time = types['builtin_interfaces/msg/Time']
    quaternion, vector = types['geometry_msgs/msg/Quaternion'], types['geometry_msgs/msg/Vector3']
    rotations = Rotation.random(50, random_state=rng)
    written = []
    path = tmp_path / 'old.bag'
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat.LZ4)
    with writer:
        imu = writer.add_connection('/imu', 'sensor_msgs/msg/Imu', typestore=store)
        pose = writer.add_connection('/ORB-SLAM/pose', 'geometry_msgs/msg/PoseStamped',
                                     typestore=store, latching=1)
        custom = writer.add_connection('/custom', 'my_msgs/msg/Thing', typestore=store)
        for i, q in enumerate(rotations.as_quat()):
            stamp = time(sec=T0 + i // 10, nanosec=(i % 10) * 100_000_000)
            values = {'orientation_covariance': rng.normal(size=9),
                      'angular_velocity': rng.normal(size=3),
                      'angular_velocity_covariance': rng.normal(size=9),
                      'linear_acceleration': rng.normal(size=3),
                      'linear_acceleration_covariance': rng.normal(size=9)}
            msg = types['sensor_msgs/msg/Imu'](
                header(seq=1000 + i, stamp=stamp, frame_id='imu_link'), quaternion(*q),
                values['orientation_covariance'], vector(*values['angular_velocity']),
                values['angular_velocity_covariance'], vector(*values['linear_acceleration']),
                values['linear_acceleration_covariance'])
            log_time = (T0 + i // 10) * 10**9 + (i % 10) * 100_000_000 + 3_000_000
            writer.write(imu, log_time, store.serialize_ros1(msg, 'sensor_msgs/msg/Imu'))
            written.append((log_time, q, values))
        writer.write(pose, T0 * 10**9, store.serialize_ros1(types['geometry_msgs/msg/PoseStamped'](
            header(seq=1, stamp=time(sec=T0, nanosec=0), frame_id='map'),
            types['geometry_msgs/msg/Pose'](types['geometry_msgs/msg/Point'](1.0, 2.0, 3.0),
                                            quaternion(0.0, 0.0, 0.6, 0.8))),
            'geometry_msgs/msg/PoseStamped'))
        writer.write(custom, T0 * 10**9 + 1, store.serialize_ros1(
            types['my_msgs/msg/Thing'](a=42, b='hello'), 'my_msgs/msg/Thing'))
    return path, written


def test_messages_become_ros2_messages_with_the_values_written(ros1_bag):
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import Imu
    path, written = ros1_bag
    with open_bag(path) as bag:
        assert bag.description == 'ROS 1 bag (lz4 chunks)' and bag.compression == 'lz4'
        assert bag.topics == {'/imu': 'sensor_msgs/msg/Imu',
                              '/ORB_SLAM/pose': 'geometry_msgs/msg/PoseStamped',
                              '/custom': 'my_msgs/msg/Thing'}
        assert bag.notes == [f"{path}: topic '/ORB-SLAM/pose' is not a valid ROS 2 name; "
                             'using /ORB_SLAM/pose']
        records = list(bag.messages(['/imu']))
        latched, = qos_profiles_from_yaml(bag.topic_metadata['/ORB_SLAM/pose']
                                          .offered_qos_profiles)
        assert latched.durability.short_key == 'transient_local'
        pose, = bag.messages(['/ORB-SLAM/pose'])   # the bag's own name works too
        custom = bag.topic_metadata['/custom']
    assert [r.log_time_ns for r in records] == [row[0] for row in written]
    for record, (log_time, q, values) in zip(records, written):
        msg = deserialize_message(record.data, Imu)
        assert msg.header.frame_id == 'imu_link' and record.publish_time_ns == log_time
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(
            log_time - 3_000_000, 10**9)
        assert [msg.orientation.x, msg.orientation.y, msg.orientation.z,
                msg.orientation.w] == list(q)
        assert list(msg.orientation_covariance) == list(values['orientation_covariance'])
        assert [msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z] == list(
            values['angular_velocity'])
        assert list(msg.linear_acceleration_covariance) == list(
            values['linear_acceleration_covariance'])
    pose_msg = deserialize_message(pose.data, PoseStamped)
    assert pose.topic == '/ORB_SLAM/pose' and pose_msg.header.frame_id == 'map'
    assert (pose_msg.pose.position.y, pose_msg.pose.orientation.w) == (2.0, 0.8)
    assert custom.definition == 'int32 a\nstring b\n' and custom.definition_encoding == 'ros2msg'


def test_convert_runs_the_pipelines_on_a_ros1_bag(tmp_path, ros1_bag):
    """Converted values equal scipy's; the custom type is copied with its own definition."""
    from geometry_msgs.msg import Vector3Stamped
    path, written = ros1_bag
    params = NodeParameters(input_type='imu', outputs=('euler',), euler_sequence='xyz')
    stats = convert(path, tmp_path / 'new.mcap', params)
    assert stats['/imu'].received == stats['/imu'].published == len(written)
    with open_bag(tmp_path / 'new.mcap') as bag:
        assert sorted(bag.topics) == ['/ORB_SLAM/pose', '/custom', '/imu', '/imu/euler']
        euler = [deserialize_message(r.data, Vector3Stamped) for r in bag.messages(['/imu/euler'])]
    angles = np.array([[m.vector.x, m.vector.y, m.vector.z] for m in euler])
    expected = Rotation.from_quat([q for _, q, _ in written]).as_euler('xyz')
    assert np.abs(np.angle(np.exp(1j * (angles - expected)))).max() < 1e-12
    # An independent reader decodes the copied custom type from the definition stored.
    with AnyReader([tmp_path / 'new.mcap']) as reader:
        connection, = [c for c in reader.connections if c.topic == '/custom']
        (_, _, data), = reader.messages([connection])
        thing = reader.deserialize(data, connection.msgtype)
    assert (thing.a, thing.b) == (42, 'hello')


def test_a_ros1_bag_is_known_by_its_content_not_its_name(ros1_bag):
    path, written = ros1_bag
    renamed = path.rename(path.with_name('recording.bag.orig'))
    with open_bag(renamed) as bag:
        assert bag.description == 'ROS 1 bag (lz4 chunks)'
        assert [r.log_time_ns for r in bag.messages(['/imu'])] == [row[0] for row in written]


def _index_data_record(path):
    """Return the bag's bytes and the position of the first index data record (after a chunk)."""
    with ChunkedReader(path) as reader:
        chunk = reader.chunks[reader.chunk_infos[0].pos]
        return bytearray(path.read_bytes()), chunk.datapos + chunk.datasize, chunk


def _damage_index_field(name, value):
    def damage(path):
        data, position, _ = _index_data_record(path)
        field = data.index(name.encode() + b'=', position) + len(name) + 1
        data[field:field + 4] = struct.pack('<I', value)
        return data
    return damage


def _damage_first_offset(path):
    data, position, _ = _index_data_record(path)
    header_size, = struct.unpack_from('<I', data, position)
    entry = position + 4 + header_size + 4
    data[entry + 8:entry + 12] = struct.pack('<I', 5)   # the offset of the first message
    return data


def _damage_compressed_data(path):
    data, _, chunk = _index_data_record(path)
    middle = chunk.datapos + chunk.datasize // 2
    data[middle:middle + 64] = b'\xff' * 64
    return data


def _damage_chunk_info_time(path):
    data, _, _ = _index_data_record(path)
    field = data.rindex(b'start_time=') + len('start_time=')
    sec, nsec = struct.unpack_from('<II', data, field)
    data[field:field + 8] = struct.pack('<II', sec + 1, nsec)   # later than the first messages
    return data


def _truncate_chunk(path):
    data, _, chunk = _index_data_record(path)
    data[chunk.datapos - 4:chunk.datapos] = struct.pack('<I', chunk.datasize - 100)
    return data


def _damage_field_name(name):
    """Make the name of the last field ``name`` (a chunk info's) not UTF-8."""
    def damage(path):
        data, _, _ = _index_data_record(path)
        field = data.rindex(name + b'=')
        data[field] = 0xf5
        return data
    return damage


def _huge_connection_header(path):
    """Set the header length of the first connection record (the bag's index) to 2**32 - 1."""
    data, _, _ = _index_data_record(path)
    field = data.index(b'index_pos=') + len('index_pos=')
    index_pos, = struct.unpack_from('<Q', data, field)
    data[index_pos:index_pos + 4] = b'\xff' * 4
    return data


def _chunk_position_past_the_end(path):
    """Set the last chunk info's chunk position to 2**63 + 5 (a seek Python cannot make)."""
    data, _, _ = _index_data_record(path)
    field = data.rindex(b'chunk_pos=') + len('chunk_pos=')
    data[field:field + 8] = struct.pack('<Q', 2**63 + 5)
    return data


DAMAGES = {
    'chunk position': (_chunk_position_past_the_end,
                       f'position {2**63 + 5} is outside the file'),
    'chunk info field name': (_damage_field_name(b'chunk_pos'),
                              "failed: 'utf-8' codec can't decode byte 0xf5"),
    'connection header length': (_huge_connection_header,
                                 'failed: Bag index looks damaged'),
    'index count': (_damage_index_field('count', 7), 'index data after the chunk at byte'),
    'index version': (_damage_index_field('ver', 2), 'IDXDATA version 2 is not supported'),
    'index offset': (_damage_first_offset, 'The message at offset 5 of the chunk'),
    'compressed data': (_damage_compressed_data, 'cannot be decompressed'),
    'chunk info time': (_damage_chunk_info_time, "outside the chunk info's time range"),
    'truncated chunk': (_truncate_chunk, 'index data after the chunk at byte'),
}


@pytest.mark.parametrize('damage', DAMAGES)
def test_a_damaged_bag_is_one_line_exit_1_nothing_written(tmp_path, capsys, ros1_bag, damage):
    path, _ = ros1_bag
    make, reason = DAMAGES[damage]
    path.write_bytes(bytes(make(path)))
    (tmp_path / 'params.yaml').write_text(
        'rotation_node:\n  ros__parameters:\n    input_type: imu\n    outputs: [euler]\n')
    before = sorted(os.listdir(tmp_path))
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        status = main(['convert', path.name, 'out.mcap', '--params', 'params.yaml'])
    finally:
        os.chdir(cwd)
    lines = capsys.readouterr().err.splitlines()
    assert status == 1 and len(lines) == 1, lines
    assert lines[0].startswith('rotation_bag convert: error: ') and 'old.bag' in lines[0]
    assert reason in lines[0] and sorted(os.listdir(tmp_path)) == before


def test_a_damaged_length_allocates_nothing(tmp_path, ros1_bag):
    """A record length of 2**32 - 1 is read as the rest of the file, not allocated."""
    import tracemalloc
    path, _ = ros1_bag
    data = _huge_connection_header(path)
    field = data.index(b'index_pos=') + len('index_pos=')
    index_pos, = struct.unpack_from('<Q', data, field)
    path.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        # The failing read starts after the record's length field.
        with pytest.raises(BagError, match=f'the read at byte {index_pos + 4} failed'):
            open_bag(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20


@pytest.mark.parametrize('compression, description, copied', [
    ('BZ2', 'ROS 1 bag (bz2 chunks)', 'zstd'),
    ('LZ4', 'ROS 1 bag (lz4 chunks)', 'lz4'),
    (None, 'ROS 1 bag', 'none'),
])
def test_a_bag_is_described_with_its_own_compression(tmp_path, compression, description,
                                                     copied):
    """bz2 is described as bz2 (robot_localization's test bags), its copy gets zstd."""
    store = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / 'small.bag'
    writer = Writer(path)
    if compression:
        writer.set_compression(Writer.CompressionFormat[compression])
    with writer:
        connection = writer.add_connection('/count', 'std_msgs/msg/Int32', typestore=store)
        for i in range(5):
            writer.write(connection, (T0 + i) * 10**9,
                         store.serialize_ros1(store.types['std_msgs/msg/Int32'](i),
                                              'std_msgs/msg/Int32'))
    with open_bag(path) as bag:
        assert (bag.description, bag.compression) == (description, copied)
        assert len(list(bag.messages())) == 5


def _random_value(store, kind, desc, rng):
    """Return a random value of a field (rosbags' field description) of a ROS 1 type."""
    from rosbags.interfaces import Nodetype
    if kind == Nodetype.NAME:
        return _random_message(store, desc, rng)
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        count = desc[1] if kind == Nodetype.ARRAY else int(rng.integers(0, 4))
        (kind, desc), _ = desc
        values = [_random_value(store, kind, desc, rng) for _ in range(count)]
        if kind != Nodetype.BASE or desc[0] == 'string':
            return values
        return np.array(values, dtype={'float64': np.float64, 'float32': np.float32,
                                       'bool': bool}.get(desc[0], getattr(np, desc[0], np.uint8)))
    name = desc[0]
    if name == 'string':
        return 'frame_' * int(rng.integers(0, 4)) + 'é' * int(rng.integers(0, 3))
    if name == 'bool':
        return bool(rng.integers(2))
    if name.startswith('float'):
        return float(rng.normal())
    bits = {'byte': 8, 'char': 8}.get(name) or int(name.lstrip('uint'))
    low = 0 if name.startswith('u') or name in ('byte', 'char') else -2 ** (bits - 1)
    return int(rng.integers(low, low + 2 ** bits - 1, dtype=np.int64 if bits < 64 else np.uint64)
               if bits < 64 else rng.integers(0, 2 ** 62))


def _random_message(store, type_name, rng):
    fields = store.fielddefs[type_name][1]
    values = {name: _random_value(store, kind, desc, rng) for name, (kind, desc) in fields}
    return store.types[type_name](**values)


@pytest.mark.parametrize('type_name', [
    'sensor_msgs/msg/Imu', 'nav_msgs/msg/Odometry', 'geometry_msgs/msg/TransformStamped',
    'geometry_msgs/msg/PoseWithCovarianceStamped', 'sensor_msgs/msg/NavSatFix',
    'geometry_msgs/msg/QuaternionStamped', 'std_msgs/msg/String', 'std_msgs/msg/Int8',
    'sensor_msgs/msg/RegionOfInterest', 'tf2_msgs/msg/TFMessage', 'sensor_msgs/msg/JointState',
    'sensor_msgs/msg/CameraInfo', 'sensor_msgs/msg/PointCloud2', 'nav_msgs/msg/Path'])
def test_fast_conversion_gives_rosbags_bytes_and_errors(rng, type_name):
    """Mixed alignments (NavSatFix: int8, uint16, float64), strings, nested headers."""
    from rotation_node.bag.reading.ros1 import ros1_to_cdr_converter
    ros1, ros2 = get_typestore(Stores.ROS1_NOETIC), get_typestore(Stores.ROS2_JAZZY)
    if type_name == 'tf2_msgs/msg/TFMessage':   # not in rosbags' Noetic store
        ros1.register(get_types_from_msg('geometry_msgs/TransformStamped[] transforms\n',
                                         type_name))

    def by_rosbags(data):
        return bytes(ros2.ros1_to_cdr(data, type_name))

    convert = ros1_to_cdr_converter(ros2.fielddefs, type_name, by_rosbags)
    assert convert is not None
    for _ in range(30):
        data = bytes(ros1.serialize_ros1(_random_message(ros1, type_name, rng), type_name))
        assert convert(data) == by_rosbags(data)
    for bad in (data[:-1], data + b'\0', b'', b'\xff' * len(data)):   # or a valid message
        try:
            expected = by_rosbags(bad)
        except Exception as error:   # noqa: B902  (whatever rosbags raises, convert raises)
            with pytest.raises(type(error), match=re.escape(str(error))):
                convert(bad)
        else:
            assert convert(bad) == expected
    _assert_blocks_convert_as_one_by_one(convert, ros1, type_name, rng)


def _assert_blocks_convert_as_one_by_one(convert, ros1, type_name, rng):
    """Messages alike in length and layout convert in blocks; any other gives None or the same."""
    datas = [bytes(ros1.serialize_ros1(_random_message(ros1, type_name, rng), type_name))
             for _ in range(12)]
    alike = [datas[0]] * 6 + [datas[1]] * 3   # evenly spaced, then apart
    bad = [datas[2][:-1], datas[3] + b'\0', b'\xff' * len(datas[4])]
    messages = alike[:6] + [datas[k] for k in rng.permutation(len(datas))] + alike[6:] + bad
    chunk, starts = b'', []
    for k, data in enumerate(messages):
        gap = b'' if k < 6 else b'gap' * int(rng.integers(1, 3))
        chunk += gap
        starts.append(len(chunk))
        chunk += data
    converted = convert.block(chunk, np.array(starts), np.array([len(d) for d in messages]))
    assert all(cdr is not None for cdr in converted[:6] + converted[-6:-3])
    for data, cdr in zip(messages, converted):
        assert cdr is None or cdr == convert(data)


def test_empty_structures_are_left_to_rosbags():
    from rotation_node.bag.reading.ros1 import ros1_to_cdr_converter
    ros2 = get_typestore(Stores.ROS2_JAZZY)
    assert ros1_to_cdr_converter(ros2.fielddefs, 'std_msgs/msg/Empty', bytes) is None


def test_ros2_types_are_the_installed_definitions_which_are_rosbags_jazzy_types():
    """Installed types parse to rosbags' Jazzy field definitions (so the bytes stay the same)."""
    from rotation_node.bag.reading.ros1 import ros2_typestore
    names = ['sensor_msgs/msg/Imu', 'nav_msgs/msg/Odometry', 'sensor_msgs/msg/NavSatFix',
             'tf2_msgs/msg/TFMessage', 'geometry_msgs/msg/PoseStamped', 'std_msgs/msg/String',
             'sensor_msgs/msg/JointState', 'sensor_msgs/msg/CameraInfo']
    store, jazzy = ros2_typestore(names), get_typestore(Stores.ROS2_JAZZY)
    assert store is not jazzy and set(names) <= set(store.fielddefs) < set(jazzy.fielddefs)
    for name in store.fielddefs:
        assert store.fielddefs[name] == jazzy.fielddefs[name], name
    # A type not installed here: rosbags' Jazzy types, all of them.
    assert 'my_msgs/msg/Thing' not in ros2_typestore(names + ['my_msgs/msg/Thing']).fielddefs
    assert len(ros2_typestore(names + ['my_msgs/msg/Thing']).fielddefs) == len(jazzy.fielddefs)


def test_same_wire_format_is_rosbags_convert_rule():
    from rosbags.convert.converter import is_same_wireformat
    from rotation_node.bag.reading.ros1 import same_wire_format
    ros1, ros2 = get_typestore(Stores.ROS1_NOETIC), get_typestore(Stores.ROS2_JAZZY)
    ros1.register(get_types_from_msg('int32 a\nstring b\n', 'my_msgs/msg/Thing'))
    ros2.register(get_types_from_msg('int32 a\nstring b\nfloat64 c\n', 'my_msgs/msg/Thing'))
    ros1.register(get_types_from_msg('std_msgs/Header header\nmy_msgs/Thing[] things\n',
                                     'my_msgs/msg/Things'))
    ros2.register(get_types_from_msg('std_msgs/Header header\nmy_msgs/Thing[] things\n',
                                     'my_msgs/msg/Things'))
    names = ['sensor_msgs/msg/Imu', 'nav_msgs/msg/Odometry', 'sensor_msgs/msg/NavSatFix',
             'geometry_msgs/msg/TransformStamped', 'sensor_msgs/msg/CameraInfo',
             'sensor_msgs/msg/PointCloud2', 'std_msgs/msg/Header', 'my_msgs/msg/Thing',
             'my_msgs/msg/Things', 'sensor_msgs/msg/BatteryState', 'sensor_msgs/msg/Range']
    answers = [same_wire_format(ros1, ros2, name, name) for name in names]
    assert answers == [is_same_wireformat(ros1, ros2, name, name) for name in names]
    assert True in answers and False in answers


def test_a_latched_topic_offers_what_rosbags_convert_gives_it():
    from rosbags.convert.converter import LATCH
    from rotation_node.bag.reading.ros1 import LATCHED_QOS_YAML
    from bag_helpers import rosbags_qos_yaml
    from rotation_node.wire.qos_yaml import profiles_yaml
    assert LATCHED_QOS_YAML == rosbags_qos_yaml(LATCH)
    assert profiles_yaml([]) == rosbags_qos_yaml([])


def test_a_definition_that_is_not_its_md5_sum_is_refused(ros1_bag):
    path, _ = ros1_bag
    data = path.read_bytes()
    md5 = re.search(rb'md5sum=([0-9a-f]{32})', data)[1]
    path.write_bytes(data.replace(md5, b'0' * 32))
    with pytest.raises(BagError, match=r'old.bag: cannot read ROS 1 bag: Message type '
                                       r"'.*' hash mismatch [0-9a-f]{32} != 0{32}$"):
        open_bag(path)
