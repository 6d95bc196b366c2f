"""
Tests of rotation_node.bag.convert: offline conversion equals the live node.

The in-process tests check ``convert`` against the ``ConversionPipeline`` fed
message by message; the round trip records a live publisher, plays the bag
into a running ``rotation_node``, records its outputs and checks that
``rotation_bag convert`` produced the same messages (values, stamps, count).
"""
import operator
import os

from bag_helpers import imu_messages, plain, stamp_ns
import pytest
from rclpy.duration import Duration
from rclpy.qos import QoSProfile
from ros_harness import make_input_message, PLAIN_INPUT_TYPES, RosProcess, script, TestNode
from rotation_node.bag.cli import main as cli_main
from rotation_node.bag.convert import convert, output_topic
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters, parameters_from_yaml
from rotation_node.pipeline import ConversionPipeline
from rotation_node.registry import INPUTS
from rotation_node.registry import OUTPUTS as OUTPUT_TYPES
from rotation_node.wire.cdr import message_encoder
from rotation_node.wire.message_types import type_name_of
from rotation_node.wire.qos import qos_profile, qos_profiles_from_yaml
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu
import yaml

OUTPUTS = ('euler', 'quaternion', 'angular_velocity')
PARAMS = NodeParameters(input_type='imu', outputs=OUTPUTS, euler_sequence='ZYX',
                        euler_degrees=True, qos_depth=1000)
ALL_OUTPUTS = tuple(OUTPUT_TYPES)


def _write_bag(path, streams):
    """``streams``: {topic: [msg, ...]}; log time = stamp + 1 ms, interleaved by time."""
    rows = sorted(((stamp_ns(msg) + 1_000_000, topic, msg)
                   for topic, messages in streams.items() for msg in messages),
                  key=lambda row: row[0])
    with BagWriter(path) as writer:
        for log_time, topic, msg in rows:
            writer.write(topic, msg, log_time)


def _outputs(path, topic):
    """``[(stamp ns, plain message)]`` of one topic of a bag."""
    with BagReader(path) as reader:
        return [(stamp_ns(m), plain(m)) for m in
                (record.message() for record in reader.messages([topic]))]


def _output_bytes(path, topic):
    """Return the serialised messages of one topic of a bag, in order."""
    with BagReader(path) as reader:
        return [bytes(record.data) for record in reader.messages([topic])]


def _expected(params, messages):
    """Return what the pipeline gives, message by message: {output name: [plain message]}."""
    pipeline = ConversionPipeline(params)
    expected = {name: [] for name in params.outputs}
    for msg in messages:
        for name, out in pipeline.process(msg):
            expected[name].append((stamp_ns(out), plain(out)))
    return expected


def test_convert_adds_pipeline_outputs_and_copies_everything(tmp_path, rng):
    messages = imu_messages(rng, 50)
    source, output = tmp_path / 'in.mcap', tmp_path / 'out.mcap'
    _write_bag(source, {'/imu': messages})
    stats = convert(source, output, PARAMS)
    assert stats['/imu'].received == 50 and stats['/imu'].published == 150
    expected = _expected(PARAMS, messages)
    for name in OUTPUTS:
        assert _outputs(output, f'/imu/{name}') == expected[name]
    with BagReader(source) as original, BagReader(output) as converted:
        assert converted.topics == {'/imu': 'sensor_msgs/msg/Imu',
                                    '/imu/euler': 'geometry_msgs/msg/Vector3Stamped',
                                    '/imu/quaternion': 'geometry_msgs/msg/QuaternionStamped',
                                    '/imu/angular_velocity': 'geometry_msgs/msg/Vector3Stamped'}
        assert converted.topic_metadata['/imu'] == original.topic_metadata['/imu']
        assert [(m.data, m.log_time_ns) for m in converted.messages(['/imu'])] == [
            (m.data, m.log_time_ns) for m in original.messages()]
        assert [m.log_time_ns for m in converted.messages(['/imu/euler'])] == [
            m.log_time_ns for m in original.messages()]
        offered, = qos_profiles_from_yaml(
            converted.topic_metadata['/imu/euler'].offered_qos_profiles)
        assert offered == qos_profile(PARAMS)


@pytest.mark.parametrize('input_type', PLAIN_INPUT_TYPES)
def test_every_input_type_and_output_is_the_pipelines_byte_for_byte(tmp_path, rng, input_type):
    """``convert`` reads cdr views and encodes values: the same bytes as process()'s messages."""
    params = NodeParameters(input_type=input_type, outputs=ALL_OUTPUTS, euler_unwrap=True,
                            quaternion_continuity=True, angular_velocity_output_frame='world')
    stamps = [1_700_000_000_000_000_000 + 10_000_000 * i for i in range(30)]
    stamps[12] = stamps[11]   # not increasing: no finite-difference outputs
    messages = [make_input_message(input_type, Rotation.random(random_state=rng),
                                   omega=rng.normal(size=3), stamp_ns=stamp, frame_id='base_link')
                for stamp in stamps]
    if input_type == 'imu':
        messages[5].orientation_covariance[0] = -1.0
        messages[20].angular_velocity_covariance[0] = -1.0
    entry = INPUTS[input_type]
    reasons = set()
    if entry.orientation_form == 'quaternion':   # "not estimated", the other form
        q = operator.attrgetter(entry.orientation_field)(messages[8])
        q.x = q.y = q.z = q.w = 0.0
        reasons.add('zero_quaternion')
    if entry.covariance_field is not None:   # DBL_MAX as "unknown", a negative variance
        for k, block in ((15, (1e308, 0, 0, 0, 1e308, 0, 0, 0, 1e308)),
                         (25, (-1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6))):
            cov = operator.attrgetter(entry.covariance_field)(messages[k])
            for index, value in zip(entry.covariance_indices, block):
                cov[index] = float(value)
        reasons |= {'covariance_too_large', 'invalid_covariance'}
    source, output = tmp_path / 'in.mcap', tmp_path / 'out.mcap'
    _write_bag(source, {'/in': messages})
    stats = convert(source, output, params)
    assert reasons <= set(stats['/in'].skipped) and not stats['/in'].dropped
    pipeline = ConversionPipeline(params)
    expected = {name: [] for name in ALL_OUTPUTS}
    for msg in messages:
        for name, out in pipeline.process(msg):
            expected[name].append(message_encoder(type_name_of(type(out)))(out))
    has_covariance = INPUTS[input_type].covariance_field is not None
    assert stats['/in'] == pipeline.stats
    assert all(expected[name] for name in ALL_OUTPUTS
               if has_covariance or name not in ('euler_stddev', 'euler_covariance'))
    with BagReader(output) as reader:
        for name in ALL_OUTPUTS:
            assert [r.data for r in reader.messages([f'/in/{name}'])] == expected[name], name


def test_one_pipeline_per_topic(tmp_path, rng):
    """Finite differences (Imu without angular velocity) must not mix interleaved topics."""
    streams = {topic: imu_messages(rng, 20, start_ns=1_700_000_000_000_000_000 + offset)
               for topic, offset in (('/a/imu', 0), ('/b/imu', 3_000_000))}
    for msg in streams['/a/imu'] + streams['/b/imu']:
        msg.angular_velocity_covariance[0] = -1.0
    source, output = tmp_path / 'in.mcap', tmp_path / 'out.mcap'
    _write_bag(source, streams)
    convert(source, output, PARAMS)
    for topic, messages in streams.items():
        assert _outputs(output, output_topic(topic, 'angular_velocity')) == \
            _expected(PARAMS, messages)['angular_velocity']


def test_topic_selection(tmp_path, rng):
    source, output = tmp_path / 'in.mcap', tmp_path / 'out.mcap'
    _write_bag(source, {'/a': imu_messages(rng, 5), '/b': imu_messages(rng, 5)})
    convert(source, output, PARAMS, topics=['/b'])
    with BagReader(output) as reader:
        assert sorted(reader.topics) == ['/a', '/b', '/b/angular_velocity', '/b/euler',
                                         '/b/quaternion']


@pytest.mark.parametrize('topics, params, match', [
    (['/nope'], PARAMS, '/nope not in'),
    (['/imu'], NodeParameters(input_type='quaternion'),
     '/imu .* is sensor_msgs/msg/Imu, but input_type expects geometry_msgs/msg/QuaternionStamped'),
    (None, NodeParameters(input_type='pose'), 'has no geometry_msgs/msg/PoseStamped topic'),
])
def test_bad_topics(tmp_path, rng, topics, params, match):
    source = tmp_path / 'in.mcap'
    _write_bag(source, {'/imu': imu_messages(rng, 3)})
    before = source.read_bytes()
    with pytest.raises(BagError, match=match):
        convert(source, tmp_path / 'out.mcap', params, topics=topics)
    assert os.listdir(tmp_path) == ['in.mcap'] and source.read_bytes() == before


def test_output_topic_already_in_input(tmp_path, rng):
    source = tmp_path / 'in.mcap'
    _write_bag(source, {'/imu': imu_messages(rng, 3)})
    convert(source, tmp_path / 'once.mcap', PARAMS)
    with pytest.raises(BagError, match='/imu/euler.* already in .*once.mcap'):
        convert(tmp_path / 'once.mcap', tmp_path / 'twice.mcap', PARAMS)
    assert not (tmp_path / 'twice.mcap').exists()


def test_refuses_to_overwrite_input_or_existing_output(tmp_path, rng):
    source, output = tmp_path / 'in.mcap', tmp_path / 'out.mcap'
    _write_bag(source, {'/imu': imu_messages(rng, 3)})
    before = source.read_bytes()
    with pytest.raises(BagError, match='is the input bag'):
        convert(source, source, PARAMS, overwrite=True)
    output.write_bytes(b'keep me')
    with pytest.raises(BagError, match='out.mcap already exists'):
        convert(source, output, PARAMS)
    assert output.read_bytes() == b'keep me' and source.read_bytes() == before
    convert(source, output, PARAMS, overwrite=True)
    assert BagReader(output).message_counts['/imu/euler'] == 3


@pytest.mark.slow
def test_corrupt_chunk_leaves_no_output(tmp_path, rng):
    source, output = tmp_path / 'in.mcap', tmp_path / 'out.mcap'
    _write_bag(source, {'/imu': imu_messages(rng, 8000)})   # several chunks
    data = bytearray(source.read_bytes())
    data[len(data) // 2:len(data) // 2 + 64] = b'\xff' * 64
    source.write_bytes(bytes(data))
    with pytest.raises(BagError, match=r'in.mcap: .*could not be read.*refused \(--strict\)'):
        convert(source, output, PARAMS, strict=True)
    assert os.listdir(tmp_path) == ['in.mcap'] and source.read_bytes() == bytes(data)


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_live_node_round_trip_equals_convert(tmp_path, rng):
    """``record`` a publisher -> play into rotation_node -> record its outputs == convert."""
    count = 200
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'/**/rotation_node': {'ros__parameters': {
        'input_type': 'imu', 'outputs': list(OUTPUTS),
        'euler': {'sequence': 'ZYX', 'degrees': True}, 'qos': {'depth': 1000}}}}))
    assert parameters_from_yaml(params_file) == PARAMS
    recorded_input, recorded_output = tmp_path / 'input.mcap', tmp_path / 'node_output.mcap'
    converted = tmp_path / 'converted.mcap'
    messages = imu_messages(rng, count)
    output_topics = [f'/imu/{name}' for name in OUTPUTS]

    with TestNode('round_trip') as client:
        # 1. Record a live publisher.
        publisher = client.node.create_publisher(Imu, '/imu', QoSProfile(depth=count))
        with RosProcess([script('rotation_bag'), 'record', recorded_input,
                         '--topics', '/imu']) as recorder:
            assert client.wait_for_subscriber(publisher, timeout=30)
            for msg in messages:
                publisher.publish(msg)
            assert publisher.wait_for_all_acked(Duration(seconds=20))
            assert recorder.stop() == 0, recorder.output
        client.node.destroy_publisher(publisher)
        with BagReader(recorded_input) as reader:
            assert [plain(r.message()) for r in reader.messages()] == [plain(m) for m in messages]

        # 2. Play it into the node, record the node's outputs.
        received = {topic: client.collect(OUTPUT_TYPES[topic.rsplit('/', 1)[-1]].message_class,
                                          topic, QoSProfile(depth=count))
                    for topic in output_topics}
        node_args = [script('rotation_node'), '--ros-args', '--params-file', params_file,
                     '-r', '__ns:=/imu', '-r', 'input:=/imu']
        with RosProcess(node_args) as node, \
                RosProcess([script('rotation_bag'), 'record', recorded_output,
                            '--topics', *output_topics]) as recorder:
            assert client.spin_until(
                lambda: all(client.node.count_subscribers(t) >= 2 for t in output_topics)
                and client.node.count_subscribers('/imu') >= 1, timeout=60), node.output
            player = RosProcess([script('rotation_bag'), 'play', recorded_input, '--rate', '0'])
            assert client.spin_until(lambda: not player.alive(), timeout=60)
            assert player.stop() == 0, player.output
            assert client.spin_until(
                lambda: all(len(r) >= count for r in received.values()), timeout=30)
            client.spin_for(0.5)   # the recorder takes them at the same time
            assert recorder.stop() == 0, recorder.output
            assert node.stop() == 0, node.output

    # 3. Convert the recorded input offline (the command, in-process) and compare.
    assert cli_main(['convert', str(recorded_input), str(converted),
                     '--params', str(params_file)]) == 0
    for topic in output_topics:
        live, offline = _outputs(recorded_output, topic), _outputs(converted, topic)
        assert len(live) == len(offline) == count
        assert live == offline
        # The node publishes the bytes convert writes (the same encoders), bit for bit.
        assert _output_bytes(recorded_output, topic) == _output_bytes(converted, topic)


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_px4_imu_with_covariance_live_node_equals_convert(tmp_path, rng):
    """An NED/FRD Imu stream with covariance: live rotation_node == rotation_bag convert."""
    count = 100
    outputs = ['euler', 'euler_stddev', 'euler_covariance', 'angular_velocity', 'quaternion']
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'/**/rotation_node': {'ros__parameters': {
        'input_type': 'imu', 'outputs': outputs, 'euler': {'degrees': True},
        'covariance': {'frame': 'body'},
        'frames': {'input_world': 'ned', 'input_body': 'frd'}, 'qos': {'depth': 1000}}}}))
    messages = imu_messages(rng, count, orientation_variance=(1e-5, 2e-5, 3e-5))
    messages[7].orientation_covariance = [0.0] * 9          # unknown: no uncertainty output
    messages[9].orientation_covariance[0] = -1.0             # orientation unknown
    # the angular velocity is FRD -> FLU without the orientation; the rest needs it
    expected_counts = {'euler': count - 1, 'quaternion': count - 1, 'angular_velocity': count,
                       'euler_stddev': count - 2, 'euler_covariance': count - 2}
    source, converted = tmp_path / 'in.mcap', tmp_path / 'converted.mcap'
    _write_bag(source, {'/imu': messages})

    with TestNode('px4_live') as client:
        received = {name: client.collect(OUTPUT_TYPES[name].message_class, f'/imu/{name}',
                                         QoSProfile(depth=count)) for name in outputs}
        publisher = client.node.create_publisher(Imu, '/imu', QoSProfile(depth=count))
        node_args = [script('rotation_node'), '--ros-args', '--params-file', params_file,
                     '-r', '__ns:=/imu', '-r', 'input:=/imu']
        with RosProcess(node_args) as node:
            assert client.spin_until(
                lambda: all(client.node.count_publishers(f'/imu/{name}') >= 1
                            for name in outputs)
                and client.wait_for_subscriber(publisher, timeout=0.1), timeout=60), node.output
            client.spin_for(0.5)   # discovery of our subscriptions by the node's publishers
            for msg in messages:
                publisher.publish(msg)
            assert client.spin_until(
                lambda: all(len(received[name]) >= expected_counts[name] for name in outputs),
                timeout=60), ({name: len(r) for name, r in received.items()}, node.output)
            client.spin_for(0.3)
            assert node.stop() == 0, node.output

    assert cli_main(['convert', str(source), str(converted), '--params', str(params_file)]) == 0
    for name in outputs:
        live = [(stamp_ns(m), plain(m)) for m in received[name]]
        offline = _outputs(converted, f'/imu/{name}')
        assert len(live) == len(offline) == expected_counts[name], name
        assert live == offline, name


def test_convert_with_a_mounting_turns_the_estimate_into_the_scenes_reference(tmp_path):
    """
    Convert a scene's IMU stream into its reference: at dt = 0 that is W R M.

    ``convert`` with ``mounting.*`` set to the scene's M and W writes it (the
    reference and scipy are the oracles).
    """
    from rotation_node.bag.cli import main
    from rotation_node.scene.simulator import write_scene_bag
    from rotation_node.scene.spec import scene_from_dict
    m = Rotation.from_euler('xyz', [30.0, -45.0, 120.0], degrees=True)
    w = Rotation.from_euler('xyz', [1.0, 2.0, -75.0], degrees=True)
    scene = scene_from_dict({
        'duration': 1.0, 'rate': 50.0,
        'motion': {'type': 'constant_rate', 'orientation': [0.0, 0.0, 0.0, 1.0],
                   'angular_velocity': [0.4, -0.9, 1.3]},
        'reference': {'rate': 50.0, 'message': 'imu', 'mounting': m.as_quat().tolist(),
                      'world_alignment': w.as_quat().tolist()}})
    source, output = tmp_path / 'scene.mcap', tmp_path / 'mounted.mcap'
    write_scene_bag(scene, source)
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({'rotation_node': {'ros__parameters': {
        'input_type': 'imu', 'outputs': ['quaternion', 'angular_velocity'],
        'mounting': {'body_rotation': [30.0, -45.0, 120.0],
                     'world_rotation': w.as_quat().tolist()}}}}))
    assert main(['convert', str(source), str(output), '--params', str(params),
                 '--topic', '/imu']) == 0
    with BagReader(output) as reader:
        got = [record.message() for record in reader.messages(['/imu/quaternion'])]
        rates = [record.message() for record in reader.messages(['/imu/angular_velocity'])]
        truth = [record.message() for record in reader.messages(['/truth/orientation'])]
        reference = [record.message() for record in reader.messages(['/reference/pose'])]
    assert len(got) == len(truth) == len(reference) == 51
    as_array = [[q.x, q.y, q.z, q.w] for q in (msg.quaternion for msg in got)]
    mounted = Rotation.from_quat(as_array)
    expected = w * Rotation.from_quat([[q.x, q.y, q.z, q.w] for q in
                                       (msg.quaternion for msg in truth)]) * m
    assert (expected.inv() * mounted).magnitude().max() < 1e-14
    ref = Rotation.from_quat([[q.x, q.y, q.z, q.w] for q in
                              (msg.orientation for msg in reference)])
    assert (ref.inv() * mounted).magnitude().max() < 1e-14
    for out, ref_msg in zip(rates, reference):
        assert out.header.stamp == ref_msg.header.stamp
        v, r = out.vector, ref_msg.angular_velocity
        assert max(abs(v.x - r.x), abs(v.y - r.y), abs(v.z - r.z)) < 1e-14
