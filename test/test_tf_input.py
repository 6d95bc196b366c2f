"""
Tests of rotation_node.tf_input: ``input_type: tf`` in the pipeline, the live node and convert.

The oracle is independent of the package: scipy's ``Rotation`` and ``Slerp``
interpolate each edge of the chain at the time tf2 would look it up (the
minimum of the dynamic edges' newest stamps, computed here from the messages
sent), and compose the chain. The process tests publish ``/tf`` and
``/tf_static`` from this process (a three-edge chain: one static edge, two
dynamic ones at different rates) into a running ``rotation_node``, convert the
same messages from a bag with ``rotation_bag convert``, and check both against
the oracle and against each other; a missing frame, unconnected trees and a
cycle are counted on /diagnostics while the node keeps running.
"""

from bag_helpers import write_rosbag2
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped, TransformStamped, Vector3Stamped
import numpy as np
import pytest
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import serialize_message
from ros_harness import RosProcess, script, TestNode
from rotation_node.bag.cli import main as cli_main
from rotation_node.bag.convert import convert, output_topic
from rotation_node.bag.plot import plot_series, plot_topic
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.errors import BagError, ParameterError
from rotation_node.parameters import NodeParameters
from rotation_node.pipeline import ConversionPipeline
from rotation_node.wire.stamps import header_stamp_ns, split_ns
from scipy.spatial.transform import Rotation, Slerp
from tf2_msgs.msg import TFMessage
import yaml

S = 1_000_000_000
T0 = 1_700_000_000 * S + 250_000_000
ANGLE_BOUND = 1e-14   # rad, composed and interpolated chain against scipy
START_TIMEOUT_S = 60.0
IDENTITY = (0.0, 0.0, 0.0, 1.0)
CHAIN = NodeParameters(input_type='tf', tf_parent_frame='map', tf_child_frame='imu_link',
                       outputs=('quaternion', 'angular_velocity'), qos_depth=1000)


def transform(parent, child, stamp_ns, rotation):
    """Return a TransformStamped of the edge ``parent -> child`` (scipy or x, y, z, w)."""
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(stamp_ns)
    q = rotation.as_quat() if isinstance(rotation, Rotation) else rotation
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = (float(v) for v in q)
    msg.transform.translation.x = 1.5   # translations are not used
    return msg


def tf_message(*transforms):
    return TFMessage(transforms=list(transforms))


class Chain:
    """map -> odom at 10 Hz, odom -> base_link at 30 Hz, base_link -> imu_link static."""

    def __init__(self, rng, seconds=2.0):
        self.static = Rotation.random(random_state=rng)
        slow_count, fast_count = int(10 * seconds), int(30 * seconds)
        self.slow = (T0 + np.arange(slow_count) * (S // 10),
                     _random_walk(rng, slow_count))
        self.fast = (T0 + 3_000_001 + np.arange(fast_count) * (S // 30),
                     _random_walk(rng, fast_count))
        rows = ([(int(t), 'map', 'odom', q) for t, q in zip(*self.slow)]
                + [(int(t), 'odom', 'base_link', q) for t, q in zip(*self.fast)])
        rows.sort(key=lambda row: row[0])
        self.static_message = tf_message(transform('base_link', 'imu_link', 0, self.static))
        self.dynamic_messages = [tf_message(transform(parent, child, t, q))
                                 for t, parent, child, q in rows]
        self.rows = rows

    def lookup_times(self):
        """Return the distinct, increasing common times after each /tf message (Time(0))."""
        newest, earliest, times = {}, {}, []
        for t, parent, child, _ in self.rows:
            newest[child] = t
            earliest.setdefault(child, t)
            if len(newest) == 2:
                common = min(newest.values())
                if common >= max(earliest.values()) and (not times or common > times[-1]):
                    times.append(common)
        return times

    def orientation(self, t):
        """Return the oracle: imu_link in map at time ``t`` (scipy slerp of each edge)."""
        def edge(stamps, quaternions):
            seconds = (stamps - T0) * 1e-9
            return Slerp(seconds, Rotation.from_quat(quaternions))((t - T0) * 1e-9)
        return edge(*self.slow) * edge(*self.fast) * self.static


def _random_walk(rng, n):
    steps = Rotation.from_rotvec(rng.normal(scale=0.1, size=(n, 3)))
    current, out = Rotation.random(random_state=rng), []
    for k in range(n):
        current = current * steps[k]
        out.append(current.as_quat())
    return np.array(out)


def _quaternion(msg):
    q = msg.quaternion
    return np.array([q.x, q.y, q.z, q.w])


def _vector(msg):
    v = msg.vector
    return np.array([v.x, v.y, v.z])


def check_against_oracle(chain, quaternions, rates):
    """Check that the outputs (stamped messages) hold the oracle's orientations and rates."""
    times = chain.lookup_times()
    assert [header_stamp_ns(m.header) for m in quaternions] == times
    assert all(m.header.frame_id == 'map' for m in quaternions)
    expected = [chain.orientation(t) for t in times]
    for msg, rotation in zip(quaternions, expected):
        assert (Rotation.from_quat(_quaternion(msg)) * rotation.inv()).magnitude() < ANGLE_BOUND
        assert _quaternion(msg)[3] >= 0.0
    # Angular velocity: the constant body rate between consecutive outputs.
    assert [header_stamp_ns(m.header) for m in rates] == times[1:]
    for k, msg in enumerate(rates):
        step = (expected[k].inv() * expected[k + 1]).as_rotvec()
        np.testing.assert_allclose(_vector(msg), step / ((times[k + 1] - times[k]) * 1e-9),
                                   rtol=0, atol=1e-12)


# The pipeline ----------------------------------------------------------------------

def run_pipeline(params, topic_messages):
    issues = []
    pipeline = ConversionPipeline(params, on_issue=lambda *issue: issues.append(issue))
    outputs = {name: [] for name in params.outputs}
    for topic, msg in topic_messages:
        for name, out in pipeline.process(msg, topic):
            outputs[name].append(out)
    return pipeline, outputs, issues


def test_three_edge_chain_in_the_pipeline_matches_scipy(rng):
    chain = Chain(rng)
    pipeline, outputs, issues = run_pipeline(
        CHAIN, [('/tf_static', chain.static_message)]
        + [('/tf', msg) for msg in chain.dynamic_messages])
    check_against_oracle(chain, outputs['quaternion'], outputs['angular_velocity'])
    # An output at each new stamp of the lagging edge (the slow one, or the fast one
    # just after a slow sample): more than the slow edge's 20. Before, the lookup
    # fails: map unknown (the static message), two trees (map -> odom only), then the
    # fast edge has no sample at the slow edge's 0 s until the slow one's 0.1 s.
    assert len(outputs['quaternion']) > 20
    assert pipeline.stats.dropped == {
        'tf_unknown_frame': 1, 'tf_not_connected': 1, 'tf_extrapolation': 3}
    assert pipeline.stats.received == 1 + len(chain.dynamic_messages)


def test_static_messages_after_dynamic_ones_complete_the_chain(rng):
    chain = Chain(rng, seconds=0.5)
    messages = [('/tf', msg) for msg in chain.dynamic_messages]
    messages.insert(7, ('/tf_static', chain.static_message))
    pipeline, outputs, _ = run_pipeline(CHAIN, messages)
    assert pipeline.stats.dropped['tf_unknown_frame'] >= 7   # imu_link unknown until then
    times = chain.lookup_times()
    stamps = [header_stamp_ns(m.header) for m in outputs['quaternion']]
    assert stamps == [t for t in times if t >= stamps[0]] and len(stamps) >= 3
    for msg in outputs['quaternion']:
        expected = chain.orientation(header_stamp_ns(msg.header))
        assert (Rotation.from_quat(_quaternion(msg)) * expected.inv()).magnitude() < ANGLE_BOUND


def test_a_static_chain_is_published_at_time_zero_when_it_changes():
    params = NodeParameters(input_type='tf', tf_parent_frame='base_link',
                            tf_child_frame='camera', outputs=('quaternion',))
    a, b = Rotation.from_euler('z', 30, degrees=True), Rotation.from_euler('x', 20, degrees=True)
    first = tf_message(transform('base_link', 'mount', 0, a), transform('mount', 'camera', 0, b))
    changed = tf_message(transform('mount', 'camera', 0, b.inv()))
    _, outputs, _ = run_pipeline(params, [('/tf_static', first), ('/tf_static', first),
                                          ('/tf_static', changed), ('/tf_static', changed)])
    assert [header_stamp_ns(m.header) for m in outputs['quaternion']] == [0, 0]
    for msg, expected in zip(outputs['quaternion'], (a * b, a * b.inv())):
        assert (Rotation.from_quat(_quaternion(msg)) * expected.inv()).magnitude() < 1e-15


def test_failures_are_counted_by_reason_and_name_the_frames():
    params = NodeParameters(input_type='tf', tf_parent_frame='map', tf_child_frame='base_link',
                            outputs=('euler',))
    sequence = [
        tf_message(transform('map', 'odom', T0, IDENTITY)),                 # base_link unknown
        tf_message(transform('odom', 'base_link', T0 + 2 * S, IDENTITY)),   # no data at T0
        tf_message(transform('world', 'base_link', T0 + 3 * S, IDENTITY)),  # two trees
        tf_message(transform('base_link', 'odom', T0 + 4 * S, IDENTITY),    # a loop
                   transform('odom', 'base_link', T0 + 4 * S, IDENTITY)),
        tf_message(transform('map', 'odom', T0 + 5 * S, IDENTITY),          # mended
                   transform('odom', 'base_link', T0 + 5 * S, IDENTITY)),
        tf_message(transform('map', 'map', T0 + 6 * S, IDENTITY),           # ignored by tf2
                   transform('map', 'odom', T0 + 6 * S, (0.0, 0.0, 0.0, 2.0))),
    ]
    pipeline, outputs, issues = run_pipeline(params, [('/tf', msg) for msg in sequence])
    assert pipeline.stats.dropped == {
        'tf_unknown_frame': 1, 'tf_not_connected': 1, 'tf_cycle': 1, 'tf_extrapolation': 1,
        'tf_sample_ignored': 2}
    details = dict(issues)
    assert "frame 'base_link' (child) does not exist" in details['tf_unknown_frame']
    assert "'map' and 'base_link' are not connected" in details['tf_not_connected']
    assert 'loop: base_link -> odom -> base_link' in details['tf_cycle']
    assert 'odom -> base_link' in details['tf_extrapolation']
    assert 'not a unit quaternion' in details['tf_sample_ignored']
    # The fifth message mends the tree at 5 s: one output, the identity.
    out, = outputs['euler']
    assert header_stamp_ns(out.header) == T0 + 5 * S and out.header.frame_id == 'map'
    np.testing.assert_array_equal(_vector(out), [0.0, 0.0, 0.0])


def test_parameters_are_required_for_tf():
    with pytest.raises(ParameterError, match="'tf.child_frame': required"):
        NodeParameters(input_type='tf', tf_parent_frame='map')


# The live node and convert ---------------------------------------------------------

def _diagnostics_values(diagnostics, name_prefix):
    """Return the latest /diagnostics values of the node, as a dict."""
    for array in reversed(diagnostics):
        for status in array.status:
            if status.name.startswith(name_prefix):
                return {kv.key: kv.value for kv in status.values}
    return {}


def _tf_publishers(client):
    """Return publishers of /tf_static (latched, as tf2_ros's static broadcaster) and /tf."""
    static = client.node.create_publisher(TFMessage, '/tf_static', QoSProfile(
        depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    return static, client.node.create_publisher(TFMessage, '/tf', 1000)


def _start_node(client, namespace, parameters):
    args = [script('rotation_node'), '--ros-args', '-r', f'__ns:={namespace}']
    for name, value in parameters.items():
        args += ['-p', f'{name}:={value}']
    node = RosProcess(args)
    assert client.spin_until(lambda: client.node.count_subscribers('/tf') >= 1
                             and client.node.count_subscribers('/tf_static') >= 1,
                             timeout=START_TIMEOUT_S), node.output
    return node


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_live_node_and_convert_match_scipy_and_each_other(tmp_path, rng):
    chain = Chain(rng)
    namespace = '/tf_chain'
    with TestNode('tf_chain_publisher') as client:
        quaternions = client.collect(QuaternionStamped, f'{namespace}/quaternion', 1000)
        rates = client.collect(Vector3Stamped, f'{namespace}/angular_velocity', 1000)
        diagnostics = client.collect(DiagnosticArray, '/diagnostics', 100)
        static_publisher, publisher = _tf_publishers(client)
        static_publisher.publish(chain.static_message)   # before the node: it is latched
        node = _start_node(client, namespace, {
            'input_type': 'tf', 'tf.parent_frame': 'map', 'tf.child_frame': 'imu_link',
            'outputs': '[quaternion, angular_velocity]', 'qos.depth': 1000})
        with node:
            assert client.spin_until(
                lambda: client.node.count_publishers(f'{namespace}/quaternion') >= 1
                and client.node.count_publishers(f'{namespace}/angular_velocity') >= 1,
                timeout=START_TIMEOUT_S), node.output
            # The node has the static transform (received once) before any /tf message.
            assert client.spin_until(lambda: _diagnostics_values(
                diagnostics, f'{namespace}/rotation_node').get('received') == '1',
                timeout=30), node.output
            client.spin_for(0.3)   # the subscription matched the /tf publisher too
            for msg in chain.dynamic_messages:
                publisher.publish(msg)
                client.spin_for(0.002)
            assert publisher.wait_for_all_acked(Duration(seconds=20))
            expected = len(chain.lookup_times())
            assert client.spin_until(lambda: len(quaternions) >= expected
                                     and len(rates) >= expected - 1, timeout=30), (
                len(quaternions), node.output)
            client.spin_for(0.2)
            assert node.alive()
            assert node.stop() == 0, node.output
    check_against_oracle(chain, quaternions, rates)

    # The same messages from a bag: rotation_bag convert gives the same outputs.
    bag, converted = tmp_path / 'tf.mcap', tmp_path / 'converted.mcap'
    with BagWriter(bag) as writer:
        writer.write('/tf_static', chain.static_message, T0 - S)
        for k, msg in enumerate(chain.dynamic_messages):
            writer.write('/tf', msg, T0 + k * 1_000_000)
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'rotation_node': {'ros__parameters': {
        'input_type': 'tf', 'tf': {'parent_frame': 'map', 'child_frame': 'imu_link'},
        'outputs': ['quaternion', 'angular_velocity']}}}))
    assert cli_main(['convert', str(bag), str(converted), '--params', str(params_file)]) == 0
    with BagReader(converted) as reader:
        assert reader.topics[output_topic('/tf', 'quaternion')] == \
            'geometry_msgs/msg/QuaternionStamped'
        offline = {name: [record.message() for record in
                          reader.messages([output_topic('/tf', name)])]
                   for name in ('quaternion', 'angular_velocity')}
    assert offline['quaternion'] == quaternions
    assert offline['angular_velocity'] == rates


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_missing_frame_and_cycle_keep_the_node_alive_and_show_on_diagnostics():
    namespace = '/tf_faults'
    with TestNode('tf_fault_publisher') as client:
        eulers = client.collect(Vector3Stamped, f'{namespace}/euler', 100)
        diagnostics = client.collect(DiagnosticArray, '/diagnostics', 100)
        _, publisher = _tf_publishers(client)
        node = _start_node(client, namespace, {
            'input_type': 'tf', 'tf.parent_frame': 'map', 'tf.child_frame': 'base_link'})
        with node:
            client.spin_for(0.3)

            def counted(reason):
                def check():
                    values = _diagnostics_values(diagnostics, f'{namespace}/rotation_node')
                    return int(values.get(f'dropped.{reason}', 0)) >= 1
                return check
            publisher.publish(tf_message(transform('map', 'odom', T0, IDENTITY)))
            assert client.spin_until(counted('tf_unknown_frame'), timeout=20), node.output
            publisher.publish(tf_message(transform('base_link', 'odom', T0 + S, IDENTITY),
                                         transform('odom', 'base_link', T0 + S, IDENTITY)))
            assert client.spin_until(counted('tf_cycle'), timeout=20), node.output
            assert node.alive()
            # Mended: the node converts again.
            publisher.publish(tf_message(transform('map', 'odom', T0 + 2 * S, IDENTITY),
                                         transform('odom', 'base_link', T0 + 2 * S, IDENTITY)))
            assert client.spin_until(lambda: len(eulers) >= 1, timeout=20), node.output
            assert header_stamp_ns(eulers[0].header) == T0 + 2 * S
            values = _diagnostics_values(diagnostics, f'{namespace}/rotation_node')
            assert values['input_topic'] == '/tf, /tf_static'
            # Each topic with its own QoS, as its publishers offer it (qos.reliability auto).
            assert values['input_qos'] == (
                '/tf: reliable, volatile; /tf_static: reliable, transient_local'), values
            assert node.stop() == 0, node.output
    assert "frame 'base_link' (child) does not exist" in node.output
    assert '[tf_unknown_frame]' in node.output
    assert 'loop: base_link -> odom -> base_link' in node.output


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_a_parameter_change_keeps_the_static_transforms():
    namespace = '/tf_reconfigured'
    with TestNode('tf_reconfigure_client') as client:
        eulers = client.collect(Vector3Stamped, f'{namespace}/euler', 100)
        static_publisher, publisher = _tf_publishers(client)
        static_publisher.publish(tf_message(transform(
            'base_link', 'imu_link', 0, Rotation.from_euler('x', 90, degrees=True))))
        node = _start_node(client, namespace, {
            'input_type': 'tf', 'tf.parent_frame': 'map', 'tf.child_frame': 'imu_link'})
        with node:
            parameters = AsyncParameterClient(client.node, f'{namespace}/rotation_node')
            assert parameters.wait_for_services(timeout_sec=START_TIMEOUT_S), node.output

            def euler_after(stamp_ns):
                """Publish map -> base_link at increasing stamps until an output arrives."""
                count = len(eulers)
                for k in range(100):
                    publisher.publish(tf_message(
                        transform('map', 'base_link', stamp_ns + k * S, IDENTITY)))
                    if client.spin_until(lambda: len(eulers) > count, timeout=0.2):
                        return _vector(eulers[-1])
                pytest.fail(f'no output:\n{node.output}')

            np.testing.assert_allclose(euler_after(T0), [np.pi / 2, 0.0, 0.0], atol=1e-15)
            # A new pipeline for the new parameters: the static transform must reach it too.
            future = parameters.set_parameters([Parameter('euler.degrees', value=True)])
            assert client.spin_until(future.done, timeout=10.0)
            assert future.result().results[0].successful
            np.testing.assert_allclose(euler_after(T0 + 1000 * S), [90.0, 0.0, 0.0],
                                       atol=1e-12)
            assert node.stop() == 0, node.output


def test_convert_pairs_each_tf_topic_with_its_static_topic(tmp_path, rng):
    chain = Chain(rng, seconds=0.5)
    other = Chain(rng, seconds=0.5)
    bag = tmp_path / 'robots.mcap'
    with BagWriter(bag) as writer:
        for prefix, robot in (('/robot1', chain), ('', other)):
            writer.write(f'{prefix}/tf_static', robot.static_message, T0 - S)
            for k, msg in enumerate(robot.dynamic_messages):
                writer.write(f'{prefix}/tf', msg, T0 + k * 1_000_000)
    stats = convert(bag, tmp_path / 'both.mcap', CHAIN)
    assert sorted(stats) == ['/robot1/tf', '/tf']   # the static topics go with their pair
    for topic, robot in (('/robot1/tf', chain), ('/tf', other)):
        with BagReader(tmp_path / 'both.mcap') as reader:
            quaternions = [r.message() for r in reader.messages([f'{topic}/quaternion'])]
            rates = [r.message() for r in reader.messages([f'{topic}/angular_velocity'])]
        check_against_oracle(robot, quaternions, rates)
    stats = convert(bag, tmp_path / 'one.mcap', CHAIN, topics=['/robot1/tf'])
    assert list(stats) == ['/robot1/tf']
    assert stats['/robot1/tf'].received == 1 + len(chain.dynamic_messages)
    with BagReader(tmp_path / 'one.mcap') as reader:
        assert '/tf/quaternion' not in reader.topics


def test_plot_draws_the_converted_orientation_and_refuses_the_tf_topic(tmp_path, rng):
    chain = Chain(rng, seconds=0.5)
    bag, converted = tmp_path / 'tf.mcap', tmp_path / 'converted.mcap'
    with BagWriter(bag) as writer:
        writer.write('/tf_static', chain.static_message, T0 - S)
        for k, msg in enumerate(chain.dynamic_messages):
            writer.write('/tf', msg, T0 + k * 1_000_000)
    params = CHAIN.replaced({'outputs': ['euler']})
    convert(bag, converted, params)
    with open_bag(converted) as reader:
        times_ns, _, (angles,) = plot_series(reader, '/tf/euler', params)
    assert list(times_ns) == chain.lookup_times()
    expected = [chain.orientation(t).as_euler('xyz') for t in chain.lookup_times()]
    np.testing.assert_allclose(angles, expected, rtol=0, atol=1e-12)
    with pytest.raises(BagError, match='convert it with input_type tf first'):
        plot_topic(converted, '/tf', tmp_path / 'tf.png', params=params)


@pytest.mark.slow
@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_a_rosbag2_directory_written_by_rosbags_converts(tmp_path, rng, storage):
    chain = Chain(rng, seconds=1.0)
    type_name = 'tf2_msgs/msg/TFMessage'
    rows = [('/tf_static', type_name, serialize_message(chain.static_message), T0 - S)]
    rows += [('/tf', type_name, serialize_message(msg), T0 + k * 1_000_000)
             for k, msg in enumerate(chain.dynamic_messages)]
    bag = write_rosbag2(tmp_path / 'bag', rows, storage=storage)
    convert(bag, tmp_path / 'out.mcap', CHAIN)
    with BagReader(tmp_path / 'out.mcap') as reader:
        check_against_oracle(
            chain, [r.message() for r in reader.messages(['/tf/quaternion'])],
            [r.message() for r in reader.messages(['/tf/angular_velocity'])])


def test_drop_reasons_are_the_lookup_errors_reasons_and_ignored_samples():
    from rotation_node import tf_buffer, tf_input
    lookup_errors = tf_buffer.TfLookupError.__subclasses__()
    assert len(lookup_errors) == 4
    assert tf_input.DROP_REASONS == (*('tf_' + error.reason for error in lookup_errors),
                                     tf_input.TF_SAMPLE_IGNORED)
