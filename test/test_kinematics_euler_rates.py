"""Tests of rotation_node.kinematics._euler_rates: Euler rates <-> angular velocity."""
import warnings

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from rotation_node import conversions as rc
from rotation_node import kinematics as rk

EPS = np.finfo(float).eps
FRAMES = ('body', 'world')
CONVENTIONS = [(seq, frame) for seq in rc.SEQUENCES for frame in FRAMES]
FD_STEP = 1e-5
MARGIN = 0.2  # rad from gimbal lock: "away from the singularity" for the accuracy targets


def singular_middle_angles(seq):
    return (0.0, np.pi) if rc.parse_sequence(seq).proper else (-np.pi / 2, np.pi / 2)


def random_angles(rng, seq, n, margin=MARGIN):
    """Angles with the middle one at least ``margin`` from its singular values."""
    angles = rng.uniform(-np.pi, np.pi, size=(n, 3))
    low, high = singular_middle_angles(seq)
    angles[:, 1] = rng.uniform(low + margin, high - margin, size=n)
    return angles


def vee(skew):
    return 0.5 * np.stack([skew[..., 2, 1] - skew[..., 1, 2], skew[..., 0, 2] - skew[..., 2, 0],
                           skew[..., 1, 0] - skew[..., 0, 1]], axis=-1)


def finite_difference_angular_velocity(angles, rates, seq, frame):
    """``vee(R^T Rdot)`` or ``vee(Rdot R^T)``, ``Rdot`` by central differences of conversions."""
    R = rc.matrix_from_euler(angles, seq)
    R_dot = (rc.matrix_from_euler(angles + FD_STEP * rates, seq)
             - rc.matrix_from_euler(angles - FD_STEP * rates, seq)) / (2 * FD_STEP)
    R_t = np.swapaxes(R, -1, -2)
    return vee(R_t @ R_dot if frame == 'body' else R_dot @ R_t)


def relative_error(actual, expected):
    return np.linalg.norm(actual - expected, axis=-1) / np.linalg.norm(expected, axis=-1)


@pytest.mark.parametrize('seq, frame', CONVENTIONS)
def test_angular_velocity_matches_central_difference(rng, seq, frame):
    angles = random_angles(rng, seq, 100)
    rates = rng.normal(size=(100, 3))
    omega = rk.angular_velocity_from_euler_rates(angles, rates, seq, frame)
    expected = finite_difference_angular_velocity(angles, rates, seq, frame)
    assert relative_error(omega, expected).max() < 1e-8


@pytest.mark.parametrize('seq, frame', CONVENTIONS)
def test_euler_rates_match_central_difference(rng, seq, frame):
    """The rates returned turn the angles at ``omega``: check by differentiating the conversion."""
    angles = random_angles(rng, seq, 100)
    omega = rng.normal(size=(100, 3))
    rates = rk.euler_rates_from_angular_velocity(angles, omega, seq, frame)
    expected = finite_difference_angular_velocity(angles, rates, seq, frame)
    assert relative_error(expected, omega).max() < 1e-8


@pytest.mark.parametrize('seq, frame', CONVENTIONS)
def test_round_trips_within_8_eps(rng, seq, frame):
    angles = random_angles(rng, seq, 2000)
    rates = rng.normal(size=(2000, 3))
    omega = rng.normal(size=(2000, 3))
    rates_back = rk.euler_rates_from_angular_velocity(
        angles, rk.angular_velocity_from_euler_rates(angles, rates, seq, frame), seq, frame)
    omega_back = rk.angular_velocity_from_euler_rates(
        angles, rk.euler_rates_from_angular_velocity(angles, omega, seq, frame), seq, frame)
    assert relative_error(rates_back, rates).max() <= 8 * EPS
    assert relative_error(omega_back, omega).max() <= 8 * EPS


@pytest.mark.parametrize('seq', rc.SEQUENCES)
def test_world_frame_is_the_rotated_body_frame(rng, seq):
    angles = random_angles(rng, seq, 50)
    rates = rng.normal(size=(50, 3))
    body = rk.angular_velocity_from_euler_rates(angles, rates, seq, 'body')
    world = rk.angular_velocity_from_euler_rates(angles, rates, seq, 'world')
    q = rc.quaternion_from_euler(angles, seq)
    np.testing.assert_allclose(world, rc.rotate_vector(q, body), rtol=0, atol=1e-14)


@pytest.mark.parametrize('frame', FRAMES)
@pytest.mark.parametrize('seq', [s for s in rc.SEQUENCES if s.islower()])
def test_extrinsic_is_reversed_intrinsic(rng, seq, frame):
    """'ijk' with (a1, a2, a3) is 'KJI' with (a3, a2, a1): same angular velocity."""
    angles = random_angles(rng, seq, 50)
    rates = rng.normal(size=(50, 3))
    reversed_seq = seq[::-1].upper()
    np.testing.assert_allclose(
        rk.angular_velocity_from_euler_rates(angles, rates, seq, frame),
        rk.angular_velocity_from_euler_rates(angles[:, ::-1], rates[:, ::-1], reversed_seq, frame),
        rtol=0, atol=1e-15)


def test_zyx_closed_form_from_numerics(rng):
    """docs/numerics.md: intrinsic ZYX (yaw, pitch, roll) and ROS 'xyz' (roll, pitch, yaw)."""
    psi, theta, phi = random_angles(rng, 'ZYX', 100).T
    d_psi, d_theta, d_phi = rng.normal(size=(3, 100))
    expected = np.stack([d_phi - d_psi * np.sin(theta),
                         d_theta * np.cos(phi) + d_psi * np.sin(phi) * np.cos(theta),
                         -d_theta * np.sin(phi) + d_psi * np.cos(phi) * np.cos(theta)], axis=-1)
    zyx = rk.angular_velocity_from_euler_rates(np.stack([psi, theta, phi], -1),
                                               np.stack([d_psi, d_theta, d_phi], -1), 'ZYX')
    rpy = rk.angular_velocity_from_euler_rates(np.stack([phi, theta, psi], -1),
                                               np.stack([d_phi, d_theta, d_psi], -1), 'xyz')
    np.testing.assert_allclose(zyx, expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rpy, expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize('frame', FRAMES)
@pytest.mark.parametrize('seq', ['xyz', 'ZXZ'])
def test_degrees(rng, seq, frame):
    """``degrees=True``: angles in deg and rates in deg/s; omega stays rad/s."""
    angles = random_angles(rng, seq, 20)
    omega = rng.normal(size=(20, 3))
    rates = rk.euler_rates_from_angular_velocity(angles, omega, seq, frame)
    rates_deg = rk.euler_rates_from_angular_velocity(np.rad2deg(angles), omega, seq, frame,
                                                     degrees=True)
    assert relative_error(rates_deg, np.rad2deg(rates)).max() < 8 * EPS
    np.testing.assert_allclose(rk.angular_velocity_from_euler_rates(
        np.rad2deg(angles), rates_deg, seq, frame, degrees=True), omega, rtol=0, atol=1e-14)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(seq=st.sampled_from(rc.SEQUENCES), frame=st.sampled_from(FRAMES),
       first=st.floats(-10, 10), middle=st.floats(MARGIN, np.pi / 2 - MARGIN),
       third=st.floats(-10, 10), omega=st.tuples(*3 * [st.floats(-1e3, 1e3)]))
def test_rates_reproduce_omega(seq, frame, first, middle, third, omega):
    """Any angles (not only the principal range) away from gimbal lock, any omega."""
    proper = rc.parse_sequence(seq).proper
    angles = np.array([first, middle + (np.pi / 2 if proper else 0.0), third])
    omega = np.array(omega)
    rates = rk.euler_rates_from_angular_velocity(angles, omega, seq, frame)
    back = rk.angular_velocity_from_euler_rates(angles, rates, seq, frame)
    np.testing.assert_allclose(back, omega, rtol=0, atol=16 * EPS * max(1.0, np.abs(omega).max()))


# ------------------------------------------------------------------ singularity

@pytest.mark.parametrize('frame', FRAMES)
@pytest.mark.parametrize('seq', rc.SEQUENCES)
def test_gimbal_lock_gives_nan_and_a_warning(rng, seq, frame):
    angles = random_angles(rng, seq, 6)
    angles[1:3, 1] = singular_middle_angles(seq)
    omega = rng.normal(size=(6, 3))
    with pytest.warns(rk.EulerSingularityWarning, match='2 of 6 samples'):
        rates = rk.euler_rates_from_angular_velocity(angles, omega, seq, frame)
    singular = np.isnan(rates[:, 0])
    np.testing.assert_array_equal(singular, [False, True, True, False, False, False])
    assert np.isnan(rates[singular]).all()
    np.testing.assert_allclose(rk.angular_velocity_from_euler_rates(
        angles[~singular], rates[~singular], seq, frame), omega[~singular], atol=1e-14)


@pytest.mark.parametrize('seq', ['xyz', 'ZYX', 'zxz', 'YZY'])
def test_threshold_is_the_distance_to_gimbal_lock(rng, seq):
    """Margins just above the threshold give finite (large) correct rates, just below NaN."""
    singular = singular_middle_angles(seq)[1]
    angles = random_angles(rng, seq, 4)
    angles[:, 1] = singular - np.array([2e-6, 1.01e-6, 0.99e-6, 0.0])
    omega = rng.normal(size=(4, 3))
    with pytest.warns(rk.EulerSingularityWarning, match='2 of 4 samples are within 1e-06 rad'):
        rates = rk.euler_rates_from_angular_velocity(angles, omega, seq,
                                                     singularity_threshold=1e-6)
    np.testing.assert_array_equal(np.isnan(rates[:, 0]), [False, False, True, True])
    assert np.abs(rates[:2]).max() > 1e4
    np.testing.assert_allclose(rk.angular_velocity_from_euler_rates(angles[:2], rates[:2], seq),
                               omega[:2], rtol=0, atol=1e-9)


def test_default_threshold_and_no_warning_when_regular(rng):
    angles = random_angles(rng, 'xyz', 3)
    angles[:, 1] = np.pi / 2 - np.array([1e-3, 1e-7, 1e-9])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        regular = rk.euler_rates_from_angular_velocity(angles[:2], np.ones((2, 3)), 'xyz')
        rk.angular_velocity_from_euler_rates(angles, np.ones((3, 3)), 'xyz')  # never singular
    assert np.isfinite(regular).all()
    assert rk.DEFAULT_SINGULARITY_THRESHOLD == pytest.approx(np.sqrt(EPS), rel=0.01)
    with pytest.warns(rk.EulerSingularityWarning):
        assert np.isnan(rk.euler_rates_from_angular_velocity(angles[2], np.ones(3), 'xyz')).all()


def test_warning_is_a_runtime_warning():
    assert issubclass(rk.EulerSingularityWarning, RuntimeWarning)


# ------------------------------------------------------------------ bad input

@pytest.mark.parametrize('seq', ['xxz', 'xyZ', 'abc', 'xy', 'xyzx', 3, None])
@pytest.mark.parametrize('function', [rk.angular_velocity_from_euler_rates,
                                      rk.euler_rates_from_angular_velocity])
def test_bad_sequence(function, seq):
    with pytest.raises(ValueError, match='`seq`'):
        function([0.1, 0.2, 0.3], [1.0, 2.0, 3.0], seq)


@pytest.mark.parametrize('call, message', [
    (lambda: rk.angular_velocity_from_euler_rates([0, 0, 0], [1, 2, 3], 'xyz', 'fixed'),
     '`frame`'),
    (lambda: rk.euler_rates_from_angular_velocity([0, 0, 0], [1, 2, 3], 'xyz', 'Body'), '`frame`'),
    (lambda: rk.angular_velocity_from_euler_rates([0, 0], [1, 2, 3], 'xyz'),
     r'`angles` to have shape \(\.\.\., 3\), got \(2,\)'),
    (lambda: rk.angular_velocity_from_euler_rates([0, 0, 0], [[1, 2, 3, 4]], 'xyz'), '`rates`'),
    (lambda: rk.euler_rates_from_angular_velocity([0, 0, 0], np.ones((2, 2)), 'xyz'), '`omega`'),
    (lambda: rk.euler_rates_from_angular_velocity([[0, 0, 0], [0, np.nan, 0]], [1, 2, 3], 'xyz'),
     r'`angles` at index \(1,\) has a NaN'),
    (lambda: rk.euler_rates_from_angular_velocity([0, 0, 0], [1, -np.inf, 3], 'xyz'),
     '`omega` has a NaN or Inf'),
    (lambda: rk.angular_velocity_from_euler_rates([0, 0, 0], [np.nan, 2, 3], 'xyz'),
     '`rates` has a NaN or Inf'),
    (lambda: rk.euler_rates_from_angular_velocity(np.zeros((2, 3)), np.ones((3, 3)), 'xyz'),
     'do not broadcast'),
    (lambda: rk.euler_rates_from_angular_velocity([0, 0, 0], [1, 2, 3], 'xyz',
                                                  singularity_threshold=-1e-9),
     '`singularity_threshold`'),
    (lambda: rk.euler_rates_from_angular_velocity([0, 0, 0], [1, 2, 3], 'xyz',
                                                  singularity_threshold=2.0),
     '`singularity_threshold`'),
    (lambda: rk.euler_rates_from_angular_velocity([0, 0, 0], [1, 2, 3], 'xyz',
                                                  singularity_threshold=np.nan),
     '`singularity_threshold`'),
    (lambda: rk.euler_rates_from_angular_velocity([0, 0, 0], [1, 2, 3], 'xyz',
                                                  singularity_threshold='small'),
     '`singularity_threshold`'),
])
def test_bad_input_raises_naming_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_inputs_are_not_modified_and_shapes_broadcast(rng):
    angles = random_angles(rng, 'ZYX', 4).reshape(4, 1, 3)
    omega = rng.normal(size=(2, 3))
    copies = angles.copy(), omega.copy()
    rates = rk.euler_rates_from_angular_velocity(angles, omega, 'ZYX', 'world', True)
    assert rates.shape == (4, 2, 3)
    assert rk.angular_velocity_from_euler_rates(angles, omega, 'ZYX').shape == (4, 2, 3)
    assert rk.angular_velocity_from_euler_rates(angles[0, 0], omega[0], 'ZYX').shape == (3,)
    np.testing.assert_array_equal(angles, copies[0])
    np.testing.assert_array_equal(omega, copies[1])
