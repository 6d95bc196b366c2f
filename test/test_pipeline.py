"""
Tests of rotation_node.pipeline: conversions, per-stream state, bad input, block form.

The block form's own contract is at the end.

Fast, no processes: the node and ``rotation_bag convert`` both run this code, so
the values are checked here against scipy, and test_node.py checks the wiring.
"""
import dataclasses
import math
import types

from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from ros_harness import (
    INPUT_COVARIANCE, make_input_message, oracle_output, output_values, PLAIN_INPUT_TYPES)
from rotation_node import conversions, registry
from rotation_node import pipeline as pipeline_module
from rotation_node.conversions import SEQUENCES
from rotation_node.conversions.kernels import BATCH_SAMPLES
from rotation_node.parameters import NodeParameters, OUTPUTS
from rotation_node.pipeline import (
    _sign_chain, _turns_away, _unwrap_chain, _unwrapped, block_form_missing, BLOCK_SAMPLES,
    CONVERSION_ERROR, ConversionPipeline, COVARIANCE_TOO_LARGE, COVARIANCE_UNKNOWN,
    EULER_COVARIANCE_NEAR_SINGULAR, EULER_COVARIANCE_NOT_LINEAR, EULER_RATES_NEAR_SINGULAR,
    input_message_type,
    INVALID_COVARIANCE, NON_FINITE_ANGULAR_VELOCITY, NON_FINITE_COVARIANCE,
    NON_FINITE_ORIENTATION, NON_UNIT_QUATERNION, ORIENTATION_UNKNOWN, output_has_block_form,
    TIMESTAMP_NOT_INCREASING, ZERO_QUATERNION)
from rotation_node.sample_block import SampleBlock
from scipy.spatial.transform import Rotation
from std_msgs.msg import Float64MultiArray

STAMP_NS = 1_700_000_000_123_456_789   # a realistic wall-clock stamp (float seconds lose ~0.2 us)
FRAME_ID = 'imu_link'


def pipeline(**params):
    issues = []
    p = ConversionPipeline(NodeParameters(**params),
                           on_issue=lambda reason, detail: issues.append((reason, detail)))
    p.issues = issues
    return p


def outputs_of(p, msg):
    return dict(p.process(msg))


def set_orientation(msg, input_type, values):
    q = {'quaternion': lambda m: m.quaternion, 'imu': lambda m: m.orientation,
         'odometry': lambda m: m.pose.pose.orientation}[input_type](msg)
    q.x, q.y, q.z, q.w = values


def same_rotation(q, expected):
    """Quaternions equal up to sign."""
    return min(np.abs(q - expected).max(), np.abs(q + expected).max()) < 1e-12


@pytest.fixture
def rotation(rng):
    return Rotation.random(random_state=rng)


# Input types ----------------------------------------------------------------------

@pytest.mark.parametrize('input_type, expected', [
    ('quaternion', 'geometry_msgs/msg/QuaternionStamped'),
    ('pose', 'geometry_msgs/msg/PoseStamped'),
    ('pose_with_covariance', 'geometry_msgs/msg/PoseWithCovarianceStamped'),
    ('imu', 'sensor_msgs/msg/Imu'),
    ('odometry', 'nav_msgs/msg/Odometry'),
    ('transform', 'geometry_msgs/msg/TransformStamped'),
    ('euler', 'geometry_msgs/msg/Vector3Stamped'),
    ('rotation_vector', 'geometry_msgs/msg/Vector3Stamped'),
])
def test_input_type_selects_the_message_class(input_type, expected):
    message_type = input_message_type(input_type)
    assert f'{message_type.__module__.split(".")[0]}/msg/{message_type.__name__}' == expected
    assert pipeline(input_type=input_type).input_type is message_type


@pytest.mark.parametrize('input_type', PLAIN_INPUT_TYPES)
def test_every_input_type_gives_its_orientation_with_the_header(input_type, rotation):
    p = pipeline(input_type=input_type, outputs=['quaternion'])
    msg = make_input_message(input_type, rotation, stamp_ns=STAMP_NS, frame_id=FRAME_ID)
    (name, out), = p.process(msg)
    assert name == 'quaternion' and isinstance(out, QuaternionStamped)
    assert same_rotation(output_values(out), rotation.as_quat())
    assert (out.header.stamp.sec, out.header.stamp.nanosec) == divmod(STAMP_NS, 10**9)
    assert out.header.frame_id == FRAME_ID


@pytest.mark.parametrize('sequence', SEQUENCES)
def test_euler_input_in_every_convention(sequence, rotation):
    p = pipeline(input_type='euler', outputs=['quaternion'], euler_sequence=sequence)
    out = outputs_of(p, make_input_message('euler', rotation, sequence=sequence))['quaternion']
    assert same_rotation(output_values(out), rotation.as_quat())


def test_euler_input_in_degrees(rotation):
    p = pipeline(input_type='euler', outputs=['quaternion'], euler_degrees=True)
    msg = make_input_message('euler', rotation, degrees=True)
    assert same_rotation(output_values(outputs_of(p, msg)['quaternion']), rotation.as_quat())


# Orientation outputs --------------------------------------------------------------

def test_output_types_follow_outputs_in_order():
    p = pipeline(outputs=['matrix', 'euler', 'quaternion_rate'])
    assert p.output_types == {
        'matrix': Float64MultiArray, 'euler': Vector3Stamped,
        'quaternion_rate': QuaternionStamped}


def test_all_outputs_come_in_the_order_of_outputs(rotation):
    order = list(reversed(OUTPUTS))
    p = pipeline(input_type='imu', outputs=order)
    assert [name for name, _ in p.process(make_input_message('imu', rotation))] == order


def test_quaternion_output_is_unit_with_w_positive(rotation):
    p = pipeline(input_type='quaternion', outputs=['quaternion'])
    msg = make_input_message('quaternion', rotation)
    # Non-unit and w < 0, within the norm tolerance.
    set_orientation(msg, 'quaternion', -0.9995 * rotation.as_quat(canonical=True))
    q = output_values(outputs_of(p, msg)['quaternion'])
    np.testing.assert_allclose(q, rotation.as_quat(canonical=True), atol=1e-15)
    assert p.stats.normalised == 0 and p.issues == []


@pytest.mark.parametrize('sequence', SEQUENCES)
def test_euler_output_in_every_convention(sequence, rotation):
    p = pipeline(input_type='quaternion', outputs=['euler'], euler_sequence=sequence)
    out = outputs_of(p, make_input_message('quaternion', rotation))['euler']
    np.testing.assert_allclose(output_values(out), rotation.as_euler(sequence), atol=1e-12)


def test_euler_output_in_degrees(rotation):
    p = pipeline(input_type='quaternion', outputs=['euler'], euler_degrees=True)
    out = outputs_of(p, make_input_message('quaternion', rotation))['euler']
    np.testing.assert_allclose(output_values(out), rotation.as_euler('xyz', degrees=True),
                               atol=1e-10)


OMEGA_BODY = np.array([0.3, -1.2, 2.5])


@pytest.mark.parametrize('frame', ['body', 'world'])
@pytest.mark.parametrize('name', OUTPUTS)
def test_every_output_matches_scipy(name, frame, rotation):
    p = pipeline(input_type='imu', outputs=[name], angular_velocity_output_frame=frame)
    msg = make_input_message('imu', rotation, omega=OMEGA_BODY)
    out = outputs_of(p, msg)[name]
    expected = oracle_output(name, rotation, OMEGA_BODY, frame=frame)
    rates = name in ('euler_rates', 'quaternion_rate')
    np.testing.assert_allclose(output_values(out), expected, rtol=1e-7 if rates else 0,
                               atol=1e-8 if rates else 1e-12)


def test_axis_angle_layout():
    out = outputs_of(pipeline(outputs=['axis_angle']),
                     make_input_message('imu', Rotation.identity()))['axis_angle']
    assert [(d.label, d.size, d.stride) for d in out.layout.dim] == [('axis_angle', 4, 4)]
    assert list(out.data) == [1.0, 0.0, 0.0, 0.0]   # identity: axis (1, 0, 0), angle 0


def test_matrix_layout_is_row_major():
    rotation = Rotation.from_euler('z', 0.5)
    out = outputs_of(pipeline(outputs=['matrix']), make_input_message('imu', rotation))['matrix']
    assert [(d.label, d.size, d.stride) for d in out.layout.dim] == [
        ('rows', 3, 9), ('cols', 3, 3)]
    assert out.data[1] == pytest.approx(-math.sin(0.5))   # R[0, 1]


def test_stamped_outputs_keep_the_header_and_counts_add_up(rotation):
    p = pipeline(input_type='imu', outputs=list(OUTPUTS))
    msg = make_input_message('imu', rotation, omega=(0.1, 0.2, 0.3), stamp_ns=STAMP_NS,
                             frame_id=FRAME_ID)
    results = p.process(msg)
    stamped = [out for _, out in results if hasattr(out, 'header')]
    assert len(stamped) == len(OUTPUTS) - 2   # axis_angle and matrix have no header
    assert all(out.header == msg.header for out in stamped)
    assert (p.stats.received, p.stats.published) == (1, len(OUTPUTS))


# Angular velocity -----------------------------------------------------------------

@pytest.mark.parametrize('input_frame, output_frame', [
    ('body', 'body'), ('body', 'world'), ('world', 'body'), ('world', 'world')])
@pytest.mark.parametrize('input_type', ['imu', 'odometry'])
def test_measured_angular_velocity_changes_frame(input_type, input_frame, output_frame,
                                                 rotation):
    omega = {'body': OMEGA_BODY, 'world': rotation.apply(OMEGA_BODY)}
    p = pipeline(input_type=input_type, outputs=['angular_velocity'],
                 angular_velocity_input_frame=input_frame,
                 angular_velocity_output_frame=output_frame)
    msg = make_input_message(input_type, rotation, omega=omega[input_frame])
    out = outputs_of(p, msg)['angular_velocity']
    np.testing.assert_allclose(output_values(out), omega[output_frame], atol=1e-12)


def constant_rate_messages(input_type, rotation, dt_ns, **kwargs):
    """Two messages of a rotation at constant body rate OMEGA_BODY, dt_ns apart."""
    second = rotation * Rotation.from_rotvec(OMEGA_BODY * dt_ns * 1e-9)
    return [make_input_message(input_type, r, stamp_ns=STAMP_NS + k * dt_ns, **kwargs)
            for k, r in enumerate((rotation, second))]


@pytest.mark.parametrize('frame', ['body', 'world'])
@pytest.mark.parametrize('input_type', [
    'quaternion', 'pose', 'pose_with_covariance', 'transform', 'euler', 'rotation_vector'])
def test_finite_difference_angular_velocity(input_type, frame, rotation):
    p = pipeline(input_type=input_type, outputs=['angular_velocity'],
                 angular_velocity_output_frame=frame)
    first, second = constant_rate_messages(input_type, rotation, dt_ns=1_000_000)
    assert p.process(first) == []   # nothing to difference against yet
    out = outputs_of(p, second)['angular_velocity']
    expected = OMEGA_BODY if frame == 'body' else rotation.apply(OMEGA_BODY)
    np.testing.assert_allclose(output_values(out), expected, rtol=1e-9)
    assert out.header == second.header


def test_imu_without_angular_velocity_falls_back_to_finite_difference(rotation):
    p = pipeline(input_type='imu', outputs=['angular_velocity'])
    messages = constant_rate_messages('imu', rotation, dt_ns=5_000_000)
    for msg in messages:
        msg.angular_velocity.x = 99.0                 # not to be used:
        msg.angular_velocity_covariance[0] = -1.0     # "no estimate" (sensor_msgs/Imu)
    p.process(messages[0])
    out = outputs_of(p, messages[1])['angular_velocity']
    np.testing.assert_allclose(output_values(out), OMEGA_BODY, rtol=1e-9)


@pytest.mark.parametrize('sequence', ['xyz', 'ZYX', 'zxz', 'YXY'])
@pytest.mark.parametrize('frame', ['body', 'world'])
def test_euler_rates_in_several_conventions(sequence, frame):
    rotation = Rotation.from_euler(sequence, [0.4, 0.7, -2.0])   # away from gimbal lock
    omega = oracle_output('angular_velocity', rotation, OMEGA_BODY, frame=frame)
    p = pipeline(input_type='imu', outputs=['euler_rates'], euler_sequence=sequence,
                 angular_velocity_input_frame=frame, angular_velocity_output_frame=frame)
    out = outputs_of(p, make_input_message('imu', rotation, omega=omega))['euler_rates']
    np.testing.assert_allclose(output_values(out),
                               oracle_output('euler_rates', rotation, OMEGA_BODY,
                                             sequence=sequence), rtol=1e-7)


def test_euler_rates_in_degrees_per_second(rotation):
    p = pipeline(input_type='imu', outputs=['euler_rates'], euler_degrees=True)
    out = outputs_of(p, make_input_message('imu', rotation, omega=OMEGA_BODY))['euler_rates']
    np.testing.assert_allclose(
        output_values(out), oracle_output('euler_rates', rotation, OMEGA_BODY, degrees=True),
        rtol=1e-7)


def test_euler_rates_are_skipped_near_gimbal_lock():
    rotation = Rotation.from_euler('xyz', [0.3, np.pi / 2 - 1e-3, 0.2])
    p = pipeline(input_type='imu', outputs=['euler', 'euler_rates'])
    results = outputs_of(p, make_input_message('imu', rotation, omega=OMEGA_BODY))
    assert list(results) == ['euler']
    assert p.stats.skipped == {EULER_RATES_NEAR_SINGULAR: 1} and p.stats.near_singular == 1
    assert [r for r, _ in p.issues] == [EULER_RATES_NEAR_SINGULAR]


def test_quaternion_rate_has_the_sign_of_the_published_quaternion():
    # Yaw 3.1 then -3.1 rad: with continuity the second quaternion is published with w < 0.
    before, rotation = Rotation.from_euler('z', 3.1), Rotation.from_euler('z', -3.1)
    p = pipeline(input_type='imu', outputs=['quaternion', 'quaternion_rate'],
                 quaternion_continuity=True)
    p.process(make_input_message('imu', before))
    results = outputs_of(p, make_input_message('imu', rotation, omega=OMEGA_BODY))
    np.testing.assert_allclose(output_values(results['quaternion']),
                               -rotation.as_quat(canonical=True), atol=1e-15)
    np.testing.assert_allclose(output_values(results['quaternion_rate']),
                               -oracle_output('quaternion_rate', rotation, OMEGA_BODY),
                               atol=1e-8)


# Orientation uncertainty ----------------------------------------------------------

UNCERTAINTY = ['euler', 'euler_stddev', 'euler_covariance']
COVARIANCE_INPUTS = ['imu', 'odometry', 'pose_with_covariance']


@pytest.mark.parametrize('input_type', COVARIANCE_INPUTS)
@pytest.mark.parametrize('covariance_frame', ['fixed', 'body'])
@pytest.mark.parametrize('sequence, degrees', [('xyz', False), ('ZYX', True), ('zxz', True)])
def test_euler_uncertainty_matches_scipy_finite_differences(input_type, covariance_frame,
                                                            sequence, degrees, rotation):
    p = pipeline(input_type=input_type, outputs=UNCERTAINTY, euler_sequence=sequence,
                 euler_degrees=degrees, covariance_frame=covariance_frame)
    msg = make_input_message(input_type, rotation, stamp_ns=STAMP_NS, frame_id=FRAME_ID)
    out = outputs_of(p, msg)
    for name in ('euler_stddev', 'euler_covariance'):
        expected = oracle_output(name, rotation, sequence=sequence, degrees=degrees,
                                 covariance_frame=covariance_frame)
        np.testing.assert_allclose(output_values(out[name]), expected, rtol=1e-7, atol=1e-12,
                                   err_msg=name)
        assert out[name].header == msg.header
    assert np.array_equal(output_values(out['euler_covariance'])[:3],
                          output_values(out['euler']))


@pytest.mark.parametrize('input_type', COVARIANCE_INPUTS)
def test_unknown_covariance_gives_no_uncertainty_and_is_counted(input_type, rotation):
    p = pipeline(input_type=input_type, outputs=UNCERTAINTY)
    msg = make_input_message(input_type, rotation, covariance=[0.0] * 9)
    assert list(outputs_of(p, msg)) == ['euler']
    assert p.stats.skipped == {COVARIANCE_UNKNOWN: 1}
    msg = make_input_message(input_type, rotation, covariance=[0.0] * 8 + [math.nan])
    assert list(outputs_of(p, msg)) == ['euler']
    assert p.stats.skipped[NON_FINITE_COVARIANCE] == 1


ALL_BUT_UNCERTAINTY = [name for name in OUTPUTS
                       if name not in ('euler_stddev', 'euler_covariance')]


@pytest.mark.parametrize('covariance, reason', [
    ([1e308, 0, 0, 0, 1e308, 0, 0, 0, 1e308], COVARIANCE_TOO_LARGE),   # DBL_MAX-ish "unknown"
    ([1e9, 0, 0, 0, 1e9, 0, 0, 0, 1e9], COVARIANCE_TOO_LARGE),
    ([1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e308], COVARIANCE_TOO_LARGE),
    ([-1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6], INVALID_COVARIANCE),        # negative variance
    ([1e-6, 5e-7, 0, -5e-7, 1e-6, 0, 0, 0, 1e-6], INVALID_COVARIANCE),  # asymmetric
    ([1e-6, 2e-6, 0, 2e-6, 1e-6, 0, 0, 0, 1e-6], INVALID_COVARIANCE),   # correlation 2
    ([1e-6, 0, 1e308, 0, 1e-6, 0, 1e308, 0, 1e-6], INVALID_COVARIANCE),
    ([1e-6, -9e-7, -9e-7, -9e-7, 1e-6, -9e-7, -9e-7, -9e-7, 1e-6],      # |c| < 1, det < 0
     INVALID_COVARIANCE),
    ([math.inf, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6], NON_FINITE_COVARIANCE),
], ids=['dbl_max', '1e9', 'one_axis_dbl_max', 'negative', 'asymmetric', 'correlation',
        'huge_covariance', 'indefinite', 'inf'])
@pytest.mark.parametrize('input_type', COVARIANCE_INPUTS)
def test_a_covariance_edge_case_skips_only_the_uncertainty_outputs(input_type, covariance,
                                                                   reason, rotation):
    """Every other output is published; no NaN standard deviation; the reason is counted."""
    p = pipeline(input_type=input_type, outputs=list(OUTPUTS))
    reference = pipeline(input_type=input_type, outputs=ALL_BUT_UNCERTAINTY)
    for k in range(2):   # the second gives the finite-difference outputs too
        msg = make_input_message(input_type, rotation, omega=(0.1, 0.2, 0.3),
                                 stamp_ns=STAMP_NS + k * 10**6, covariance=covariance)
        out = p.process_values(msg)
        expected = reference.process_values(msg)
        assert [name for name, _, _ in out] == [name for name, _, _ in expected]
        for (_, _, numbers), (_, _, numbers_expected) in zip(out, expected):
            np.testing.assert_array_equal(numbers, numbers_expected)
    assert [name for name, _, _ in out] == ALL_BUT_UNCERTAINTY
    assert p.stats.dropped == {} and p.stats.skipped == {reason: 2}
    assert all(r == reason and 'uncertainty outputs skipped' in detail
               for r, detail in p.issues)


def test_a_valid_covariance_at_the_edge_of_definiteness_is_published(rotation):
    """Fully correlated axes (rank 1) and a zero variance are covariances: published."""
    p = pipeline(input_type='imu', outputs=['euler_stddev', 'euler_covariance'])
    for covariance in ([1e-6, 1e-6, 1e-6] * 3, [1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 0.0],
                       [1e-6, -1e-6, 0, -1e-6, 1e-6, 0, 0, 0, 4e-6]):
        out = outputs_of(p, make_input_message('imu', rotation, covariance=covariance))
        assert np.isfinite(output_values(out['euler_stddev'])).all()
    assert p.stats.skipped == {}


def test_imu_orientation_unknown_gives_no_uncertainty(rotation):
    p = pipeline(input_type='imu', outputs=UNCERTAINTY)
    msg = make_input_message('imu', rotation)
    msg.orientation_covariance[0] = -1.0
    assert outputs_of(p, msg) == {}
    assert p.stats.skipped == {ORIENTATION_UNKNOWN: 1}


def test_an_input_without_covariance_counts_it_unknown(rotation):
    p = pipeline(input_type='quaternion', outputs=UNCERTAINTY)
    assert list(outputs_of(p, make_input_message('quaternion', rotation))) == ['euler']
    assert p.stats.skipped == {COVARIANCE_UNKNOWN: 1}


def test_gimbal_lock_and_non_linear_covariance_are_skipped_and_counted():
    p = pipeline(input_type='imu', outputs=UNCERTAINTY, euler_singularity_threshold=0.01)
    sigma = 1e-3   # isotropic: sigma / margin is the linearisation ratio
    covariance = np.diag([sigma ** 2] * 3).ravel()
    for margin, reason in [(0.005, EULER_COVARIANCE_NEAR_SINGULAR),
                           (0.002, EULER_COVARIANCE_NEAR_SINGULAR),
                           (0.0031, EULER_COVARIANCE_NEAR_SINGULAR),
                           (0.02, None), (1.0, None)]:
        rotation = Rotation.from_euler('xyz', [0.3, np.pi / 2 - margin, -1.0])
        out = outputs_of(p, make_input_message('imu', rotation, covariance=covariance))
        assert ('euler_stddev' in out) == (reason is None), margin
    assert p.stats.skipped == {EULER_COVARIANCE_NEAR_SINGULAR: 3}
    p = pipeline(input_type='imu', outputs=UNCERTAINTY, euler_singularity_threshold=0.001,
                 covariance_max_linearisation_ratio=0.3)
    for margin, published in [(0.0031, False), (0.0034, True), (0.5, True)]:
        rotation = Rotation.from_euler('xyz', [0.3, np.pi / 2 - margin, -1.0])
        out = outputs_of(p, make_input_message('imu', rotation, covariance=covariance))
        assert ('euler_covariance' in out) == published, margin
    assert p.stats.skipped == {EULER_COVARIANCE_NOT_LINEAR: 1}
    assert any('covariance.max_linearisation_ratio' in detail for _, detail in p.issues)


# Frame conventions -----------------------------------------------------------------

# Hand transcriptions: NED from ENU swaps x and y and negates z; FRD from FLU negates y, z.
NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])
PX4_FRAMES = {'frames_input_world': 'ned', 'frames_input_body': 'frd'}


def px4_imu(rotation, omega_body, covariance, covariance_frame='fixed'):
    """Return the Imu message of the same motion and uncertainty written in NED/FRD."""
    r = NED_FROM_ENU @ rotation.as_matrix() @ FRD_FROM_FLU
    block = FRD_FROM_FLU if covariance_frame == 'body' else NED_FROM_ENU
    cov = block @ np.reshape(covariance, (3, 3)) @ block.T
    return make_input_message('imu', Rotation.from_matrix(r), omega=FRD_FROM_FLU @ omega_body,
                              stamp_ns=STAMP_NS, covariance=cov.ravel())


@pytest.mark.parametrize('covariance_frame', ['fixed', 'body'])
@pytest.mark.parametrize('output_frame', ['body', 'world'])
def test_px4_ned_frd_stream_becomes_rep_103(covariance_frame, output_frame, rotation, rng):
    omega = rng.normal(size=3)
    outputs = ['quaternion', 'angular_velocity', *UNCERTAINTY]
    p = pipeline(input_type='imu', outputs=outputs, covariance_frame=covariance_frame,
                 angular_velocity_output_frame=output_frame, **PX4_FRAMES)
    out = outputs_of(p, px4_imu(rotation, omega, INPUT_COVARIANCE, covariance_frame))
    for name in outputs:
        expected = oracle_output(name, rotation, omega, frame=output_frame,
                                 covariance_frame=covariance_frame)
        if name == 'quaternion':
            assert same_rotation(output_values(out[name]), expected)
        else:
            np.testing.assert_allclose(output_values(out[name]), expected, rtol=1e-7,
                                       atol=1e-12, err_msg=name)


def test_rep_103_stream_becomes_px4_and_back(rotation, rng):
    omega = rng.normal(size=3)
    to_px4 = pipeline(input_type='imu', outputs=['quaternion', 'angular_velocity', 'matrix'],
                      frames_output_world='ned', frames_output_body='frd')
    msg = make_input_message('imu', rotation, omega=omega, stamp_ns=STAMP_NS)
    out = outputs_of(to_px4, msg)
    expected = Rotation.from_matrix(NED_FROM_ENU @ rotation.as_matrix() @ FRD_FROM_FLU)
    assert same_rotation(output_values(out['quaternion']), expected.as_quat())
    np.testing.assert_allclose(output_values(out['matrix']).reshape(3, 3), expected.as_matrix(),
                               atol=1e-15)
    assert np.array_equal(output_values(out['angular_velocity']), FRD_FROM_FLU @ omega)
    # yaw is measured from north clockwise in NED: pi/2 minus the ENU yaw
    roll, pitch, yaw = rotation.as_euler('xyz')
    euler = pipeline(input_type='imu', outputs=['euler'], frames_output_world='ned',
                     frames_output_body='frd')
    got = output_values(outputs_of(euler, msg)['euler'])
    assert np.allclose(np.remainder(got - [roll, -pitch, np.pi / 2 - yaw] + np.pi, 2 * np.pi)
                       - np.pi, 0.0, atol=1e-9)
    back = pipeline(input_type='quaternion', outputs=['quaternion'], **PX4_FRAMES)
    q_px4 = make_input_message('quaternion', Rotation.from_quat(output_values(out['quaternion'])))
    q_back = output_values(outputs_of(back, q_px4)['quaternion'])
    assert same_rotation(q_back, rotation.as_quat())


def test_frames_apply_to_euler_and_rotation_vector_inputs(rotation):
    expected = NED_FROM_ENU @ rotation.as_matrix() @ FRD_FROM_FLU
    for input_type in ('euler', 'rotation_vector'):
        p = pipeline(input_type=input_type, outputs=['matrix'], frames_output_world='ned',
                     frames_output_body='frd')
        got = output_values(outputs_of(p, make_input_message(input_type, rotation))['matrix'])
        np.testing.assert_allclose(got.reshape(3, 3), expected, atol=1e-14)


# Mounting and world alignment --------------------------------------------------------

MOUNT_M = Rotation.from_euler('xyz', [15.0, -40.0, 100.0], degrees=True)
MOUNT_W = Rotation.from_euler('xyz', [2.0, -3.0, 60.0], degrees=True)
MOUNTING = {'mounting_body_rotation': tuple(MOUNT_M.as_quat()),
            'mounting_world_rotation': (2.0, -3.0, 40.0), 'mounting_yaw_offset': 0.2,
            'mounting_magnetic_declination': math.radians(20.0) - 0.2}


@pytest.mark.parametrize('covariance_frame', ['fixed', 'body'])
@pytest.mark.parametrize('output_frame', ['body', 'world'])
@pytest.mark.parametrize('input_frame', ['body', 'world'])
def test_mounting_applies_w_r_m_to_orientation_rates_and_covariance(
        covariance_frame, output_frame, input_frame, rotation, rng):
    """The outputs are scipy's of the mounted motion: W R M, M^T w, W S W^T or M^T S M."""
    omega = rng.normal(size=3)
    outputs = ['quaternion', 'angular_velocity', *UNCERTAINTY]
    p = pipeline(input_type='imu', outputs=outputs, covariance_frame=covariance_frame,
                 angular_velocity_input_frame=input_frame,
                 angular_velocity_output_frame=output_frame, **MOUNTING)
    measured = omega if input_frame == 'body' else rotation.apply(omega)
    out = outputs_of(p, make_input_message('imu', rotation, omega=measured, stamp_ns=STAMP_NS))
    mounted = MOUNT_W * rotation * MOUNT_M
    sigma = np.reshape(INPUT_COVARIANCE, (3, 3))
    side = MOUNT_W.as_matrix() if covariance_frame == 'fixed' else MOUNT_M.as_matrix().T
    for name in outputs:
        expected = oracle_output(name, mounted, MOUNT_M.inv().apply(omega), frame=output_frame,
                                 covariance=(side @ sigma @ side.T).ravel(),
                                 covariance_frame=covariance_frame)
        if name == 'quaternion':
            assert same_rotation(output_values(out[name]), expected)
        else:
            np.testing.assert_allclose(output_values(out[name]), expected, rtol=1e-7,
                                       atol=1e-12, err_msg=name)


def test_mounting_finite_difference_rate_is_the_mounted_bodys(rotation, rng):
    omega = rng.normal(size=3)
    p = pipeline(input_type='quaternion', outputs=['angular_velocity'], **MOUNTING)
    for k in range(2):
        moved = rotation * Rotation.from_rotvec(omega * k * 0.01)
        out = outputs_of(p, make_input_message('quaternion', moved,
                                               stamp_ns=STAMP_NS + k * 10_000_000))
    np.testing.assert_allclose(output_values(out['angular_velocity']),
                               MOUNT_M.inv().apply(omega), rtol=1e-9, atol=1e-12)


def test_yaw_offset_and_declination_add_to_the_ros_yaw(rotation):
    p = pipeline(input_type='imu', outputs=['euler'], mounting_yaw_offset=0.3,
                 mounting_magnetic_declination=-0.1)
    got = output_values(outputs_of(p, make_input_message('imu', rotation))['euler'])
    expected = rotation.as_euler('xyz') + [0.0, 0.0, 0.2]
    assert np.allclose(np.remainder(got - expected + np.pi, 2 * np.pi) - np.pi, 0.0, atol=1e-12)


def test_mounting_after_the_frame_conventions(rotation):
    """R_out = W (P R B) M: a PX4 stream mounted in REP 103 terms."""
    p = pipeline(input_type='quaternion', outputs=['matrix'], **PX4_FRAMES, **MOUNTING)
    px4 = Rotation.from_matrix(NED_FROM_ENU @ rotation.as_matrix() @ FRD_FROM_FLU)
    got = output_values(outputs_of(p, make_input_message('quaternion', px4))['matrix'])
    np.testing.assert_allclose(got.reshape(3, 3), (MOUNT_W * rotation * MOUNT_M).as_matrix(),
                               atol=1e-14)


def test_identity_mounting_is_bit_for_bit_no_mounting(rotation, rng):
    msg = make_input_message('imu', rotation, omega=rng.normal(size=3), stamp_ns=STAMP_NS)
    outputs = list(OUTPUTS)
    plain = pipeline(input_type='imu', outputs=outputs).process_values(msg)
    identity = pipeline(input_type='imu', outputs=outputs,
                        mounting_body_rotation=(0.0, 0.0, 0.0),
                        mounting_world_rotation=(0.0, 0.0, 0.0, 1.0)).process_values(msg)
    assert [(n, np.asarray(v).tobytes()) for n, _, v in plain] == \
        [(n, np.asarray(v).tobytes()) for n, _, v in identity]


# State over time ------------------------------------------------------------------

def yaw_messages(yaws, input_type='quaternion'):
    return [make_input_message(input_type, Rotation.from_euler('xyz', [0.1, -0.2, yaw]),
                               stamp_ns=STAMP_NS + k * 10_000_000)
            for k, yaw in enumerate(yaws)]


@pytest.mark.parametrize('degrees', [False, True])
def test_unwrap_keeps_yaw_continuous_through_noise_at_the_wrap(degrees, rng):
    yaws = np.pi + np.concatenate([np.linspace(-0.3, 0.0, 20), np.zeros(20)])
    yaws += rng.normal(0.0, 1e-3, yaws.size)    # noise around +-pi
    p = pipeline(input_type='quaternion', outputs=['euler'], euler_unwrap=True,
                 euler_degrees=degrees)
    out = np.array([output_values(outputs_of(p, m)['euler']) for m in yaw_messages(yaws)])
    scale = 180.0 / np.pi if degrees else 1.0
    wrapped = (yaws + np.pi) % (2 * np.pi) - np.pi
    assert np.ptp(wrapped) > 6.0    # the raw yaw does jump across the wrap
    np.testing.assert_allclose(out[:, 2], yaws * scale, rtol=1e-12)
    np.testing.assert_allclose(out[:, :2], np.tile([0.1, -0.2], (yaws.size, 1)) * scale,
                               rtol=1e-12)


def test_without_unwrap_yaw_stays_in_minus_pi_to_pi():
    p = pipeline(input_type='quaternion', outputs=['euler'])
    out = [output_values(outputs_of(p, m)['euler'])[2] for m in yaw_messages([3.0, 3.2, 3.4])]
    np.testing.assert_allclose(out, [3.0, 3.2 - 2 * np.pi, 3.4 - 2 * np.pi], rtol=1e-12)


@pytest.mark.parametrize('continuity', [False, True])
def test_quaternion_sign_continuity(continuity):
    # A yaw sweep through 180 degrees: the canonical (w >= 0) quaternion flips sign there.
    yaws = np.linspace(2.8, 3.5, 15)
    p = pipeline(input_type='quaternion', outputs=['quaternion'], quaternion_continuity=continuity)
    qs = np.array([output_values(outputs_of(p, m)['quaternion']) for m in yaw_messages(yaws)])
    steps = np.einsum('ij,ij->i', qs[1:], qs[:-1])
    if continuity:
        assert np.all(steps > 0.99)
    else:
        assert np.all(qs[:, 3] >= 0) and np.any(steps < 0)


@pytest.mark.parametrize('sequence, middle, near', [
    ('xyz', np.pi / 2 - 0.005, True), ('xyz', np.pi / 2 - 0.02, False),
    ('ZYZ', 0.005, True), ('ZYZ', np.pi - 0.005, True), ('ZYZ', 0.5, False),
])
def test_near_singular_samples_are_counted(sequence, middle, near):
    p = pipeline(input_type='quaternion', outputs=['euler'], euler_sequence=sequence)
    msg = make_input_message('quaternion', Rotation.from_euler(sequence, [0.3, middle, 0.2]))
    assert 'euler' in outputs_of(p, msg)
    assert p.stats.near_singular == int(near)


# Bad input ------------------------------------------------------------------------

@pytest.mark.parametrize('values, reason', [
    ((math.nan, 0.0, 0.0, 1.0), NON_FINITE_ORIENTATION),
    ((0.0, math.inf, 0.0, 1.0), NON_FINITE_ORIENTATION),
    ((0.0, 0.0, 0.0, -math.inf), NON_FINITE_ORIENTATION),
])
@pytest.mark.parametrize('input_type', ['quaternion', 'imu', 'odometry'])
def test_bad_quaternions_are_dropped_with_a_reason(input_type, values, reason):
    p = pipeline(input_type=input_type, outputs=list(OUTPUTS))
    msg = make_input_message(input_type, Rotation.identity(), omega=(0.1, 0.2, 0.3))
    set_orientation(msg, input_type, values)
    assert p.process(msg) == []
    assert p.stats.dropped == {reason: 1} and p.stats.published == 0
    assert [r for r, _ in p.issues] == [reason]
    assert 'dropped' in p.issues[0][1]


@pytest.mark.parametrize('input_type', ['quaternion', 'imu', 'odometry'])
def test_a_zero_quaternion_is_an_unknown_orientation_as_the_imu_flag(input_type):
    """(0, 0, 0, 0) and orientation_covariance[0] == -1 both say "not estimated"."""
    p = pipeline(input_type=input_type, outputs=list(OUTPUTS))
    msg = make_input_message(input_type, Rotation.identity(), omega=(0.1, 0.2, 0.3),
                             stamp_ns=STAMP_NS)
    set_orientation(msg, input_type, (0.0, 0.0, 0.0, 0.0))
    out = outputs_of(p, msg)
    # The measured angular velocity needs no orientation; the quaternion input has none.
    assert list(out) == ([] if input_type == 'quaternion' else ['angular_velocity'])
    if out:
        np.testing.assert_array_equal(output_values(out['angular_velocity']), [0.1, 0.2, 0.3])
    assert p.stats.dropped == {} and p.stats.skipped == {ZERO_QUATERNION: 1}
    assert [r for r, _ in p.issues] == [ZERO_QUATERNION]
    if input_type == 'imu':   # the flag: the same outputs, its own reason
        flagged = pipeline(input_type='imu', outputs=list(OUTPUTS))
        msg = make_input_message('imu', Rotation.identity(), omega=(0.1, 0.2, 0.3),
                                 stamp_ns=STAMP_NS)
        msg.orientation_covariance[0] = -1.0
        assert list(outputs_of(flagged, msg)) == list(out)
        assert flagged.stats.skipped == {ORIENTATION_UNKNOWN: 1}


@pytest.mark.parametrize('input_type', ['euler', 'rotation_vector'])
def test_non_finite_vectors_are_dropped(input_type):
    p = pipeline(input_type=input_type, outputs=['quaternion'])
    msg = make_input_message(input_type, Rotation.identity())
    msg.vector.y = math.nan
    assert p.process(msg) == []
    assert p.stats.dropped == {NON_FINITE_ORIENTATION: 1}


def test_the_stream_continues_after_a_dropped_message(rotation):
    p = pipeline(input_type='quaternion', outputs=['quaternion'])
    bad = make_input_message('quaternion', rotation)
    bad.quaternion.w = math.nan
    assert p.process(bad) == []
    assert len(p.process(make_input_message('quaternion', rotation))) == 1
    assert (p.stats.received, p.stats.published) == (2, 1)


def test_imu_without_orientation_still_converts_angular_velocity(rotation):
    p = pipeline(input_type='imu', outputs=['euler', 'angular_velocity', 'quaternion_rate'])
    msg = make_input_message('imu', rotation, omega=OMEGA_BODY)
    msg.orientation_covariance[0] = -1.0
    results = outputs_of(p, msg)
    assert list(results) == ['angular_velocity']
    np.testing.assert_allclose(output_values(results['angular_velocity']), OMEGA_BODY)
    assert p.stats.skipped == {ORIENTATION_UNKNOWN: 1} and not p.stats.dropped
    assert [r for r, _ in p.issues] == [ORIENTATION_UNKNOWN]


def test_imu_without_orientation_cannot_change_the_frame(rotation):
    p = pipeline(input_type='imu', outputs=['angular_velocity'],
                 angular_velocity_output_frame='world')
    msg = make_input_message('imu', rotation, omega=OMEGA_BODY)
    msg.orientation_covariance[0] = -1.0
    assert p.process(msg) == []
    assert p.stats.skipped == {ORIENTATION_UNKNOWN: 1}


def test_non_finite_angular_velocity_skips_only_the_rates(rotation):
    p = pipeline(input_type='imu', outputs=['euler', 'angular_velocity', 'euler_rates'])
    msg = make_input_message('imu', rotation, omega=(0.0, math.nan, 0.0))
    assert list(outputs_of(p, msg)) == ['euler']
    assert p.stats.skipped == {NON_FINITE_ANGULAR_VELOCITY: 1}


@pytest.mark.parametrize('scale', [1.01, 0.5, 1e-160, 1e160])
def test_non_unit_quaternions_are_normalised_and_reported(scale, rotation):
    p = pipeline(input_type='quaternion', outputs=['quaternion', 'euler'])
    msg = make_input_message('quaternion', rotation)
    set_orientation(msg, 'quaternion', scale * rotation.as_quat(canonical=True))
    results = outputs_of(p, msg)
    np.testing.assert_allclose(output_values(results['quaternion']),
                               rotation.as_quat(canonical=True), atol=1e-15)
    np.testing.assert_allclose(output_values(results['euler']), rotation.as_euler('xyz'),
                               atol=1e-12)
    assert p.stats.normalised == 1 and not p.stats.dropped
    assert [r for r, _ in p.issues] == [NON_UNIT_QUATERNION]


def test_norm_tolerance_sets_where_reporting_starts(rotation):
    p = pipeline(input_type='quaternion', outputs=['quaternion'], quaternion_norm_tolerance=0.1)
    msg = make_input_message('quaternion', rotation)
    msg.quaternion.w *= 1.05
    p.process(msg)
    assert p.stats.normalised == 0


@pytest.mark.parametrize('step_ns', [0, -1, -5_000_000])
def test_a_stamp_not_after_the_previous_skips_the_finite_difference(step_ns, rotation):
    p = pipeline(input_type='quaternion', outputs=['euler', 'angular_velocity'])
    first, second = constant_rate_messages('quaternion', rotation, dt_ns=1_000_000)
    later = make_input_message('quaternion', rotation, stamp_ns=STAMP_NS + 2_000_000)
    second.header.stamp.sec, second.header.stamp.nanosec = divmod(STAMP_NS + step_ns, 10**9)
    p.process(first)
    assert list(outputs_of(p, second)) == ['euler']   # orientation outputs still published
    assert p.stats.skipped == {TIMESTAMP_NOT_INCREASING: 1}
    assert [r for r, _ in p.issues] == [TIMESTAMP_NOT_INCREASING]
    # The stream restarts from the out-of-order sample instead of stalling.
    assert list(outputs_of(p, later)) == ['euler', 'angular_velocity']


FIELD = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                  st.sampled_from([0.0, -0.0, 1e-310, 1e308, math.nan, math.inf]))
# Angular velocities up to 1e300 rad/s: beyond that, Euler rates (|w| / cos(pitch))
# legitimately exceed the float64 range. Quaternions are scale-invariant: any size.
RATE = st.one_of(st.floats(-1e300, 1e300),
                 st.sampled_from([0.0, -0.0, 1e-310, 1e300, math.nan, math.inf, -math.inf]))


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(FIELD, FIELD, FIELD, FIELD), min_size=1, max_size=4),
       st.tuples(RATE, RATE, RATE), st.booleans())
@pytest.mark.parametrize('input_type', ['imu', 'quaternion'])
def test_process_never_raises_and_accounts_for_every_message(input_type, quaternions, omega,
                                                             continuity):
    p = ConversionPipeline(NodeParameters(
        input_type=input_type, outputs=list(OUTPUTS), euler_unwrap=True,
        quaternion_continuity=continuity))
    for k, values in enumerate(quaternions):
        msg = make_input_message(input_type, Rotation.identity(), omega=omega, stamp_ns=k)
        set_orientation(msg, input_type, values)
        for _, out in p.process(msg):
            assert np.all(np.isfinite(output_values(out)))
    finite = sum(1 for values in quaternions if all(map(math.isfinite, values)))
    zero = sum(1 for values in quaternions if not any(values))
    assert p.stats.received == len(quaternions)
    assert sum(p.stats.dropped.values()) == len(quaternions) - finite
    assert p.stats.skipped[ZERO_QUATERNION] == zero   # orientation not estimated


def test_a_message_the_caller_could_not_read_is_counted_and_reported_as_dropped():
    p = pipeline(input_type='imu')
    p.drop_message(CONVERSION_ERROR, error=ValueError('truncated CDR'))
    assert (p.stats.received, p.stats.dropped[CONVERSION_ERROR], p.stats.published) == (1, 1, 0)
    assert p.issues == [(CONVERSION_ERROR, 'message dropped: truncated CDR')]


# The block form (process_block): its own contract. Its exactness against the per-message
# form is checked end to end in test_bag_block_convert.py.
def _block(n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    stamps = 1_000_000_000 + 10_000_000 * np.arange(n, dtype=np.int64)
    return SampleBlock(stamps, q, np.ones(n, dtype=bool), rng.normal(size=(n, 3)),
                       np.ones(n, dtype=bool))


def test_blocks_stay_below_the_batch_schedules():
    assert BLOCK_SAMPLES < BATCH_SAMPLES
    p = ConversionPipeline(NodeParameters(input_type='imu'))
    with pytest.raises(ValueError, match='block'):
        p.process_block(_block(BLOCK_SAMPLES + 1))


def test_the_outputs_with_a_block_form():
    assert {name for name in registry.OUTPUTS if output_has_block_form(name)} == {
        'quaternion', 'euler', 'rotation_vector', 'axis_angle', 'matrix', 'angular_velocity',
        'euler_rates', 'quaternion_rate'}


def _values_of(need, n, rng):
    """Arrays of ``n`` samples of a pipeline value: random, then the identity and a half turn."""
    if need == registry.ANGULAR_VELOCITY:
        return rng.normal(size=(n, 3))
    q = rng.normal(size=(n, 4))
    q[-2:] = [[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0]]
    if need == registry.OUTPUT_QUATERNION:   # unit, w >= 0
        q = conversions.canonical_quaternion(q)
    return q


@pytest.mark.parametrize('name', [name for name in sorted(registry.OUTPUTS)
                                  if registry.OUTPUTS[name].compute_takes_blocks])
def test_each_block_output_computes_a_block_as_each_sample_alone(name):
    output = registry.OUTPUTS[name]
    params = NodeParameters(input_type='imu', outputs=(name,))
    rng = np.random.default_rng(7)
    values = [_values_of(need, 40, rng) for need in output.needs]
    block = np.asarray(output.compute(params, *values), dtype=np.float64)
    assert block.shape[0] == 40 and block.ndim == 2
    for s in range(40):
        alone = np.asarray(output.compute(params, *(value[s] for value in values)),
                           dtype=np.float64)
        assert alone.shape == block[s].shape and alone.tobytes() == block[s].tobytes(), (
            s, alone, block[s])


@pytest.mark.parametrize('values, reason', [
    ({'outputs': ('euler_stddev',)}, 'output euler_stddev'),
    ({'frames_input_body': 'frd'}, 'frame conversion'),
])
def test_block_form_missing_names_what_has_no_block_form(values, reason):
    params = NodeParameters(input_type='pose_with_covariance', **values)
    assert reason in block_form_missing(params)
    with pytest.raises(ValueError, match='no block form'):
        ConversionPipeline(params).process_block(_block(2))


def test_an_output_added_without_a_block_form_is_left_to_the_pipeline(monkeypatch):
    # A compute not declared to take blocks (compute_takes_blocks defaults to False).
    added = dataclasses.replace(registry.OUTPUTS['euler'], name='euler_again',
                                compute=lambda params, angles: angles)
    monkeypatch.setitem(registry.OUTPUTS, 'euler_again', added)
    # As the parameters will be once the output is in their choices.
    params = types.SimpleNamespace(**dataclasses.asdict(NodeParameters(input_type='imu')))
    params.outputs = ('euler', 'euler_again')
    assert block_form_missing(params) == 'output euler_again has no block form'


def test_a_block_a_conversion_rejects_changes_nothing(monkeypatch):
    params = NodeParameters(input_type='imu', outputs=('euler', 'angular_velocity'),
                            angular_velocity_input_frame='world')
    p = ConversionPipeline(params)
    assert p.process_block(_block(10)) is not None
    state = (p.state.previous_euler, p.stats.received)

    def rejects(*args, **kwargs):
        raise ValueError('q: rejected')

    monkeypatch.setattr(conversions, 'rotate_vector', rejects)
    assert p.process_block(_block(10, seed=1)) is None
    assert (p.state.previous_euler, p.stats.received) == state


def _interpreted_and_compiled(chain, flat, *previous):
    """Return what a chain kernel makes of ``flat``: run interpreted, and compiled."""
    chain.load()
    interpreted, compiled = flat.copy(), flat.copy()
    chain.interpreted(interpreted, *previous)
    chain.dispatcher(compiled, *previous)
    return interpreted, compiled


_ANGLES = st.one_of(st.floats(-10.0, 10.0), st.sampled_from(
    [0.0, -0.0, math.pi, -math.pi, 3 * math.pi, 180.0, -180.0, 540.0, 90.0, -270.0]))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(_ANGLES, _ANGLES), max_size=30), st.sampled_from([2.0 * math.pi, 360.0]),
       st.tuples(st.sampled_from([0.0, -0.0, 1.0, 180.0]), st.sampled_from([0.0, -180.0])))
def test_the_block_forms_unwrap_chain_is_the_unwrapping_of_each_sample(angles, period, start):
    """Half a period from the previous (e.g. 180 after 0 in degrees) rounds half to even."""
    published, (first, third) = [], start
    for angle_first, angle_third in angles:
        first = _unwrapped(angle_first, first, period)
        third = _unwrapped(angle_third, third, period)
        published.append((first, 0.25, third))
    triples = np.array([(a, 0.25, b) for a, b in angles]).reshape(-1)
    for got in _interpreted_and_compiled(_unwrap_chain, triples, *start, period):
        assert got.tobytes() == np.array(published).reshape(-1).tobytes()


def test_an_unwrapping_tie_rounds_half_to_even_in_both_forms():
    # (0 - 180) / 360 = -0.5 rounds to -0: 180 stays; (0 - 540) / 360 = -1.5 rounds to -2.
    for got in _interpreted_and_compiled(_unwrap_chain, np.array([180.0, 0.0, 540.0]),
                                         0.0, 0.0, 360.0):
        assert got.tolist() == [180.0, 0.0, -180.0]
    assert (_unwrapped(180.0, 0.0, 360.0), _unwrapped(540.0, 0.0, 360.0)) == (180.0, -180.0)


# Quaternions some of them a quarter turn apart: dot products exactly 0 and -0 between them.
_QUARTER_TURNS = [(0.0, 0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, -0.0, -1.0),
                  (0.5, 0.5, 0.5, 0.5), (-0.5, 0.5, -0.5, 0.5), (0.0, -0.0, 1.0, 0.0),
                  (-0.0, -0.0, 0.0, 1.0), (0.6, 0.8, 0.0, 0.0), (0.8, -0.6, 0.0, 0.0)]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(_QUARTER_TURNS), max_size=30),
       st.sampled_from([(0.0,) * 4, (0.0, 0.0, 0.0, 1.0), (0.0, -0.0, 1.0, 0.0)]))
def test_the_block_forms_sign_chain_negates_as_each_sample_alone(quaternions, previous):
    """A quaternion is negated when its dot product with the previous output is below 0."""
    published, last = [], previous
    for q in quaternions:
        if _turns_away(*last, *q):
            q = tuple(-c for c in q)
        published.append(q)
        last = q
    flat = np.array(quaternions, dtype=float).reshape(-1)
    for got in _interpreted_and_compiled(_sign_chain, flat, *previous):
        assert got.tobytes() == np.array(published, dtype=float).reshape(-1).tobytes()


def test_a_dot_product_of_zero_negates_nothing():
    assert not _turns_away(0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0)   # 0
    assert not _turns_away(0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, -0.0)   # -0
    assert _turns_away(0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, -1e-300)


def test_each_stateful_rule_is_the_one_both_forms_call(monkeypatch):
    """Another rule changes the per-message and the block form alike: neither has its own."""
    for chain in (_sign_chain, _unwrap_chain):
        monkeypatch.setattr(chain, 'call', chain.interpreted)   # calls the rule as Python
    monkeypatch.setattr(pipeline_module, '_turns_away', lambda *values: True)
    monkeypatch.setattr(pipeline_module, '_unwrapped', lambda angle, previous, period: previous)
    quaternions = Rotation.random(6, random_state=3).as_quat().tolist()
    outputs = ('quaternion', 'euler')
    alone, blocks = _both_forms(quaternions, {
        'input_type': 'quaternion', 'outputs': outputs, 'quaternion_continuity': True,
        'euler_unwrap': True})
    for name in outputs:
        assert blocks[name].tobytes() == alone[name].tobytes(), name
    assert (alone['quaternion'].reshape(-1, 4)[:, 3] < 0.0).all()   # each canonical negated
    euler = alone['euler'].reshape(-1, 3)
    assert (euler[:, [0, 2]] == euler[0, [0, 2]]).all()   # each the previous


def _quaternion_stream(quaternions):
    """Messages of ``quaternions`` and the same samples as a block."""
    stamps = STAMP_NS + 10_000_000 * np.arange(len(quaternions), dtype=np.int64)
    messages = []
    for stamp, q in zip(stamps.tolist(), quaternions):
        msg = make_input_message('quaternion', Rotation.identity(), stamp_ns=stamp)
        set_orientation(msg, 'quaternion', q)
        messages.append(msg)
    return messages, SampleBlock(stamps, np.array(quaternions, dtype=float),
                                 np.ones(len(quaternions), dtype=bool))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.one_of(st.sampled_from(_QUARTER_TURNS), st.tuples(
    *[st.floats(-1.0, 1.0)] * 3, st.floats(0.1, 1.0))), min_size=1, max_size=20),
    st.sampled_from([False, True]))
def test_sign_continuity_and_unwrapping_agree_per_message_and_in_blocks(quaternions, degrees):
    """The stateful rules on quarter turns (ties of sign) and turns near the wrap of the angles."""
    params = {'input_type': 'quaternion', 'outputs': ('quaternion', 'euler', 'angular_velocity'),
              'quaternion_continuity': True, 'euler_unwrap': True, 'euler_degrees': degrees}
    alone, blocks = _both_forms(quaternions, params)
    for name in params['outputs']:
        assert blocks[name].tobytes() == alone[name].tobytes(), name
    assert alone['stats'] == blocks['stats']


def _both_forms(quaternions, params):
    """Return each output's numbers (flat) and the stats: message by message, and in 2 blocks."""
    messages, block = _quaternion_stream(quaternions)
    one = ConversionPipeline(NodeParameters(**params))
    results = [one.process_values(msg) for msg in messages]
    alone = {name: np.array([numbers for sample in results for output, _, numbers in sample
                             if output == name], dtype=float).reshape(-1)
             for name in params['outputs']}
    blocks = ConversionPipeline(NodeParameters(**params))
    half = len(quaternions) // 2   # two blocks: the second continues the first's state
    outputs = [blocks.process_block(SampleBlock(*(a[:half] for a in block[:3]))),
               blocks.process_block(SampleBlock(*(a[half:] for a in block[:3])))]
    in_blocks = {name: np.concatenate([o.numbers[name].reshape(-1) for o in outputs])
                 for name in params['outputs']}
    return {**alone, 'stats': one.stats}, {**in_blocks, 'stats': blocks.stats}
