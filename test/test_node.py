"""
Process tests of the ``rotation_node`` console script: real processes talking over DDS.

One node process (module fixture) serves most tests: each test first sets every
parameter (defaults plus its own changes) through the node's parameter service,
so tests do not depend on each other's settings. Values are compared with scipy
(``ros_harness.oracle_output``); test_pipeline.py covers the conversions in depth.
"""
from pathlib import Path
import signal
import subprocess
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.duration import Duration
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_harness import (
    make_input_message, oracle_output, output_values, PLAIN_INPUT_TYPES, RosProcess, script,
    TestNode)
from rotation_node.errors import ParameterError
from rotation_node.parameters import (
    NodeParameters, OUTPUTS, PARAMETERS, parameters_file_sections, parameters_from_yaml)
from rotation_node.pipeline import input_message_type
from rotation_node.registry import OUTPUTS as OUTPUT_TYPES
from scipy.spatial.transform import Rotation

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'params.yaml'
STAMP_NS = 1_700_000_000_000_000_000
OMEGA_BODY = np.array([0.4, -0.9, 1.7])
START_TIMEOUT_S = 60.0
# Bound of the waits for outputs and /diagnostics (published once a second): far above what
# a loaded machine takes, so that it only ends a test where something is broken.
WAIT_TIMEOUT_S = 30.0


@pytest.fixture(scope='module')
def ros():
    with TestNode('rotation_node_test') as test_node:
        test_node.diagnostics = test_node.collect(DiagnosticArray, '/diagnostics')
        test_node.log = test_node.collect(Log, '/rosout', qos=1000)
        yield test_node


DISCOVERY_SETTLE_S = 0.25


class NodeUnderTest:
    """A running ``rotation_node`` process and the test's handles on it."""

    def __init__(self, ros, args, namespace='/'):
        self.ros = ros
        self.namespace = namespace
        self.fq_name = namespace.rstrip('/') + '/rotation_node'
        self.process = RosProcess([script('rotation_node'), '--ros-args', *args])
        self.parameters = AsyncParameterClient(ros.node, self.fq_name)
        self.received = {name: [] for name in OUTPUTS}
        self.subscriptions = {
            name: ros.node.create_subscription(
                OUTPUT_TYPES[name].message_class, self.topic(name),
                self.received[name].append, 100)
            for name in OUTPUTS}
        if not self.parameters.wait_for_services(timeout_sec=START_TIMEOUT_S):
            self.stop()
            pytest.fail(f'rotation_node did not start:\n{self.process.output}')

    def call(self, future):
        # The parameter services answer once the node spins: after it has loaded its kernels,
        # which takes a while on a loaded machine (the node's start-up bound).
        assert self.ros.spin_until(future.done, timeout=START_TIMEOUT_S), \
            'parameter service timed out'
        return future.result()

    def set(self, values):  # noqa: A003
        """Set parameters one by one; return the SetParametersResult of each."""
        return self.call(self.parameters.set_parameters(
            [Parameter(name, value=value) for name, value in values.items()])).results

    def get(self, name):
        value, = self.call(self.parameters.get_parameters([name])).values
        return parameter_value_to_python(value)

    def configure(self, values):
        """Set every parameter: the defaults, changed by ``values`` (ROS names)."""
        ros_values = NodeParameters.from_ros(values).to_ros()
        result = self.call(self.parameters.set_parameters_atomically(
            [Parameter(name, value=value) for name, value in ros_values.items()])).result
        assert result.successful, result.reason

    def topic(self, name):
        return f'{self.namespace.rstrip("/")}/{name}'

    def exchange(self, input_type, messages, expected_counts, *, topic='input', qos=None,
                 timeout=WAIT_TIMEOUT_S):
        """
        Publish ``messages`` on the node's input; return ``{output: [messages]}``.

        Waits until every output named in ``expected_counts`` has received that many
        messages (and fails if not). Send a valid message last when checking that an
        earlier one produced nothing: outputs of one topic arrive in order.

        The outputs are read by subscriptions that live as long as this object, so
        the node's publishers, however new, match them as soon as they exist. With
        ``qos`` (a QoSProfile) the publisher and fresh subscriptions use it instead; a best
        effort publisher sends ``messages`` again each second until the outputs are there
        (what it sends before the node's reader has matched it is lost unseen) and the
        first ``expected_counts`` outputs are returned.
        """
        best_effort = qos is not None and qos.reliability == ReliabilityPolicy.BEST_EFFORT
        node = self.ros.node
        if qos is None:
            for name in expected_counts:
                self.received[name].clear()
            received, subscriptions = self.received, [
                self.subscriptions[name] for name in expected_counts]
        else:
            received = {name: [] for name in expected_counts}
            subscriptions = [
                node.create_subscription(OUTPUT_TYPES[name].message_class, self.topic(name),
                                         received[name].append, qos)
                for name in expected_counts]
        publisher = node.create_publisher(
            input_message_type(input_type), self.topic(topic) if topic == 'input' else topic,
            qos or 100)
        try:
            assert self.ros.spin_until(lambda: publisher.get_subscription_count() > 0 and all(
                s.get_publisher_count() > 0 for s in subscriptions), timeout), 'no match'
            # The publisher sees the node's subscription before that subscription has
            # matched the new publisher, and a volatile reader drops what came before.
            self.ros.spin_for(0.5 if qos is not None else DISCOVERY_SETTLE_S)
            deadline = time.monotonic() + timeout
            while True:
                for msg in messages:
                    publisher.publish(msg)
                done = self.ros.spin_until(lambda: all(
                    len(received[name]) >= count for name, count in expected_counts.items()),
                    min(1.0, deadline - time.monotonic()) if best_effort else timeout)
                if done or not best_effort or time.monotonic() >= deadline:
                    break
            self.ros.spin_for(0.1)
            assert done, {name: len(received[name]) for name in expected_counts}
        finally:
            node.destroy_publisher(publisher)
            if qos is not None:
                for subscription in subscriptions:
                    node.destroy_subscription(subscription)
        if best_effort:
            return {name: received[name][:count] for name, count in expected_counts.items()}
        return {name: list(received[name]) for name in expected_counts}

    def next_diagnostics(self, condition=lambda values: True, timeout=WAIT_TIMEOUT_S):
        """Return the values of the next /diagnostics status of this node meeting ``condition``."""
        seen = len(self.ros.diagnostics)
        found = []

        def arrived():
            for array in self.ros.diagnostics[seen:]:
                for status in array.status:
                    values = {kv.key: kv.value for kv in status.values}
                    if status.name.startswith(self.fq_name + ':') and condition(values):
                        found.append((status, values))
            return bool(found)
        assert self.ros.spin_until(arrived, timeout), 'no matching /diagnostics'
        status, values = found[0]
        values['level'], values['name'] = status.level, status.name
        return values

    def stop(self):
        """Ctrl-C the node; return its exit code."""
        for subscription in self.subscriptions.values():
            self.ros.node.destroy_subscription(subscription)
        self.subscriptions.clear()
        return self.process.stop()


@pytest.fixture(scope='module')
def node(ros):
    under_test = NodeUnderTest(ros, [])
    yield under_test
    under_test.stop()


@pytest.fixture
def rotation(rng):
    return Rotation.random(random_state=rng)


def assert_output(out, name, rotation, omega=OMEGA_BODY, **convention):
    expected = oracle_output(name, rotation, omega, **convention)
    np.testing.assert_allclose(output_values(out), expected, rtol=1e-7, atol=1e-9)


# Inputs, outputs, headers ----------------------------------------------------------

@pytest.mark.parametrize('input_type', PLAIN_INPUT_TYPES)
def test_each_input_type(node, input_type, rotation):
    node.configure({'input_type': input_type, 'outputs': ['quaternion', 'euler']})
    msg = make_input_message(input_type, rotation, stamp_ns=STAMP_NS + 123, frame_id='base')
    got = node.exchange(input_type, [msg], {'quaternion': 1, 'euler': 1})
    for name in ('quaternion', 'euler'):
        out, = got[name]
        assert_output(out, name, rotation)
        assert out.header == msg.header   # stamp and frame_id preserved


@pytest.mark.parametrize('name', OUTPUTS)
def test_each_output(node, name, rotation):
    node.configure({'input_type': 'imu', 'outputs': [name],
                    'angular_velocity.output_frame': 'world'})
    msg = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS,
                             frame_id='imu_link')
    out, = node.exchange('imu', [msg], {name: 1})[name]
    assert_output(out, name, rotation, frame='world')
    if name not in ('axis_angle', 'matrix'):   # Float64MultiArray has no header
        assert out.header == msg.header


def test_finite_difference_angular_velocity(node, rotation):
    node.configure({'input_type': 'pose', 'outputs': ['angular_velocity']})
    dt_ns = 2_000_000
    later = rotation * Rotation.from_rotvec(OMEGA_BODY * dt_ns * 1e-9)
    messages = [make_input_message('pose', r, stamp_ns=STAMP_NS + k * dt_ns)
                for k, r in enumerate((rotation, later))]
    out, = node.exchange('pose', messages, {'angular_velocity': 1})['angular_velocity']
    np.testing.assert_allclose(output_values(out), OMEGA_BODY, rtol=1e-9)
    assert out.header == messages[1].header


def test_mounting_and_yaw_offset_apply_to_orientation_and_angular_velocity(node, rotation):
    node.configure({'input_type': 'imu', 'outputs': ['quaternion', 'angular_velocity'],
                    'mounting.body_rotation': [10.0, -20.0, 30.0],
                    'mounting.yaw_offset': 0.5})
    msg = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS)
    got = node.exchange('imu', [msg], {'quaternion': 1, 'angular_velocity': 1})
    m = Rotation.from_euler('xyz', [10.0, -20.0, 30.0], degrees=True)
    mounted = Rotation.from_euler('z', 0.5) * rotation * m
    assert_output(got['quaternion'][0], 'quaternion', mounted)
    assert_output(got['angular_velocity'][0], 'angular_velocity', mounted,
                  m.inv().apply(OMEGA_BODY))
    assert node.get('mounting.body_rotation') == [10.0, -20.0, 30.0]


def test_mounting_from_tf_static_once_the_frames_connect(node, rotation):
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    result, = node.set({'mounting.tf_sensor_frame': 'imu_link'})   # one frame alone
    assert not result.successful and 'mounting.tf_body_frame' in result.reason
    node.configure({'input_type': 'imu', 'outputs': ['quaternion'],
                    'mounting.tf_sensor_frame': 'imu_link',
                    'mounting.tf_body_frame': 'base_link'})
    msg = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS)
    node.exchange('imu', [msg], {})   # before /tf_static: dropped, counted
    node.next_diagnostics(lambda v: int(v['dropped.mounting_unknown']) >= 1)
    mount = Rotation.from_euler('xyz', [0.0, 180.0, 90.0], degrees=True)   # imu_link in base
    edge = TransformStamped()
    edge.header.frame_id, edge.child_frame_id = 'base_link', 'imu_link'
    q = edge.transform.rotation
    q.x, q.y, q.z, q.w = (float(c) for c in mount.as_quat())
    publisher = node.ros.node.create_publisher(TFMessage, '/tf_static', QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    try:
        publisher.publish(TFMessage(transforms=[edge]))
        # the node has it (acknowledged), and its tf listener a moment to take it
        assert node.ros.wait_for_subscriber(publisher, WAIT_TIMEOUT_S)
        assert publisher.wait_for_all_acked(Duration(seconds=WAIT_TIMEOUT_S))
        node.ros.spin_for(0.5)
        out, = node.exchange('imu', [msg], {'quaternion': 1})['quaternion']
    finally:
        node.ros.node.destroy_publisher(publisher)
    assert_output(out, 'quaternion', rotation * mount.inv())


# Runtime parameter changes ----------------------------------------------------------

def test_a_convention_change_applies_to_the_next_message(node, rotation):
    node.configure({'input_type': 'quaternion', 'outputs': ['euler']})
    msg = make_input_message('quaternion', rotation)
    first, = node.exchange('quaternion', [msg], {'euler': 1})['euler']
    assert_output(first, 'euler', rotation)
    results = node.set({'euler.sequence': 'ZYX', 'euler.degrees': True})
    assert all(result.successful for result in results)
    assert node.get('euler.sequence') == 'ZYX' and node.get('euler.degrees') is True
    second, = node.exchange('quaternion', [msg], {'euler': 1})['euler']
    assert_output(second, 'euler', rotation, sequence='ZYX', degrees=True)


@pytest.mark.parametrize('name, value, reason', [
    ('euler.sequence', 'xxy', "'xxy' is not an Euler sequence"),
    ('euler.sequence', 'XyZ', "'XyZ' is not an Euler sequence"),
    ('outputs', ['euler', 'eulr'], "'eulr' is not allowed"),
    ('outputs', ['euler', 'euler'], 'euler listed twice'),
    ('input_type', 'twist', "'twist' is not allowed"),
    ('angular_velocity.output_frame', 'map', "'map' is not allowed"),
    ('qos.depth', 0, 'qos.depth'),                     # rejected by the descriptor's range
    ('euler.singularity_threshold', 3.0, 'euler.singularity_threshold'),
    ('euler.degrees', 'yes', 'type'),                  # rejected by the declared type
])
def test_an_invalid_change_is_rejected_and_the_old_value_stays(node, name, value, reason):
    node.configure({})
    before = node.get(name)
    result, = node.set({name: value})
    assert not result.successful
    assert reason in result.reason
    assert node.get(name) == before


def test_changing_outputs_creates_and_destroys_publishers(node):
    graph = node.ros.node
    node.configure({'outputs': ['euler', 'matrix']})
    assert node.ros.spin_until(lambda: graph.count_publishers('/matrix') == 1)
    node.configure({'outputs': ['rotation_vector']})
    assert node.ros.spin_until(lambda: graph.count_publishers('/matrix') == 0
                               and graph.count_publishers('/euler') == 0
                               and graph.count_publishers('/rotation_vector') == 1)


def test_changing_reliability_recreates_the_subscription(node, rotation):
    best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    node.configure({'input_type': 'quaternion', 'outputs': ['quaternion'],
                    'qos.reliability': 'reliable'})
    msg = make_input_message('quaternion', rotation)
    with pytest.raises(AssertionError, match='no match'):   # a reliable reader ignores it
        node.exchange('quaternion', [msg], {'quaternion': 1}, qos=best_effort, timeout=2.0)
    node.configure({'input_type': 'quaternion', 'outputs': ['quaternion'],
                    'qos.reliability': 'best_effort'})
    out, = node.exchange('quaternion', [msg], {'quaternion': 1}, qos=best_effort)['quaternion']
    assert_output(out, 'quaternion', rotation)


CONFIG_FILES = sorted(CONFIG.parent.glob('*.yaml'))


def load_request(path):
    """Return a parameters file's values for the node in file order (ros2 param load's request)."""
    values = {}
    for key, section in parameters_file_sections(path):
        assert key.endswith('rotation_node'), key   # the shipped files hold the node's only
        values.update(section)
    return values


def get_all(node):
    names = [spec.name for spec in PARAMETERS]
    values = node.call(node.parameters.get_parameters(names)).values
    return {name: parameter_value_to_python(value) for name, value in zip(names, values)}


def tf_static_euler(node, rotation):
    """Publish map -> base_link on /tf_static; return the node's next euler output."""
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    publisher = node.ros.node.create_publisher(TFMessage, '/tf_static', latched)
    transform = TransformStamped()
    transform.header.frame_id, transform.child_frame_id = 'map', 'base_link'
    q = transform.transform.rotation
    q.x, q.y, q.z, q.w = (float(v) for v in rotation.as_quat())
    node.received['euler'].clear()
    try:
        publisher.publish(TFMessage(transforms=[transform]))
        assert node.ros.spin_until(lambda: node.received['euler'], WAIT_TIMEOUT_S), \
            'no euler from /tf'
    finally:
        node.ros.node.destroy_publisher(publisher)
    return node.received['euler'][-1]


@pytest.mark.parametrize('path', CONFIG_FILES, ids=lambda path: path.name)
def test_a_shipped_parameters_file_loads_in_one_request(node, path, rotation):
    """ros2 param load sends a file's parameters in one set_parameters request: all apply."""
    values = load_request(path)
    expected = parameters_from_yaml(path, '/rotation_node')
    # Start from another input type than the file's: its frames come after input_type.
    node.configure({'input_type': 'tf', 'tf.parent_frame': 'odom', 'tf.child_frame': 'imu',
                    'outputs': ['quaternion'], 'euler.sequence': 'ZYX'}
                   if expected.input_type != 'tf' else {'euler.sequence': 'ZYX'})
    results = node.set(values)
    assert [(r.successful, r.reason) for r in results] == [(True, '')] * len(values)
    assert get_all(node) == expected.to_ros()
    if expected.input_type == 'tf':
        assert_output(tf_static_euler(node, rotation), 'euler', rotation)
    else:
        msg = make_input_message(expected.input_type, rotation)
        out, = node.exchange(expected.input_type, [msg], {'euler': 1})['euler']
        assert_output(out, 'euler', rotation, sequence=expected.euler_sequence)


def test_an_invalid_combination_in_one_request_changes_nothing(node, rotation):
    node.configure({'outputs': ['euler']})
    before = get_all(node)
    values = {'input_type': 'tf', 'euler.sequence': 'ZYX', 'tf.parent_frame': 'map',
              'outputs': ['quaternion']}   # no tf.child_frame
    results = node.set(values)
    assert all(not r.successful and r.reason.startswith('not applied: ') and
               "'tf.child_frame': required with input_type tf" in r.reason for r in results)
    assert get_all(node) == before
    msg = make_input_message('imu', rotation)
    out, = node.exchange('imu', [msg], {'euler': 1})['euler']
    assert_output(out, 'euler', rotation)


def test_one_invalid_value_of_a_request_fails_alone(node):
    node.configure({})
    results = node.set({'euler.sequence': 'xxy', 'euler.degrees': True})
    assert [r.successful for r in results] == [False, True]
    assert node.get('euler.sequence') == 'xyz' and node.get('euler.degrees') is True


# Bad input -------------------------------------------------------------------------

def set_quaternion(msg, values):
    msg.quaternion.x, msg.quaternion.y, msg.quaternion.z, msg.quaternion.w = values


@pytest.mark.parametrize('values, reason', [
    ((np.nan, 0.0, 0.0, 1.0), 'non_finite_orientation'),
    ((0.0, 0.0, np.inf, 1.0), 'non_finite_orientation'),
], ids=['nan', 'inf'])
def test_a_bad_quaternion_is_dropped_and_counted(node, values, reason, rotation):
    node.configure({'input_type': 'quaternion', 'outputs': ['quaternion']})
    before = node.next_diagnostics()
    bad = make_input_message('quaternion', rotation, stamp_ns=STAMP_NS)
    set_quaternion(bad, values)
    good = make_input_message('quaternion', rotation, stamp_ns=STAMP_NS + 1)
    out, = node.exchange('quaternion', [bad, good], {'quaternion': 1})['quaternion']
    assert out.header == good.header
    key = f'dropped.{reason}'
    after = node.next_diagnostics(lambda v: int(v[key]) > int(before[key]))
    assert int(after[key]) == int(before[key]) + 1
    assert after['level'] == DiagnosticStatus.WARN   # the report right after the drop


def test_imu_without_orientation_still_gives_angular_velocity(node, rotation):
    node.configure({'input_type': 'imu', 'outputs': ['euler', 'angular_velocity']})
    before = node.next_diagnostics()
    unknown = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS)
    unknown.orientation_covariance[0] = -1.0
    good = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS + 1)
    got = node.exchange('imu', [unknown, good], {'euler': 1, 'angular_velocity': 2})
    assert [out.header for out in got['euler']] == [good.header]
    assert [out.header for out in got['angular_velocity']] == [unknown.header, good.header]
    assert_output(got['angular_velocity'][0], 'angular_velocity', rotation)
    after = node.next_diagnostics(lambda v: int(v['received']) >= int(before['received']) + 2)
    key = 'skipped.orientation_unknown'
    assert int(after[key]) == int(before[key]) + 1


def test_imu_with_a_zero_quaternion_still_gives_angular_velocity(node, rotation):
    """(0, 0, 0, 0) without the -1 flag: the other form of "orientation not estimated"."""
    node.configure({'input_type': 'imu', 'outputs': ['euler', 'angular_velocity']})
    before = node.next_diagnostics()
    unknown = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS)
    unknown.orientation.w = 0.0
    unknown.orientation.x = unknown.orientation.y = unknown.orientation.z = 0.0
    good = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS + 1)
    got = node.exchange('imu', [unknown, good], {'euler': 1, 'angular_velocity': 2})
    assert [out.header for out in got['euler']] == [good.header]
    assert [out.header for out in got['angular_velocity']] == [unknown.header, good.header]
    assert_output(got['angular_velocity'][0], 'angular_velocity', rotation)
    after = node.next_diagnostics(lambda v: int(v['received']) >= int(before['received']) + 2)
    assert int(after['skipped.zero_quaternion']) == int(before['skipped.zero_quaternion']) + 1
    assert after['dropped'] == before['dropped']


@pytest.mark.parametrize('covariance, reason', [
    ((1e308, 0, 0, 0, 1e308, 0, 0, 0, 1e308), 'covariance_too_large'),   # DBL_MAX: unknown
    ((-1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6), 'invalid_covariance'),       # negative variance
], ids=['dbl_max', 'negative'])
def test_a_covariance_edge_case_skips_only_the_uncertainty(node, rotation, covariance, reason):
    node.configure({'input_type': 'imu',
                    'outputs': ['euler', 'angular_velocity', 'euler_stddev']})
    before = node.next_diagnostics()
    odd = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS,
                             covariance=covariance)
    good = make_input_message('imu', rotation, omega=OMEGA_BODY, stamp_ns=STAMP_NS + 1)
    got = node.exchange('imu', [odd, good], {'euler': 2, 'angular_velocity': 2,
                                             'euler_stddev': 1})
    assert [out.header for out in got['euler']] == [odd.header, good.header]
    assert [out.header for out in got['angular_velocity']] == [odd.header, good.header]
    stddev, = got['euler_stddev']
    assert stddev.header == good.header and np.isfinite(output_values(stddev)).all()
    key = f'skipped.{reason}'
    after = node.next_diagnostics(lambda v: int(v[key]) > int(before[key]))
    assert int(after[key]) == int(before[key]) + 1
    assert after['dropped'] == before['dropped'] and after['level'] == DiagnosticStatus.WARN


def test_a_non_unit_quaternion_is_normalised_with_a_warning(node, rotation):
    node.configure({'input_type': 'quaternion', 'outputs': ['quaternion']})
    before = node.next_diagnostics()
    msg = make_input_message('quaternion', rotation)
    set_quaternion(msg, 1.5 * rotation.as_quat())
    out, = node.exchange('quaternion', [msg], {'quaternion': 1})['quaternion']
    assert_output(out, 'quaternion', rotation)
    assert node.ros.spin_until(lambda: any(
        log.name == 'rotation_node' and 'normalised' in log.msg and log.level == Log.WARN
        for log in node.ros.log))
    after = node.next_diagnostics(lambda v: int(v['received']) > int(before['received']))
    assert int(after['normalised']) == int(before['normalised']) + 1


def test_a_backwards_stamp_skips_only_the_finite_difference(node, rotation):
    node.configure({'input_type': 'quaternion', 'outputs': ['euler', 'angular_velocity']})
    before = node.next_diagnostics()
    offsets_ms = [0, 10, 5, 20]     # the third message goes back in time
    messages = [make_input_message('quaternion', rotation, stamp_ns=STAMP_NS + ms * 10**6)
                for ms in offsets_ms]
    got = node.exchange('quaternion', messages, {'euler': 4, 'angular_velocity': 2})
    assert [out.header for out in got['angular_velocity']] == [
        messages[1].header, messages[3].header]
    after = node.next_diagnostics(lambda v: int(v['received']) >= int(before['received']) + 4)
    key = 'skipped.timestamp_not_increasing'
    assert int(after[key]) == int(before[key]) + 1
    assert node.process.alive()


# Diagnostics -----------------------------------------------------------------------

def test_diagnostics_report_counters_and_conventions(node):
    node.configure({'input_type': 'euler', 'outputs': ['euler'], 'euler.sequence': 'ZYX',
                    'euler.degrees': True})
    before = node.next_diagnostics(lambda v: v['euler.sequence'] == 'ZYX')
    near_lock = make_input_message('euler', Rotation.from_euler('ZYX', [10, 89.9, 20], True),
                                   sequence='ZYX', degrees=True)
    node.exchange('euler', [near_lock], {'euler': 1})
    after = node.next_diagnostics(lambda v: int(v['received']) > int(before['received']))
    assert after['name'] == '/rotation_node: orientation conversion'
    assert int(after['published']) == int(before['published']) + 1
    assert int(after['near_singular']) == int(before['near_singular']) + 1
    assert after['input_topic'] == '/input'
    assert after['euler.degrees'] == 'true' and after['outputs'] == 'euler'
    assert {spec.name for spec in PARAMETERS} <= set(after)
    assert {'skipped.zero_quaternion', 'skipped.timestamp_not_increasing',
            'skipped.covariance_too_large', 'skipped.invalid_covariance',
            'normalised'} <= set(after)


# Start-up: parameters file, invalid values, namespace and remapping -------------------

def test_parameters_files_are_applied(ros, tmp_path, rotation):
    overrides = tmp_path / 'override.yaml'
    overrides.write_text(
        '/**:\n  ros__parameters:\n    input_type: odometry\n'
        '    outputs: [rotation_vector]\n    euler:\n      sequence: zxz\n')
    started = NodeUnderTest(ros, ['-r', '__ns:=/from_file', '--params-file', CONFIG,
                                  '--params-file', overrides], namespace='/from_file')
    try:
        assert started.get('euler.sequence') == 'zxz'
        assert started.get('qos.depth') == 1000    # from config/params.yaml
        msg = make_input_message('odometry', rotation)
        out, = started.exchange('odometry', [msg], {'rotation_vector': 1})['rotation_vector']
        assert_output(out, 'rotation_vector', rotation)
    finally:
        assert started.stop() == 0


@pytest.mark.parametrize('args, message', [
    (['-p', 'euler.sequence:=xxy'], "'xxy' is not an Euler sequence"),
    (['-p', 'outputs:=[euler,eulr]'], "'eulr' is not allowed"),
    (['-p', 'euler.degrees:=1'], 'euler.degrees'),
    (['-p', 'qos.depth:=0'], 'qos.depth'),
    (['-p', 'mounting.tf_sensor_frame:=imu_link'], "'mounting.tf_body_frame': required"),
    (['-p', 'mounting.body_rotation:=[0.0,0.0,2.0,0.0]'], 'unit quaternion'),
], ids=['sequence', 'outputs', 'type', 'range', 'one_mounting_frame', 'mounting_norm'])
def test_an_invalid_initial_value_exits_non_zero_with_the_reason(args, message):
    process = RosProcess([script('rotation_node'), '--ros-args', *args])
    process.proc.wait(timeout=START_TIMEOUT_S)
    assert process.stop() == 1
    assert message in process.output
    assert 'Traceback' not in process.output


BAD_PARAMETERS_FILES = {
    'misspelt key': ('/**/rotation_node:\n  ros__parameters:\n    euler:\n      sequense: ZYX\n',
                     [], "unknown parameter 'euler.sequense' (did you mean 'euler.sequence'?)"),
    'no section': ('other_node:\n  ros__parameters:\n    qos.depth: 5\n', [],
                   "no section for node '/rotation_node'"),
    'no section in the namespace': ('rotation_node:\n  ros__parameters:\n    qos.depth: 5\n',
                                    ['-r', '__ns:=/robot'],
                                    "no section for node '/robot/rotation_node'"),
    'empty outputs': ('/**:\n  ros__parameters:\n    outputs: []\n', [],
                      "parameter 'outputs': list at least one output"),
    'malformed': ('rotation_node: [unclosed\n', [], 'invalid YAML (line 2, column 1)'),
    'malformed section of another node': (
        '/**/rotation_node:\n  ros__parameters: {}\nother_node:\n  rate: 5\n', [],
        "section 'other_node' needs a 'ros__parameters:' mapping"),
    'missing': (None, [], 'cannot read it (No such file or directory)'),
    # What rcl itself refuses, in a traceback, unless the node refuses it first:
    'invalid node name': ('rotation-node:\n  ros__parameters:\n    qos.depth: 5\n', [],
                          "section 'rotation-node': 'rotation-node' is not a node name"),
    'mixed list': ('/**:\n  ros__parameters:\n    outputs: [euler, 1]\n', [],
                   "'outputs': a list must hold values of one type, got int, str"),
    'no value': ('/**:\n  ros__parameters:\n    qos.depth:\n', [],
                 "parameter 'qos.depth' has no value"),
    'alias': ('/**:\n  ros__parameters:\n    a: &x 1\n    b: *x\n', [],
              'aliases (*name) are not allowed in a parameters file'),
}


@pytest.mark.parametrize('name', BAD_PARAMETERS_FILES)
def test_node_and_convert_reject_the_same_parameters_files(tmp_path, name):
    text, args, message = BAD_PARAMETERS_FILES[name]
    path = tmp_path / 'params.yaml'
    if text is not None:
        path.write_text(text)
    result = subprocess.run(
        [script('rotation_node'), '--ros-args', *args, '--params-file', str(path)],
        capture_output=True, text=True, timeout=START_TIMEOUT_S)
    assert result.returncode == 1
    assert result.stderr.startswith('rotation_node: error: ') and result.stderr.count('\n') == 1
    assert message in result.stderr and 'Traceback' not in result.stdout
    namespace = '/robot' if args else ''
    with pytest.raises(ParameterError) as convert_error:   # what rotation_bag convert reads
        parameters_from_yaml(path, f'{namespace}/rotation_node')
    assert result.stderr == f'rotation_node: error: {convert_error.value}\n'


def test_an_unknown_parameter_on_the_command_line_names_the_nearest():
    result = subprocess.run(
        [script('rotation_node'), '--ros-args', '-p', 'other_node:rate:=5', '-p', 'qos.dept:=5'],
        capture_output=True, text=True, timeout=START_TIMEOUT_S)
    assert result.returncode == 1
    assert result.stderr == (
        "rotation_node: error: unknown parameter 'qos.dept' in -p qos.dept:=5 (did you mean "
        f"'qos.depth'?); the node's parameters are {', '.join(p.name for p in PARAMETERS)}\n")


def test_a_params_file_flag_without_a_file_is_one_error_line():
    result = subprocess.run([script('rotation_node'), '--ros-args', '--params-file'],
                            capture_output=True, text=True, timeout=START_TIMEOUT_S)
    assert result.returncode == 1 and 'Traceback' not in result.stderr
    last = result.stderr.splitlines()[-1]
    assert last.startswith('rotation_node: error: ') and 'No file path provided' in last


@pytest.fixture(scope='module')
def namespaced(ros):
    under_test = NodeUnderTest(ros, ['-r', '__ns:=/robot', '-r', 'input:=/imu'],
                               namespace='/robot')
    yield under_test
    under_test.stop()


def test_namespace_and_input_remapping(namespaced, rotation):
    msg = make_input_message('imu', rotation, frame_id='imu_link')
    out, = namespaced.exchange('imu', [msg], {'euler': 1}, topic='/imu')['euler']
    assert_output(out, 'euler', rotation)
    assert namespaced.ros.node.count_publishers('/robot/euler') == 1
    values = namespaced.next_diagnostics()
    assert values['name'] == '/robot/rotation_node: orientation conversion'
    assert values['input_topic'] == '/imu'


def test_ctrl_c_exits_cleanly(namespaced):
    assert namespaced.stop() == 0, namespaced.process.output
    assert 'Traceback' not in namespaced.process.output


START_UP_MOMENTS = {
    # where the signal comes: (the name in rotation_node.node's modules to wrap, before or
    # after it)
    'before rclpy.init': ('rclpy.init', 'before'),
    'between rclpy.init and the node': ('conversion_node.load_in_background', 'before'),
    'while the node is configured': ('RotationNode._configure', 'before'),
    'before rclpy handles signals': ('program.install_signal_handlers', 'before'),
    'once rclpy handles signals': ('program.install_signal_handlers', 'after'),
}


@pytest.mark.parametrize('moment', START_UP_MOMENTS)
@pytest.mark.parametrize('number', [signal.SIGINT, signal.SIGTERM], ids=lambda n: n.name)
def test_a_signal_at_any_moment_of_start_up_is_one_line_and_exit_0(monkeypatch, capsys,
                                                                   moment, number):
    """In-process: the signal is raised in the main thread at that moment of main()."""
    import rclpy
    from rotation_node.node import conversion_node, program
    path, when = START_UP_MOMENTS[moment]
    owner_name, _, attribute = path.rpartition('.')
    owner = {'program': program, 'conversion_node': conversion_node, 'rclpy': rclpy,
             'RotationNode': conversion_node.RotationNode}[owner_name]
    original = getattr(owner, attribute)
    raised = []

    def wrapped(*args, **kwargs):
        if when == 'before':
            raised.append(number)
            signal.raise_signal(number)
        result = original(*args, **kwargs)
        if when == 'after':
            raised.append(number)
            signal.raise_signal(number)
        return result

    monkeypatch.setattr(owner, attribute, wrapped)
    handlers = {n: signal.getsignal(n) for n in (signal.SIGINT, signal.SIGTERM)}
    assert program.main(['rotation_node']) == 0
    assert raised == [number]
    assert capsys.readouterr().err.splitlines() == [
        f'rotation_node: interrupted while starting ({number.name})']
    assert not rclpy.ok()
    assert {n: signal.getsignal(n) for n in handlers} == handlers


@pytest.mark.parametrize('number', [signal.SIGINT, signal.SIGTERM], ids=lambda n: n.name)
def test_a_signal_while_the_node_loads_exits_0_with_one_line(number):
    process = RosProcess([script('rotation_node')])
    time.sleep(0.3)   # loading numpy, numba, rclpy: seconds
    process.proc.send_signal(number)
    process.output, _ = process.proc.communicate(timeout=START_TIMEOUT_S)
    assert process.proc.returncode == 0, process.output
    assert process.output.splitlines()[-1] == (
        f'rotation_node: interrupted while starting ({number.name})')
    assert 'Traceback' not in process.output


def test_sigterm_while_spinning_exits_0(ros):
    started = NodeUnderTest(ros, ['-r', '__ns:=/sigterm'], namespace='/sigterm')
    for subscription in started.subscriptions.values():
        ros.node.destroy_subscription(subscription)
    # The parameter services exist before the node is constructed; an answer means it spins.
    assert started.get('input_type') == 'imu'
    started.process.proc.send_signal(signal.SIGTERM)
    started.process.output, _ = started.process.proc.communicate(timeout=15.0)
    assert started.process.proc.returncode == 0, started.process.output
    assert 'Traceback' not in started.process.output
    assert 'interrupted while starting' not in started.process.output


def test_destroying_the_node_destroys_its_message_lost_event_handles_first():
    """No event handle outlives the subscription it belongs to."""
    import rclpy
    from rclpy.context import Context
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rotation_node.node.conversion_node import RotationNode
    context = Context()
    rclpy.init(context=context)
    try:
        node = RotationNode(context=context)
        events = [e for state in node._inputs for e in state.message_lost.values()
                  if e is not None]
        assert events, 'Fast DDS reports message-lost events'
        for event in events:
            with event:
                pass
        node.destroy_node()
        assert not any(state.message_lost for state in node._inputs)
        for event in events:
            with pytest.raises(rclpy_implementation.InvalidHandle):
                with event:
                    pass
    finally:
        rclpy.try_shutdown(context=context)


def test_issue_warnings_are_throttled_per_reason():
    """A flood of one problem logs it once per period and cannot hide another problem."""
    import rclpy
    from rclpy.context import Context
    from rotation_node.node.conversion_node import RotationNode
    context = Context()
    rclpy.init(context=context)
    try:
        node = RotationNode(context=context)
        logged = []

        class Logger:
            def warning(self, text):
                logged.append(text)
        node.get_logger = Logger
        for _ in range(1000):
            node._log_issue('non_unit_quaternion', 'normalised')
        node._log_issue('zero_quaternion', 'dropped')
        assert logged == ['normalised [non_unit_quaternion]', 'dropped [zero_quaternion]']
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
