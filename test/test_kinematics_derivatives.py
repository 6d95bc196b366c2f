"""Tests of rotation_node.kinematics._derivatives: quaternion and matrix derivatives."""
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
import numpy as np
import pytest
from rotation_node import conversions as rc
from rotation_node import kinematics as rk

EPS = np.finfo(float).eps
FRAMES = ('body', 'world')
FD_STEP = 1e-5  # central differences: truncation ~h^2 |w|^3 / 6, rounding ~eps / h


def random_quaternions(rng, n):
    return rc.canonical_quaternion(rng.normal(size=(n, 4)))


def rotated(q, omega, tau, frame):
    """Orientation after turning for ``tau`` at the constant angular velocity ``omega``."""
    step = rc.quaternion_from_rotation_vector(omega * tau)
    return rc.quaternion_product(q, step) if frame == 'body' else rc.quaternion_product(step, q)


def vee(skew):
    return 0.5 * np.stack([skew[..., 2, 1] - skew[..., 1, 2], skew[..., 0, 2] - skew[..., 2, 0],
                           skew[..., 1, 0] - skew[..., 0, 1]], axis=-1)


def relative_error(actual, expected):
    scale = np.linalg.norm(expected.reshape(len(expected), -1), axis=-1)
    return np.linalg.norm((actual - expected).reshape(len(expected), -1), axis=-1) / scale


@pytest.mark.parametrize('frame', FRAMES)
def test_quaternion_derivative_matches_central_difference(rng, frame):
    q = random_quaternions(rng, 200)
    omega = rng.normal(size=(200, 3))
    fd = (rotated(q, omega, FD_STEP, frame) - rotated(q, omega, -FD_STEP, frame)) / (2 * FD_STEP)
    assert relative_error(rk.quaternion_derivative(q, omega, frame), fd).max() < 1e-8


@pytest.mark.parametrize('frame', FRAMES)
def test_matrix_derivative_matches_central_difference(rng, frame):
    q = random_quaternions(rng, 200)
    omega = rng.normal(size=(200, 3))
    fd = (rc.matrix_from_quaternion(rotated(q, omega, FD_STEP, frame))
          - rc.matrix_from_quaternion(rotated(q, omega, -FD_STEP, frame))) / (2 * FD_STEP)
    R = rc.matrix_from_quaternion(q)
    assert relative_error(rk.matrix_derivative(R, omega, frame), fd).max() < 1e-8


@pytest.mark.parametrize('frame', FRAMES)
def test_angular_velocity_from_central_differences(rng, frame):
    q = random_quaternions(rng, 200)
    omega = rng.normal(size=(200, 3))
    q_dot = (rotated(q, omega, FD_STEP, frame)
             - rotated(q, omega, -FD_STEP, frame)) / (2 * FD_STEP)
    R_dot = (rc.matrix_from_quaternion(rotated(q, omega, FD_STEP, frame))
             - rc.matrix_from_quaternion(rotated(q, omega, -FD_STEP, frame))) / (2 * FD_STEP)
    from_q = rk.angular_velocity_from_quaternion_derivative(q, q_dot, frame)
    from_R = rk.angular_velocity_from_matrix_derivative(rc.matrix_from_quaternion(q), R_dot, frame)
    assert relative_error(from_q, omega).max() < 1e-8
    assert relative_error(from_R, omega).max() < 1e-8


def test_textbook_quaternion_formula_is_the_world_frame_one(rng):
    """The textbook dq_v/dt = 1/2 (q_s w - q_v x w) is labelled body but is the world formula."""
    q = random_quaternions(rng, 100)
    omega = rng.normal(size=(100, 3))
    qv, qs = q[:, :3], q[:, 3:]
    seed = 0.5 * (qs * omega - np.cross(qv, omega))
    body = 0.5 * (qs * omega + np.cross(qv, omega))
    scalar = -0.5 * np.sum(qv * omega, axis=-1)
    world_dot = rk.quaternion_derivative(q, omega, 'world')
    body_dot = rk.quaternion_derivative(q, omega, 'body')
    np.testing.assert_allclose(world_dot[:, :3], seed, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(body_dot[:, :3], body, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(world_dot[:, 3], scalar, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(body_dot[:, 3], scalar, rtol=0, atol=4 * EPS)
    assert np.abs(body_dot[:, :3] - seed).max() > 0.1


def test_textbook_omega_matrix_is_the_world_angular_velocity(rng):
    """The textbook Omega = dR/dt R^T is [w_w]x; R^T dR/dt is [w_b]x."""
    R = rc.matrix_from_quaternion(random_quaternions(rng, 50))
    R_dot = rng.normal(size=(50, 3, 3))
    np.testing.assert_allclose(rk.angular_velocity_from_matrix_derivative(R, R_dot, 'world'),
                               vee(R_dot @ np.swapaxes(R, -1, -2)), rtol=0, atol=1e-14)
    np.testing.assert_allclose(rk.angular_velocity_from_matrix_derivative(R, R_dot, 'body'),
                               vee(np.swapaxes(R, -1, -2) @ R_dot), rtol=0, atol=1e-14)


@pytest.mark.parametrize('frame', FRAMES)
def test_frames_are_related_by_the_rotation(rng, frame):
    q = random_quaternions(rng, 100)
    omega_body = rng.normal(size=(100, 3))
    omega_world = rc.rotate_vector(q, omega_body)
    R = rc.matrix_from_quaternion(q)
    np.testing.assert_allclose(rk.quaternion_derivative(q, omega_body, 'body'),
                               rk.quaternion_derivative(q, omega_world, 'world'), atol=1e-14)
    np.testing.assert_allclose(rk.matrix_derivative(R, omega_body, 'body'),
                               rk.matrix_derivative(R, omega_world, 'world'), atol=1e-14)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(q=arrays(np.float64, 4, elements=st.floats(-1, 1)).filter(lambda q: np.abs(q).max() > 1e-3),
       omega=arrays(np.float64, 3, elements=st.floats(-1e3, 1e3)),
       frame=st.sampled_from(FRAMES))
def test_quaternion_round_trip(q, omega, frame):
    q_dot = rk.quaternion_derivative(q, omega, frame)
    back = rk.angular_velocity_from_quaternion_derivative(q, q_dot, frame)
    np.testing.assert_allclose(back, omega, rtol=0, atol=8 * EPS * max(1.0, np.abs(omega).max()))
    assert abs(np.dot(q_dot, q)) <= 8 * EPS * np.linalg.norm(q) * max(1.0, np.abs(omega).max())


@pytest.mark.parametrize('frame', FRAMES)
def test_matrix_round_trip(rng, frame):
    R = rc.matrix_from_quaternion(random_quaternions(rng, 500))
    omega = rng.normal(size=(500, 3))
    R_dot = rk.matrix_derivative(R, omega, frame)
    back = rk.angular_velocity_from_matrix_derivative(R, R_dot, frame)
    assert relative_error(back, omega).max() < 8 * EPS


@pytest.mark.parametrize('frame', FRAMES)
def test_inverses_ignore_what_a_rotation_cannot_do(rng, frame):
    """Radial q_dot (norm change) and symmetric R^T R_dot are projected out."""
    q = random_quaternions(rng, 50)
    omega = rng.normal(size=(50, 3))
    q_dot = rk.quaternion_derivative(q, omega, frame) + 0.3 * q
    np.testing.assert_allclose(rk.angular_velocity_from_quaternion_derivative(q, q_dot, frame),
                               omega, atol=1e-14)
    R = rc.matrix_from_quaternion(q)
    symmetric = rng.normal(size=(50, 3, 3))
    symmetric = symmetric + np.swapaxes(symmetric, -1, -2)
    stretch = R @ symmetric if frame == 'body' else symmetric @ R
    R_dot = rk.matrix_derivative(R, omega, frame) + stretch
    np.testing.assert_allclose(rk.angular_velocity_from_matrix_derivative(R, R_dot, frame),
                               omega, atol=1e-13)


@pytest.mark.parametrize('scale', [1e-160, 1e160, -1.0, 1 + 1e-6])
def test_quaternion_scale_and_sign(rng, scale):
    """Any non-zero norm: q is normalised first, its sign kept (-q gives -q_dot)."""
    q = random_quaternions(rng, 20)
    omega = rng.normal(size=(20, 3))
    q_dot = rk.quaternion_derivative(q, omega)
    np.testing.assert_allclose(rk.quaternion_derivative(scale * q, omega), np.sign(scale) * q_dot,
                               rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(
        rk.angular_velocity_from_quaternion_derivative(scale * q, np.sign(scale) * q_dot),
        omega, rtol=0, atol=1e-14)


def test_broadcasting_and_shapes(rng):
    q = random_quaternions(rng, 5).reshape(5, 1, 4)
    omega = rng.normal(size=(3, 3))
    q_dot = rk.quaternion_derivative(q, omega)
    assert q_dot.shape == (5, 3, 4)
    np.testing.assert_array_equal(q_dot[2, 1], rk.quaternion_derivative(q[2, 0], omega[1]))
    assert rk.quaternion_derivative(q[0, 0], omega[0]).shape == (4,)
    R = rc.matrix_from_quaternion(q)
    assert rk.matrix_derivative(R, omega).shape == (5, 3, 3, 3)
    R_dot = rk.matrix_derivative(R[:, 0], omega[0])
    assert rk.angular_velocity_from_matrix_derivative(R[:, 0], R_dot).shape == (5, 3)


def test_inputs_are_not_modified(rng):
    q = random_quaternions(rng, 4) * 3.0
    omega = rng.normal(size=(4, 3))
    R = rc.matrix_from_quaternion(q)
    copies = [a.copy() for a in (q, omega, R)]
    rk.quaternion_derivative(q, omega, 'world')
    rk.angular_velocity_from_quaternion_derivative(q, q, 'body')
    rk.matrix_derivative(R, omega)
    rk.angular_velocity_from_matrix_derivative(R, R, 'world')
    for original, copy in zip((q, omega, R), copies):
        np.testing.assert_array_equal(original, copy)


@pytest.mark.parametrize('call, message', [
    (lambda: rk.quaternion_derivative([0, 0, 0, 1], [1, 2, 3], 'Body'), '`frame`'),
    (lambda: rk.quaternion_derivative([0, 0, 0, 1], [1, 2, 3], None), '`frame`'),
    (lambda: rk.quaternion_derivative([0, 0, 1], [1, 2, 3]),
     r'`q` to have shape \(\.\.\., 4\), got \(3,\)'),
    (lambda: rk.quaternion_derivative([0, 0, 0, 1], [1, 2]),
     r'`omega` to have shape \(\.\.\., 3\)'),
    (lambda: rk.quaternion_derivative([0, 0, 0, 0], [1, 2, 3]), '`q` has zero norm'),
    (lambda: rk.quaternion_derivative([[0, 0, 0, 1], [0, np.nan, 0, 1]], [1, 2, 3]),
     r'`q` at index \(1,\) has a NaN'),
    (lambda: rk.quaternion_derivative([0, 0, 0, 1], [1, np.inf, 3]), '`omega` has a NaN or Inf'),
    (lambda: rk.quaternion_derivative(np.ones((2, 4)), np.ones((3, 3))), 'do not broadcast'),
    (lambda: rk.quaternion_derivative('q', [1, 2, 3]), '`q` to be an array of numbers'),
    (lambda: rk.angular_velocity_from_quaternion_derivative([0, 0, 0, 1], [0, 0, np.nan, 0]),
     '`q_dot` has a NaN'),
    (lambda: rk.angular_velocity_from_quaternion_derivative([0, 0, 0, 1], [0, 0, 0]), '`q_dot`'),
    (lambda: rk.matrix_derivative(np.eye(3)[:2], [1, 2, 3]),
     r'`R` to have shape \(\.\.\., 3, 3\)'),
    (lambda: rk.matrix_derivative(-np.eye(3), [1, 2, 3]), r'`R` has det <= 0'),
    (lambda: rk.matrix_derivative(np.eye(3), [1, 2, 3], 'inertial'), '`frame`'),
    (lambda: rk.angular_velocity_from_matrix_derivative(np.eye(3), np.full((3, 3), np.nan)),
     '`R_dot` has a NaN'),
    (lambda: rk.angular_velocity_from_matrix_derivative([np.eye(3), np.diag([1, 1, -1])],
                                                        np.eye(3)),
     r'`R` at index \(1,\) has det <= 0'),
])
def test_bad_input_raises_naming_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()
