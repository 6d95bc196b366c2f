"""
Block conversion (rotation_node.bag.block_convert) against the per-message pipeline.

The oracle is the live node's ConversionPipeline fed message by message (the
path ``convert(..., blocks=False)`` takes): the block form must give the same
output bytes, counters, per-stream state and reports, on scenes with every
sensor effect and on generated streams of every input type and every output
with a block form.
"""
import math
import operator
import os

from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from rotation_node import registry
from rotation_node.bag.block_convert import (
    block_form_missing, BLOCK_MESSAGES, converted_blocks, TopicConverter)
from rotation_node.bag.convert import convert, output_topic
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.records import BagMessage
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters
from rotation_node.pipeline import output_has_block_form
from rotation_node.scene import load_scene, simulate, write_bag
from rotation_node.wire.cdr import fixed_layout_codec

HERE = os.path.dirname(os.path.abspath(__file__))
EVERY_EFFECT = os.path.join(HERE, os.pardir, 'config', 'scenes', 'every_effect.yaml')
PLAIN_INPUTS = [name for name, entry in registry.INPUTS.items() if entry.stream is None]


def _outputs_for(input_type):
    """Every output with a block form (all of them need only what every input gives)."""
    return tuple(name for name in registry.OUTPUTS if output_has_block_form(name))


def _converter_outputs(params, topic='/in'):
    return {name: (output_topic(topic, name), registry.OUTPUTS[name].type_name,
                   registry.OUTPUTS[name].message.encoder()) for name in params.outputs}


def _run(params, records, splits, *, blocks):
    """Convert ``records`` cut into blocks at ``splits``; outputs, stats, reports and state."""
    reports = []
    converter = TopicConverter(params, _converter_outputs(params), blocks=blocks)
    converter.pipeline.on_issue = lambda reason, detail: reports.append((reason, detail))
    outputs = []
    bounds = [0, *sorted(set(splits)), len(records)]
    for start, stop in zip(bounds[:-1], bounds[1:]):
        if stop > start:
            outputs += converter.convert(records[start:stop])
    pipeline = converter.pipeline
    state = (pipeline.state.previous_quaternion, pipeline.state.previous_stamp_ns,
             pipeline.state.previous_output_quaternion, pipeline.state.previous_euler)
    return outputs, pipeline.stats, reports, state, converter.block_form_missing


def _same_state(a, b):
    for x, y in zip(a, b):
        if x is None or y is None:
            assert x is None and y is None
        else:
            assert np.array_equal(np.asarray(x), np.asarray(y))
            assert np.asarray(x).tobytes() == np.asarray(y).tobytes()


def assert_block_form_exact(params, records, splits=()):
    """Assert the block form gives the per-message pipeline's bytes, counters, reports, state."""
    expected = _run(params, records, splits, blocks=False)
    got = _run(params, records, splits, blocks=True)
    assert got[4] is None, got[4]   # really converted in blocks
    assert got[0] == expected[0]
    assert got[1] == expected[1]
    assert got[2] == expected[2]
    _same_state(got[3], expected[3])
    return expected


# ------------------------------------------------------------------ generated streams

def _set(message, path, values):
    target = operator.attrgetter(path)(message)
    for name, value in zip('xyzw', values):
        setattr(target, name, value)


_SPECIAL = [0.0, -0.0, 1.0, -1.0, 1e-160, 1e160, 0.5, math.nan, math.inf]
_component = st.one_of(st.floats(-2.0, 2.0), st.sampled_from(_SPECIAL))


@st.composite
def _streams(draw, input_type):
    """CDR records of one input type: repeated and decreasing stamps, flips, NaN, gimbal, zero."""
    entry = registry.INPUTS[input_type]
    n = draw(st.integers(1, 40))
    width = 4 if entry.orientation_form == registry.QUATERNION else 3
    codec = fixed_layout_codec(entry.type_name)
    stamp_ns = 1_700_000_000_000_000_000
    frame_id = draw(st.sampled_from(['imu_link', 'x', 'base_link_é', '']))
    records, previous = [], None
    for _ in range(n):
        msg = entry.message_class()
        stamp_ns += draw(st.sampled_from([10_000_000, 10_000_000, 1, 0, -5_000_000]))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        msg.header.frame_id = frame_id
        kind = draw(st.sampled_from(['random', 'random', 'flip', 'gimbal', 'special', 'zero']))
        if kind == 'zero':   # a quaternion (0, 0, 0, 0): orientation not estimated
            values = [draw(st.sampled_from([0.0, -0.0])) for _ in range(width)]
        elif kind == 'flip' and previous is not None:
            values = [-v for v in previous]
        elif kind == 'gimbal':
            values = ([0.5, 0.5, 0.5, 0.5] if width == 4
                      else [draw(st.floats(-3, 3)), math.pi / 2, draw(st.floats(-3, 3))])
        elif kind == 'special':
            values = [draw(_component) for _ in range(width)]
        else:
            values = [draw(st.floats(-1.0, 1.0)) for _ in range(width)]
            scale = draw(st.sampled_from([1.0, 1.0, 1.0 + 1e-9, 1.3, 1e-3]))
            norm = math.sqrt(sum(v * v for v in values)) if width == 4 else 1.0
            if norm > 0:
                values = [v / norm * scale for v in values]
        previous = values
        _set(msg, entry.orientation_field, values)
        if entry.angular_velocity_field is not None:
            rate = [draw(st.floats(-5, 5)) for _ in range(3)]
            if draw(st.integers(0, 15)) == 0:
                rate[1] = math.nan
            _set(msg, entry.angular_velocity_field, rate)
        if entry.orientation_unknown_field is not None and draw(st.integers(0, 6)) == 0:
            operator.attrgetter(entry.orientation_unknown_field)(msg)[0] = -1.0
        if entry.angular_velocity_unknown_field is not None and draw(st.booleans()):
            operator.attrgetter(entry.angular_velocity_unknown_field)(msg)[0] = -1.0
        records.append(BagMessage('/in', entry.type_name, codec.encode(msg), stamp_ns, stamp_ns))
    splits = draw(st.lists(st.integers(0, n), max_size=3))
    return records, splits


_parameters = st.fixed_dictionaries({
    'euler_sequence': st.sampled_from(['xyz', 'ZYX', 'zxz', 'YXY']),
    'euler_degrees': st.booleans(),
    'euler_unwrap': st.booleans(),
    'quaternion_continuity': st.booleans(),
    'euler_singularity_threshold': st.sampled_from([1e-6, 0.1]),
    'quaternion_norm_tolerance': st.sampled_from([1e-6, 0.01]),
    'angular_velocity_input_frame': st.sampled_from(['body', 'world']),
    'angular_velocity_output_frame': st.sampled_from(['body', 'world']),
    'mounting_body_rotation': st.sampled_from([(0.0, 0.0, 0.0, 1.0), (10.0, -80.0, 135.0)]),
    'mounting_world_rotation': st.sampled_from([(0.0, 0.0, 0.0, 1.0),
                                                (0.5, -0.5, 0.5, 0.5)]),
    'mounting_yaw_offset': st.sampled_from([0.0, 0.3]),
})


@pytest.mark.slow
@pytest.mark.parametrize('input_type', PLAIN_INPUTS)
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_generated_streams_match_the_per_message_pipeline(input_type, data):
    values = data.draw(_parameters)
    params = NodeParameters(input_type=input_type, outputs=_outputs_for(input_type), **values)
    records, splits = data.draw(_streams(input_type))
    assert_block_form_exact(params, records, splits)


# ------------------------------------------------------------------ scenes and bags

@pytest.fixture(scope='module')
def every_effect_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp('scene') / 'every_effect.mcap'
    write_bag(simulate(load_scene(EVERY_EFFECT), seed=3), path)
    return path


def _imu_records(path):
    with BagReader(path) as reader:
        return list(reader.messages(['/imu']))


@pytest.mark.parametrize('values', [
    {},
    {'euler_degrees': True, 'euler_sequence': 'ZXZ', 'quaternion_continuity': True},
    {'angular_velocity_output_frame': 'world', 'euler_unwrap': False},
    {'mounting_body_rotation': (0.1, -0.2, 0.3, 0.9273618495495703),
     'mounting_world_rotation': (3.0, -2.0, 47.0), 'mounting_magnetic_declination': -0.2,
     'angular_velocity_output_frame': 'world', 'quaternion_continuity': True},
])
def test_every_effect_scene_matches_the_per_message_pipeline(every_effect_bag, values):
    params = NodeParameters(input_type='imu', outputs=_outputs_for('imu'), **values)
    records = _imu_records(every_effect_bag)
    outputs, stats, reports, _, _ = assert_block_form_exact(params, records, [150, 151, 333])
    # Every effect shows up in the counters the block form reproduced.
    assert stats.dropped['non_finite_orientation'] > 0
    assert stats.skipped['orientation_unknown'] > 0
    assert stats.skipped['non_finite_angular_velocity'] > 0
    assert stats.normalised > 0
    assert sum(map(len, outputs)) == stats.published


@pytest.mark.slow
def test_convert_writes_the_same_messages_in_blocks(every_effect_bag, tmp_path):
    params = NodeParameters(input_type='imu', outputs=_outputs_for('imu'), euler_unwrap=True)
    stats = {}
    for blocks in (True, False):
        stats[blocks] = convert(every_effect_bag, tmp_path / f'{blocks}.mcap', params,
                                blocks=blocks)
    assert stats[True] == stats[False]
    with BagReader(tmp_path / 'True.mcap') as a, BagReader(tmp_path / 'False.mcap') as b:
        assert a.topic_metadata == b.topic_metadata
        for x, y in zip(a.messages(), b.messages(), strict=True):
            assert (x.topic, x.data, x.log_time_ns, x.publish_time_ns) == (
                y.topic, y.data, y.log_time_ns, y.publish_time_ns)


def test_blocks_hold_a_bounded_number_of_records():
    class Record:
        topic = '/other'

    blocks = list(converted_blocks(iter([Record()] * (2 * BLOCK_MESSAGES + 5)), {}))
    assert [len(block) for block in blocks] == [BLOCK_MESSAGES, BLOCK_MESSAGES, 5]
    assert all(outputs is None for block in blocks for _, outputs in block)


# ------------------------------------------------------------------ fallbacks

def test_outputs_without_a_block_form_go_message_by_message(every_effect_bag):
    params = NodeParameters(input_type='imu', outputs=('euler', 'euler_stddev'))
    assert 'euler_stddev' in block_form_missing(params)
    records = _imu_records(every_effect_bag)[:200]
    expected = _run(params, records, (), blocks=False)
    got = _run(params, records, (), blocks=True)
    assert got[4] is not None
    assert got[:3] == expected[:3]


def test_frame_conversion_goes_message_by_message():
    params = NodeParameters(input_type='imu', outputs=('euler',), frames_input_world='ned')
    assert 'frame' in block_form_missing(params)


def _imu_record(stamp_ns, data=None):
    entry = registry.INPUTS['imu']
    msg = entry.message_class()
    msg.header.frame_id = 'imu'
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.orientation.w = 1.0
    msg.orientation.z = stamp_ns * 1e-12
    if data is None:
        data = fixed_layout_codec(entry.type_name).encode(msg)
    return BagMessage('/in', entry.type_name, data, stamp_ns, stamp_ns)


def _outcome(params, records, blocks):
    """Return what converting gives: the outputs, counters and reports, or the error line."""
    try:
        return _run(params, records, (), blocks=blocks)[:3]
    except BagError as error:
        return str(error)


@pytest.mark.parametrize('damage', ['not_little_endian', 'truncated', 'frame_id_without_nul',
                                    'frame_id_not_utf8', 'empty_frame_id'])
def test_blocks_the_block_form_cannot_read_go_message_by_message(damage):
    records = [_imu_record(10_000_000 * (k + 1)) for k in range(20)]
    data = bytearray(records[7].data)
    nul = 4 + 12 + len('imu')   # the frame_id's NUL
    if damage == 'not_little_endian':
        data[1] = 0   # representation identifier 00 00: big-endian CDR
    elif damage == 'truncated':
        del data[-9:]
    elif damage == 'frame_id_without_nul':
        data[nul] = ord('!')
    elif damage == 'frame_id_not_utf8':
        data[nul - 1] = 0xff
    else:
        data[12:16] = bytes(4)   # length 0: no bytes, no NUL
        del data[16:nul + 1]
    records[7] = BagMessage('/in', records[7].type_name, bytes(data), 8, 8)
    params = NodeParameters(input_type='imu', outputs=('euler', 'quaternion', 'matrix'))
    expected = _outcome(params, records, False)
    assert _outcome(params, records, True) == expected
    if damage in ('frame_id_without_nul', 'frame_id_not_utf8'):
        assert not isinstance(expected, str)   # converted, frame_id rewritten as rclpy reads it
