"""
Tests of rotation_node.registry: the registry of input and output message types.

Each input entry is checked to read the fields a hand-written table (independent
of the registry) names, from rclpy messages and from CDR views alike; each
output entry to build a message whose encoding is the bytes rclpy serialises
(zero padding, byte for byte against rosbags); the parameters, the pipeline's
values and the plot panels to agree with the registry; and the extension
points (a stateful input stream, an input-stage transform) to work as one entry.
"""
import dataclasses
import operator
import sys
import types

from bag_helpers import random_message
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from ros_harness import oracle_output
from rosbags.typesys import get_typestore, Stores
from rotation_node import parameters, pipeline, registry
from rotation_node.parameters import NodeParameters
from rotation_node.registry import INPUTS, OutputMessage, OUTPUTS, Sample
from rotation_node.wire.cdr import fixed_layout_codec
from rotation_node.wire.message_types import message_class
from rotation_node.wire.stamps import split_ns
from scipy.spatial.transform import Rotation

# Written from the message definitions, not from the registry.
EXPECTED_INPUT_FIELDS = {
    # name: (type, orientation field, angular velocity field, covariance (field, 6x6?))
    'quaternion': ('geometry_msgs/msg/QuaternionStamped', 'quaternion', None, None),
    'pose': ('geometry_msgs/msg/PoseStamped', 'pose.orientation', None, None),
    'pose_with_covariance': ('geometry_msgs/msg/PoseWithCovarianceStamped',
                             'pose.pose.orientation', None, ('pose.covariance', 6)),
    'imu': ('sensor_msgs/msg/Imu', 'orientation', 'angular_velocity',
            ('orientation_covariance', 3)),
    'odometry': ('nav_msgs/msg/Odometry', 'pose.pose.orientation', 'twist.twist.angular',
                 ('pose.covariance', 6)),
    'transform': ('geometry_msgs/msg/TransformStamped', 'transform.rotation', None, None),
    'euler': ('geometry_msgs/msg/Vector3Stamped', 'vector', None, None),
    'rotation_vector': ('geometry_msgs/msg/Vector3Stamped', 'vector', None, None),
    'tf': ('tf2_msgs/msg/TFMessage', 'transforms', None, None),   # a stream (test_tf_input)
}
PLAIN_INPUTS = [name for name, entry in INPUTS.items() if entry.stream is None]


@pytest.fixture(scope='module')
def rosbags_store():
    return get_typestore(Stores.ROS2_JAZZY)


def _components(field):
    names = ('x', 'y', 'z', 'w') if hasattr(field, 'w') else ('x', 'y', 'z')
    return tuple(getattr(field, name) for name in names)


def test_the_parameters_offer_exactly_the_registry():
    assert parameters.INPUT_TYPES == tuple(INPUTS) == tuple(EXPECTED_INPUT_FIELDS)
    assert parameters.OUTPUTS == tuple(OUTPUTS)
    spec = parameters.PARAMETERS_BY_NAME
    assert spec['input_type'].choices == tuple(INPUTS)
    assert spec['outputs'].choices == tuple(OUTPUTS)


@pytest.mark.parametrize('name', PLAIN_INPUTS)
def test_each_input_reads_its_fields(name):
    type_name, orientation, rate, covariance = EXPECTED_INPUT_FIELDS[name]
    entry = INPUTS[name]
    assert entry.type_name == type_name and entry.message_class is message_class(type_name)
    rng = np.random.default_rng(len(name))
    for _ in range(5):
        msg = random_message(entry.message_class, rng)
        if name == 'imu':   # known orientation and rate
            msg.orientation_covariance[0] = msg.angular_velocity_covariance[0] = 0.5
        view = fixed_layout_codec(type_name).decode(serialize_message(msg))
        for source in (msg, view):
            sample = entry.sample_reader(covariance=True)(source)
            assert sample.header is source.header
            assert sample.orientation == _components(operator.attrgetter(orientation)(msg))
            expected_rate = (None if rate is None
                             else _components(operator.attrgetter(rate)(msg)))
            assert sample.angular_velocity == expected_rate
            if covariance is None:
                assert sample.covariance is None
            else:
                path, size = covariance
                full = np.asarray(operator.attrgetter(path)(msg)).reshape(size, size)
                assert sample.covariance == tuple(full[-3:, -3:].ravel())
            assert entry.sample_reader()(source).covariance is None   # only on request
            assert list(entry.sample_stream(None)('input', source)) == [
                entry.sample_reader()(source)]


def test_imu_flags_unknown_orientation_and_rate():
    msg = message_class('sensor_msgs/msg/Imu')()
    msg.orientation_covariance[0] = -1.0
    msg.angular_velocity_covariance[0] = -1.0
    sample = INPUTS['imu'].sample_reader()(msg)
    assert sample.orientation is None and sample.angular_velocity is None
    msg.orientation_covariance[0] = 0.0
    assert INPUTS['imu'].sample_reader()(msg).orientation == (0.0, 0.0, 0.0, 1.0)


def _numbers_count(output):
    if output.message.layout is not None:
        return output.message.layout.dim[0].stride
    return len(output.message.numbers(output.message_class()))


@pytest.mark.parametrize('name', OUTPUTS)
def test_each_output_encodes_what_rclpy_serialises(name, rosbags_store):
    output = OUTPUTS[name]
    encode = output.message.encoder()
    rng = np.random.default_rng(len(name))
    header = message_class('std_msgs/msg/Header')()
    for frame_id in ('', 'a', 'imu_link', 'caf\u00e9'):
        header.stamp.sec, header.stamp.nanosec = split_ns(int(rng.integers(0, 2**31 * 10**9)))
        header.frame_id = frame_id
        numbers = rng.normal(size=_numbers_count(output)).tolist()
        msg = output.message.build(header, numbers)
        assert isinstance(msg, output.message_class)
        assert list(output.message.numbers(msg)) == numbers
        data = encode(header, numbers)
        rclpy_data = serialize_message(msg)
        assert len(data) == len(rclpy_data)
        assert deserialize_message(data, output.message_class) == msg
        reference = bytes(rosbags_store.serialize_cdr(
            rosbags_store.deserialize_cdr(rclpy_data, output.type_name), output.type_name))
        assert data == reference + bytes(len(rclpy_data) - len(reference))


def test_an_output_of_a_type_without_a_fixed_layout_is_serialised_by_rclpy():
    def build(header, numbers):
        msg = message_class('sensor_msgs/msg/JointState')()
        msg.header, msg.name, msg.position = header, ['a', 'b'], list(numbers)
        return msg
    joints = OutputMessage('sensor_msgs/msg/JointState', build, lambda msg: msg.position)
    header = message_class('std_msgs/msg/Header')(frame_id='base')
    data = joints.encoder()(header, [1.5, -2.0])
    assert deserialize_message(data, joints.message_class) == build(header, [1.5, -2.0])


def test_stamped_numbers_of_a_type_without_a_fixed_layout_is_refused():
    joints = OutputMessage('sensor_msgs/msg/JointState', lambda header, numbers: None,
                           lambda msg: msg.position, stamped_numbers=True)
    with pytest.raises(ValueError, match='stamped_numbers: sensor_msgs/msg/JointState'):
        joints.encoder()


def test_every_pipeline_value_comes_after_those_it_depends_on():
    seen = set()
    for value in pipeline.VALUES:
        assert set(value.requires) | set(value.uses) <= seen, value.name
        seen.add(value.name)
    assert seen == set(registry.PIPELINE_VALUES)
    for output in OUTPUTS.values():
        assert output.needs and set(output.needs) <= seen, output.name


def _stream_input(monkeypatch):
    """Register a stateful two-topic input: topic 'frames' sets the frame, 'data' gives samples."""
    def stream(params, report):
        state = {'frame': None}

        def samples(topic, msg):
            if topic == 'frames':
                state['frame'] = msg.header.frame_id
                return ()
            if state['frame'] is None:
                report('no_frame', 'no frame yet')
                return ()
            header = message_class('std_msgs/msg/Header')(
                stamp=msg.header.stamp, frame_id=state['frame'])
            return (Sample(header, _components(msg.quaternion)),)
        return samples
    module = types.ModuleType('frames_stream')   # what InputType.stream names
    module.sample_stream, module.DROP_REASONS = stream, ('no_frame',)
    monkeypatch.setitem(sys.modules, module.__name__, module)
    entry = dataclasses.replace(
        INPUTS['quaternion'], name='stream', topics=(registry.InputTopic('data'),
                                                     registry.InputTopic('frames', True)),
        stream=module.__name__)
    monkeypatch.setitem(INPUTS, 'stream', entry)
    params = NodeParameters(outputs=('quaternion', 'euler'))
    object.__setattr__(params, 'input_type', 'stream')   # not a parameter choice: a test entry
    return params


def test_a_stateful_input_stream_is_one_entry(monkeypatch):
    p = pipeline.ConversionPipeline(_stream_input(monkeypatch))
    rotation = Rotation.from_rotvec([0.3, -0.2, 1.1])
    msg = message_class('geometry_msgs/msg/QuaternionStamped')()
    msg.quaternion.x, msg.quaternion.y, msg.quaternion.z, msg.quaternion.w = rotation.as_quat()
    assert p.process(msg, 'data') == []      # no frame yet: no sample
    frames = message_class('geometry_msgs/msg/QuaternionStamped')()
    frames.header.frame_id = 'world'
    assert p.process(frames, 'frames') == []
    outputs = dict(p.process(msg, 'data'))
    assert outputs['euler'].header.frame_id == 'world'
    np.testing.assert_allclose(
        _components(outputs['euler'].vector), oracle_output('euler', rotation), atol=1e-12)
    assert (p.stats.received, p.stats.published) == (3, 2)
    assert p.stats.dropped == {'no_frame': 1} and p.drop_reasons[-1] == 'no_frame'


def test_an_input_stage_transform_changes_every_sample(monkeypatch):
    turn = Rotation.from_euler('z', 90, degrees=True)

    def factory(params):
        def turned(sample):
            q = (turn * Rotation.from_quat(sample.orientation)).as_quat()
            return sample._replace(orientation=tuple(q))
        return turned
    monkeypatch.setattr(pipeline, 'SAMPLE_TRANSFORMS', [factory, lambda params: None])
    p = pipeline.ConversionPipeline(NodeParameters(input_type='quaternion', outputs=('matrix',)))
    rotation = Rotation.from_rotvec([0.1, 0.2, 0.3])
    msg = message_class('geometry_msgs/msg/QuaternionStamped')()
    msg.quaternion.x, msg.quaternion.y, msg.quaternion.z, msg.quaternion.w = rotation.as_quat()
    (_, out), = p.process(msg)
    np.testing.assert_allclose(out.data, (turn * rotation).as_matrix().ravel(), atol=1e-12)


@pytest.mark.parametrize('outputs, reads_rate', [
    (('euler',), False), (('angular_velocity',), True), (('quaternion_rate', 'matrix'), True)])
def test_samples_carry_the_angular_velocity_only_when_a_value_reads_it(
        monkeypatch, outputs, reads_rate):
    seen = []
    monkeypatch.setattr(pipeline, 'SAMPLE_TRANSFORMS',
                        [lambda params: lambda sample: seen.append(sample) or sample])
    p = pipeline.ConversionPipeline(NodeParameters(input_type='imu', outputs=outputs))
    msg = message_class('sensor_msgs/msg/Imu')()
    msg.orientation.w, msg.angular_velocity.z = 1.0, 0.5
    p.process(msg)
    assert seen[0].angular_velocity == ((0.0, 0.0, 0.5) if reads_rate else None)
    assert seen[0].covariance is None   # no value reads it yet
