"""
Tests of rotation_node.wire.cdr: fast CDR of fixed-layout messages, one or a block.

Every supported type is checked against rclpy both ways (decode what rclpy
serialises, rclpy deserialises what is encoded), field by field with floats
compared bit for bit, and against an independent serialiser with zero
padding (rosbags), byte for byte; the strings take every length from 0 to 9
characters, which puts the data after them at every alignment, and a
multi-byte UTF-8 one. The block form is checked against the per-message one:
the same values decoded, the same bytes encoded, and blocks it cannot read
alike declined.
"""
import math
import operator
import struct

from bag_helpers import random_message
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_typestore, Stores
from rotation_node.errors import BagError
from rotation_node.registry import OUTPUTS
from rotation_node.wire import cdr
from rotation_node.wire.cdr import (
    CDR_LE, fixed_layout_codec, float64_multi_array_block_encoder, float64_multi_array_encoder,
    message_encoder)
from rotation_node.wire.message_types import message_class
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

PIPELINE_TYPES = [   # inputs, and the stamped outputs
    'sensor_msgs/msg/Imu',
    'geometry_msgs/msg/QuaternionStamped',
    'geometry_msgs/msg/PoseStamped',
    'geometry_msgs/msg/PoseWithCovarianceStamped',
    'geometry_msgs/msg/TransformStamped',
    'geometry_msgs/msg/Vector3Stamped',
    'nav_msgs/msg/Odometry',
]
FIXED_TYPES = PIPELINE_TYPES + [
    'std_msgs/msg/Header',
    'builtin_interfaces/msg/Time',        # no string
    'std_msgs/msg/String',                # only a string
    'diagnostic_msgs/msg/KeyValue',       # two strings in a row
    'sensor_msgs/msg/NavSatFix',          # int8, uint16 after the string, then float64s
    'sensor_msgs/msg/Range',              # uint8, float32
    'sensor_msgs/msg/RegionOfInterest',   # uint32, bool
    'std_msgs/msg/Int64',
    'std_msgs/msg/UInt64',
    'std_msgs/msg/Int16',
    'std_msgs/msg/ColorRGBA',
]
# Every length 0..9 (the first float64 after a Header lands on every
# alignment) and one multi-byte character.
STRINGS = ['abcdefghi'[:n] for n in range(10)] + ['caf\u00e9']
SPECIAL_FLOATS = [math.nan, -math.nan, math.inf, -math.inf, -0.0, 5e-324, 1.7976931348623157e308]
EXTREME_STAMPS = [(-2**31, 0), (2**31 - 1, 999_999_999), (0, 2**32 - 1), (1_700_000_000, 1)]


@pytest.fixture(scope='module')
def rosbags_store():
    return get_typestore(Stores.ROS2_JAZZY)


def _fill(msg, text, rng):
    """Every string = ``text``; some float64s special (NaN, Inf, -0, subnormal); extreme stamps."""
    for name, field_type in msg.get_fields_and_field_types().items():
        value = getattr(msg, name)
        if hasattr(value, 'get_fields_and_field_types'):
            _fill(value, text, rng)
        elif field_type == 'string':
            setattr(msg, name, text)
        elif field_type == 'double' and rng.random() < 0.5:
            setattr(msg, name, SPECIAL_FLOATS[rng.integers(len(SPECIAL_FLOATS))])
        elif field_type.startswith('double['):
            mask = rng.random(len(value)) < 0.5
            value[mask] = rng.choice(SPECIAL_FLOATS, int(mask.sum()))
    if type(msg).__name__ == 'Time':
        msg.sec, msg.nanosec = EXTREME_STAMPS[rng.integers(len(EXTREME_STAMPS))]
    return msg


def _message(type_name, text, rng):
    return _fill(random_message(message_class(type_name), rng), text, rng)


def _same_number(a, b):
    """Equal, floats bit for bit (NaN == NaN, -0.0 != 0.0)."""
    if isinstance(a, float) or isinstance(b, float):
        return struct.pack('<d', a) == struct.pack('<d', b)
    return a == b


def _flat(view):
    """Return the values of a view, depth first."""
    return [x for item in view for x in _flat(item)] if isinstance(view, tuple) else [view]


def assert_same_fields(expected, actual, path='msg'):
    """Every field of the rclpy message ``expected`` is in ``actual`` (rclpy message or view)."""
    for name in expected.get_fields_and_field_types():
        want, got = getattr(expected, name), getattr(actual, name)
        where = f'{path}.{name}'
        if hasattr(want, 'get_fields_and_field_types'):
            assert_same_fields(want, got, where)
        elif isinstance(want, str):
            assert got == want, where
        elif isinstance(want, (np.ndarray, list, tuple)):
            assert len(got) == len(want), where
            assert all(_same_number(w, g) for w, g in zip(want, got)), (where, want, got)
        else:
            assert _same_number(want, got), (where, want, got)


@pytest.mark.parametrize('text', STRINGS)
@pytest.mark.parametrize('type_name', FIXED_TYPES)
def test_decode_reads_every_field_rclpy_wrote(type_name, text, rng):
    msg = _message(type_name, text, rng)
    view = fixed_layout_codec(type_name).decode(serialize_message(msg))
    assert type(view) is fixed_layout_codec(type_name).view_class
    assert_same_fields(msg, view)


@pytest.mark.parametrize('text', STRINGS)
@pytest.mark.parametrize('type_name', FIXED_TYPES)
def test_rclpy_reads_every_field_of_the_encoding(type_name, text, rng):
    msg = _message(type_name, text, rng)
    data = fixed_layout_codec(type_name).encode(msg)
    assert len(data) == len(serialize_message(msg))
    assert_same_fields(msg, deserialize_message(data, type(msg)))


@pytest.mark.parametrize('text', STRINGS)
@pytest.mark.parametrize('type_name', FIXED_TYPES)
def test_encoding_is_zero_padded_cdr_byte_for_byte(type_name, text, rng, rosbags_store):
    """
    The bytes of rosbags' independent serialiser, which zeroes the padding.

    Then zeros to rclpy's length: rmw_fastrtps pads the types without strings
    to a multiple of 4 bytes, rosbags does not.
    """
    msg = _message(type_name, text, rng)
    reference = bytes(rosbags_store.serialize_cdr(
        rosbags_store.deserialize_cdr(serialize_message(msg), type_name), type_name))
    reference += bytes(len(serialize_message(msg)) - len(reference))
    assert fixed_layout_codec(type_name).encode(msg) == reference


@pytest.mark.slow
@pytest.mark.parametrize('text', STRINGS)
@pytest.mark.parametrize('type_name', FIXED_TYPES)
def test_equal_messages_give_equal_bytes(type_name, text, rng):
    codec = fixed_layout_codec(type_name)
    msg = _message(type_name, text, rng)
    data = codec.encode(msg)
    assert codec.encode(deserialize_message(serialize_message(msg), type(msg))) == data
    assert codec.encode(codec.decode(data)) == data   # a view encodes like its message


def test_layout_of_a_vector3_stamped():
    """Stamp, frame_id length 2 with its NUL, 2 bytes of zero padding, then x, y, z at 16."""
    msg = message_class('geometry_msgs/msg/Vector3Stamped')()
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = -1, 7, 'a'
    msg.vector.x, msg.vector.y, msg.vector.z = 1.0, -2.0, 0.5
    assert fixed_layout_codec('geometry_msgs/msg/Vector3Stamped').encode(msg) == (
        CDR_LE + struct.pack('<iII2s', -1, 7, 2, b'a') + bytes(2) + struct.pack('<3d', 1, -2, .5))


@pytest.mark.parametrize('little_endian', [True, False])
@pytest.mark.parametrize('type_name', FIXED_TYPES)
def test_decode_reads_what_rosbags_wrote(type_name, little_endian, rng, rosbags_store):
    """Little-endian (no end padding) into a view; big-endian goes to rclpy."""
    msg = _message(type_name, 'base_link', rng)
    data = bytes(rosbags_store.serialize_cdr(
        rosbags_store.deserialize_cdr(serialize_message(msg), type_name), type_name,
        little_endian=little_endian))
    assert data[:2] == (b'\x00\x01' if little_endian else b'\x00\x00')
    decoded = fixed_layout_codec(type_name).decode(data)
    assert isinstance(decoded, tuple) is little_endian
    assert_same_fields(msg, decoded)


def test_unknown_encapsulation_is_a_clear_error():
    data = fixed_layout_codec('geometry_msgs/msg/Vector3Stamped').encode(
        message_class('geometry_msgs/msg/Vector3Stamped')())
    with pytest.raises(BagError, match='encapsulation ff ff 00 00 is not little-endian CDR'):
        fixed_layout_codec('geometry_msgs/msg/Vector3Stamped').decode(b'\xff\xff' + data[2:])


@pytest.mark.parametrize('cut', [3, 4, 7, 11, -9, -1])
@pytest.mark.parametrize('type_name', PIPELINE_TYPES + ['std_msgs/msg/String'])
def test_truncated_data_is_a_bag_error(type_name, cut, rng):
    codec = fixed_layout_codec(type_name)
    data = codec.encode(_message(type_name, 'imu', rng))
    with pytest.raises(BagError, match=f'{len(data[:cut])} bytes is truncated'):
        codec.decode(data[:cut])


def test_string_length_past_the_end_is_a_bag_error():
    data = bytearray(serialize_message(message_class('geometry_msgs/msg/Vector3Stamped')()))
    data[12:16] = struct.pack('<I', 2**32 - 1)
    with pytest.raises(BagError, match='truncated'):
        fixed_layout_codec('geometry_msgs/msg/Vector3Stamped').decode(bytes(data))


@pytest.mark.parametrize('raw', [b'ab', b'\xff\xfe', b''])
def test_strings_decode_as_rclpy_does(raw):
    """Without the NUL, invalid UTF-8, length 0: what rclpy (Fast CDR) accepts, read alike."""
    data = CDR_LE + struct.pack(f'<I{len(raw)}s', len(raw), raw)
    expected = deserialize_message(data, message_class('std_msgs/msg/String'))
    assert fixed_layout_codec('std_msgs/msg/String').decode(data).data == expected.data


def test_views_are_read_only():
    view = fixed_layout_codec('sensor_msgs/msg/Imu').decode(
        serialize_message(message_class('sensor_msgs/msg/Imu')()))
    with pytest.raises(AttributeError):
        view.orientation.x = 1.0
    with pytest.raises(TypeError):
        view.orientation_covariance[0] = 1.0
    assert view.orientation_covariance[0] == 0.0 and view.orientation.w == 1.0


@pytest.mark.parametrize('type_name', [
    'std_msgs/msg/Float64MultiArray', 'sensor_msgs/msg/JointState', 'std_msgs/msg/Empty',
    'geometry_msgs/msg/PolygonStamped'])
def test_types_without_a_fixed_layout_have_no_codec(type_name):
    assert fixed_layout_codec(type_name) is None


def test_unknown_type_is_an_error():
    with pytest.raises(BagError, match='nope_msgs'):
        fixed_layout_codec('nope_msgs/msg/Nope')


def test_a_type_installed_without_a_description_is_left_to_rclpy(monkeypatch):
    """No type description (a package built without one): no codec, the type still known."""
    monkeypatch.setattr(cdr, 'message_fields', lambda type_name: None)
    caches = (fixed_layout_codec, message_encoder)
    for cached in caches:
        cached.cache_clear()
    try:
        assert fixed_layout_codec('sensor_msgs/msg/Imu') is None
        assert message_encoder('sensor_msgs/msg/Imu') is None   # the writer serialises with rclpy
        with pytest.raises(BagError, match='nope_msgs'):
            fixed_layout_codec('nope_msgs/msg/Nope')
    finally:
        for cached in caches:   # nothing computed without the descriptions stays
            cached.cache_clear()


def test_encoding_an_impossible_value_names_the_field():
    codec = fixed_layout_codec('geometry_msgs/msg/Vector3Stamped')
    view = codec.decode(serialize_message(message_class('geometry_msgs/msg/Vector3Stamped')()))
    bad = view._replace(header=view.header._replace(stamp=view.header.stamp._replace(sec=2**40)))
    with pytest.raises(BagError, match=r'header\.stamp\.sec = 1099511627776'):
        codec.encode(bad)


@pytest.mark.parametrize('type_name', ['geometry_msgs/msg/Vector3Stamped',
                                       'geometry_msgs/msg/QuaternionStamped',
                                       'geometry_msgs/msg/PoseStamped', 'sensor_msgs/msg/Imu'])
@pytest.mark.parametrize('text', ['', 'imu_link', 'caf\u00e9'])
def test_stamped_encoder_encodes_header_and_numbers(type_name, text, rng):
    codec = fixed_layout_codec(type_name)
    msg = _message(type_name, text, rng)
    view = codec.decode(serialize_message(msg))
    numbers = _flat(view)[3:]   # after sec, nanosec, frame_id
    encode = codec.stamped_encoder()
    assert encode(view.header, numbers) == encode(msg.header, numbers) == codec.encode(msg)
    assert encode(msg.header, np.array(numbers, dtype=np.float64)) == codec.encode(msg)


@pytest.mark.parametrize('type_name', ['geometry_msgs/msg/TransformStamped',
                                       'builtin_interfaces/msg/Time', 'std_msgs/msg/String'])
def test_stamped_encoder_needs_a_header_then_numbers(type_name):
    with pytest.raises(BagError, match='not a std_msgs/Header followed by numbers'):
        fixed_layout_codec(type_name).stamped_encoder()


def test_stamped_encoder_rejects_the_wrong_count_of_numbers():
    encode = fixed_layout_codec('geometry_msgs/msg/Vector3Stamped').stamped_encoder()
    header = message_class('std_msgs/msg/Header')()
    with pytest.raises(BagError, match='cannot encode geometry_msgs/msg/Vector3Stamped'):
        encode(header, [1.0, 2.0])


def _layout_message(layout):
    """Return the std_msgs/MultiArrayLayout of a registry.ArrayLayout."""
    return MultiArrayLayout(dim=[MultiArrayDimension(label=d.label, size=d.size, stride=d.stride)
                                 for d in layout.dim], data_offset=layout.data_offset)


LAYOUTS = {
    **{name: _layout_message(output.message.layout) for name, output in OUTPUTS.items()
       if output.message.layout},
    'labels 0..4 characters': MultiArrayLayout(
        dim=[MultiArrayDimension(label='abcd'[:n], size=n, stride=7 * n) for n in range(5)],
        data_offset=3)}


@pytest.mark.parametrize('count', [0, 1, 4, 9])
@pytest.mark.parametrize('layout', LAYOUTS)
def test_float64_multi_array(layout, count, rng, rosbags_store):
    msg = Float64MultiArray(layout=LAYOUTS[layout], data=rng.normal(size=count).tolist())
    data = float64_multi_array_encoder(msg.layout)(msg.data)
    assert float64_multi_array_encoder(msg.layout)(np.array(msg.data)) == data   # rows too
    assert len(data) == len(serialize_message(msg))
    assert deserialize_message(data, Float64MultiArray) == msg
    assert message_encoder('std_msgs/msg/Float64MultiArray')(msg) == data
    if count:   # rosbags writes no padding for an empty sequence; Fast CDR and we do
        type_name = 'std_msgs/msg/Float64MultiArray'
        assert data == bytes(rosbags_store.serialize_cdr(
            rosbags_store.deserialize_cdr(serialize_message(msg), type_name), type_name))


def test_message_encoder_covers_fixed_layouts_and_float64_multi_array_only():
    imu = fixed_layout_codec('sensor_msgs/msg/Imu')
    assert message_encoder('sensor_msgs/msg/Imu') == imu.encode
    assert message_encoder('sensor_msgs/msg/JointState') is None


def test_float64_multi_array_blocks_are_the_per_message_bytes(rng):
    layout = LAYOUTS['labels 0..4 characters']
    data = rng.normal(size=(5, 7))
    for rows in (data, data[:1], data[:0]):
        assert float64_multi_array_block_encoder(layout, 7)(rows) == [
            float64_multi_array_encoder(layout)(row) for row in rows]


# ------------------------------------------------------------------ the block form

def _block(type_name, rng, count=3):
    """Messages of every string length, in an interleaved order (several groups)."""
    msgs = [_message(type_name, text, rng) for text in STRINGS for _ in range(count)]
    order = rng.permutation(len(msgs))
    return [msgs[k] for k in order]


def _rows_of(block):
    """Return each message's ``(group, row in its group)`` of a DecodedBlock."""
    seen = [0] * len(block.records)
    rows = []
    for g in block.group.tolist():
        rows.append((g, seen[g]))
        seen[g] += 1
    assert seen == [len(records) for records in block.records]
    return rows


@pytest.mark.parametrize('type_name', FIXED_TYPES)
def test_decode_block_reads_what_decode_reads(type_name, rng):
    codec = fixed_layout_codec(type_name)
    msgs = _block(type_name, rng)
    datas = [serialize_message(msg) for msg in msgs]   # rclpy's bytes, padding uninitialised
    block = codec.decode_block(datas)
    for data, (g, row) in zip(datas, _rows_of(block), strict=True):
        view, record = codec.decode(data), block.records[g][row]
        for leaf in codec.leaves:
            want, got = operator.attrgetter(leaf.path)(view), record[leaf.path]
            if leaf.code == 's':
                assert bytes(got) == want.encode() + b'\0', leaf.path
            elif leaf.count:
                assert len(got) == len(want) and all(map(_same_number, want, got.tolist()))
            else:
                assert _same_number(want, got.item()), (leaf.path, want, got)


@pytest.mark.parametrize('type_name', FIXED_TYPES)
def test_encode_block_gives_the_bytes_of_encode(type_name, rng):
    """From the fields decode_block reads in rclpy's bytes: zero padding, as encode writes."""
    codec = fixed_layout_codec(type_name)
    msgs = _block(type_name, rng)
    block = codec.decode_block([serialize_message(msg) for msg in msgs])
    encoded = []
    for records in block.records:
        string_lengths = tuple(records.dtype[leaf.path].shape[0]
                               for leaf in codec.leaves if leaf.code == 's')
        encoded.append(iter(codec.layout(string_lengths).encode_block(
            len(records), {leaf.path: records[leaf.path] for leaf in codec.leaves})))
    assert [next(encoded[g]) for g in block.group.tolist()] == [codec.encode(m) for m in msgs]


def test_layout_of_a_vector3_stamped_in_both_forms():
    """The struct and the dtype of one layout: stamp, frame_id length 2, padding, x, y, z."""
    layout = fixed_layout_codec('geometry_msgs/msg/Vector3Stamped').layout((2,))
    assert layout.offsets == {'header.stamp.sec': 0, 'header.stamp.nanosec': 4,
                              'header.frame_id': 8, 'vector.x': 16, 'vector.y': 24,
                              'vector.z': 32}
    assert layout.size == layout.struct.size == layout.dtype.itemsize == 40
    assert layout.dtype.fields['header.frame_id'][1] == 12   # its bytes, after the length
    assert layout.end_padding == 0
    assert fixed_layout_codec('builtin_interfaces/msg/Time').layout(()).end_padding == 0
    assert fixed_layout_codec('std_msgs/msg/Int16').layout(()).end_padding == 2


def _damaged(data, damage):
    data = bytearray(data)
    nul = 4 + 12 + len('imu')   # the frame_id's NUL
    if damage == 'not_little_endian':
        data[1] = 0
    elif damage == 'truncated':
        del data[-9:]
    elif damage == 'shorter_than_the_encapsulation':
        del data[3:]
    elif damage == 'string_length_past_the_end':
        data[12:16] = struct.pack('<I', 2**32 - 1)
    elif damage == 'frame_id_without_nul':
        data[nul] = ord('!')
    elif damage == 'frame_id_not_utf8':
        data[nul - 1] = 0xff
    else:   # an empty frame_id: length 0, no bytes, no NUL
        data[12:16] = bytes(4)
        del data[16:nul + 1]
    return bytes(data)


@pytest.mark.parametrize('damage', [
    'not_little_endian', 'truncated', 'shorter_than_the_encapsulation',
    'string_length_past_the_end', 'frame_id_without_nul', 'frame_id_not_utf8', 'empty_frame_id'])
@pytest.mark.parametrize('type_name', ['sensor_msgs/msg/Imu', 'geometry_msgs/msg/Vector3Stamped'])
def test_decode_block_declines_what_decode_reads_otherwise(type_name, damage, rng):
    """One damaged message declines the block: decode raises, or reads what encode rewrites."""
    codec = fixed_layout_codec(type_name)
    datas = [codec.encode(_message(type_name, 'imu', rng)) for _ in range(6)]
    assert codec.decode_block(datas) is not None
    datas[4] = _damaged(datas[4], damage)
    assert codec.decode_block(datas) is None
    try:
        assert codec.encode(codec.decode(datas[4])) != datas[4]
    except BagError:
        pass


def test_decode_block_of_nothing_is_none():
    assert fixed_layout_codec('sensor_msgs/msg/Imu').decode_block([]) is None


def test_decoded_blocks_are_read_only(rng):
    codec = fixed_layout_codec('sensor_msgs/msg/Imu')
    block = codec.decode_block([codec.encode(_message('sensor_msgs/msg/Imu', 'a', rng))])
    with pytest.raises(ValueError, match='read-only'):
        block.records[0]['orientation.x'] = 1.0
