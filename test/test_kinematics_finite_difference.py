"""Tests of rotation_node.kinematics._finite_difference: angular velocity from orientations."""
import numpy as np
import pytest

from rotation_node import conversions as rc
from rotation_node import kinematics as rk
from scipy.spatial.transform import Rotation, Slerp
from test_kinematics_coning import coning_orientation, coning_rate

FRAMES = ('body', 'world')


def constant_rate_series(q0, omega, t, frame):
    step = rc.quaternion_from_rotation_vector(omega * (t - t[0])[:, None])
    return rc.quaternion_product(q0, step) if frame == 'body' else rc.quaternion_product(step, q0)


@pytest.mark.parametrize('frame', FRAMES)
def test_constant_angular_velocity_is_exact(rng, frame):
    """Exact for a constant rate with any (non-uniform) steps, up to a rotation of pi per step."""
    t = np.cumsum(rng.uniform(0.01, 0.5, size=40))
    omega = np.array([1.5, -2.0, 0.7])  # |omega| max step = 1.36 rad
    q = constant_rate_series(rc.canonical_quaternion(rng.normal(size=4)), omega, t, frame)
    estimate = rk.angular_velocity_from_quaternions(q, t, frame)
    assert estimate.shape == (39, 3)
    np.testing.assert_allclose(estimate, np.broadcast_to(omega, (39, 3)), rtol=0, atol=1e-13)


@pytest.mark.parametrize('frame', FRAMES)
def test_second_order_at_the_midpoints(frame):
    errors = []
    for steps in (50, 100):
        t = np.linspace(0.0, 2.0, steps + 1)
        estimate = rk.angular_velocity_from_quaternions(coning_orientation(t), t, frame)
        errors.append(np.abs(estimate - coning_rate(0.5 * (t[1:] + t[:-1]), frame)).max())
    assert np.log2(errors[0] / errors[1]) == pytest.approx(2.0, abs=0.3)
    assert errors[1] < 1e-4


@pytest.mark.parametrize('frame', FRAMES)
def test_sign_flips_and_scale_between_samples_do_not_matter(rng, frame):
    t = np.linspace(0.0, 1.0, 30)
    q = coning_orientation(t)
    flipped = q * rng.choice([-1.0, 1.0], size=(30, 1)) * rng.uniform(0.5, 2.0, size=(30, 1))
    np.testing.assert_allclose(rk.angular_velocity_from_quaternions(flipped, t, frame),
                               rk.angular_velocity_from_quaternions(q, t, frame),
                               rtol=0, atol=1e-13)


def test_two_samples_give_one_value():
    """The node's use: one estimate between the previous and the current message."""
    q_prev = rc.quaternion_from_euler([0.1, 0.2, 0.3], 'xyz')
    q = rc.quaternion_product(q_prev, rc.quaternion_from_rotation_vector([0.0, 0.0, 0.02]))
    omega = rk.angular_velocity_from_quaternions([q_prev, q], [10.0, 10.01])
    assert omega.shape == (1, 3)
    np.testing.assert_allclose(omega[0], [0.0, 0.0, 2.0], atol=1e-10)


def test_leading_dimensions():
    t = np.linspace(0.0, 1.0, 5)
    q = coning_orientation(t)
    batch = np.stack([q, -q[:, [1, 0, 2, 3]]])  # two different series
    estimate = rk.angular_velocity_from_quaternions(batch, t)
    assert estimate.shape == (2, 4, 3)
    np.testing.assert_array_equal(estimate[1], rk.angular_velocity_from_quaternions(batch[1], t))
    np.testing.assert_array_equal(estimate[0], rk.angular_velocity_from_quaternions(q, t))


def test_inverts_integration(rng):
    """Differentiating a Magnus-4 integration of coning motion returns the midpoint rates."""
    t = np.linspace(0.0, 1.0, 201)
    q = rk.integrate_angular_velocity(rc.canonical_quaternion(rng.normal(size=4)), coning_rate, t)
    estimate = rk.angular_velocity_from_quaternions(q, t)
    np.testing.assert_allclose(estimate, coning_rate(0.5 * (t[1:] + t[:-1])), atol=1e-5)


def test_input_not_modified(rng):
    q = rng.normal(size=(6, 4))
    t = np.arange(6.0)
    copies = q.copy(), t.copy()
    rk.angular_velocity_from_quaternions(q, t, 'world')
    np.testing.assert_array_equal(q, copies[0])
    np.testing.assert_array_equal(t, copies[1])


@pytest.mark.parametrize('q, t, frame, message', [
    (np.tile([0, 0, 0, 1.0], (3, 1)), [0.0, 1.0, 1.0], 'body',
     r'`t` to be strictly increasing, got t\[2\] = 1.0 <= t\[1\] = 1.0'),
    (np.tile([0, 0, 0, 1.0], (3, 1)), [0.0, 2.0, 1.0], 'body', r'strictly increasing, got t\[2\]'),
    (np.tile([0, 0, 0, 1.0], (3, 1)), [0.0, np.nan, 1.0], 'body', r'`t` at index 1 is nan'),
    (np.tile([0, 0, 0, 1.0], (3, 1)), [0.0, 1.0], 'body', r'`t` to have shape \(3,\)'),
    (np.tile([0, 0, 0, 1.0], (3, 1)), [[0.0, 1.0, 2.0]], 'body', r'`t` to have shape \(3,\)'),
    (np.tile([0, 0, 0, 1.0], (3, 1)), 'abc', 'body', r'`t` to be an array of numbers'),
    ([[0, 0, 0, 1.0]], [0.0], 'body', r'`q` to hold a time series of N >= 2 samples, got N = 1'),
    ([0, 0, 0, 1.0], [0.0], 'body', r'`q` to have shape \(\.\.\., N, 4\)'),
    (np.ones((3, 3)), [0.0, 1.0, 2.0], 'body', r'`q` to have shape \(\.\.\., 4\)'),
    ([[0, 0, 0, 1.0], [0, 0, 0, 0]], [0.0, 1.0], 'body', r'`q` at index \(1,\) has zero norm'),
    (np.tile([0, 0, 0, 1.0], (2, 3, 1)) * [[[1], [1], [np.nan]]], [0.0, 1.0, 2.0], 'body',
     r'`q` at index \(0, 2\) has a NaN'),
    (np.tile([0, 0, 0, 1.0], (3, 1)), [0.0, 1.0, 2.0], 'spatial', '`frame`'),
])
def test_bad_input_raises_naming_the_argument(q, t, frame, message):
    with pytest.raises(ValueError, match=message):
        rk.angular_velocity_from_quaternions(q, t, frame)


def angle_between(q, expected: Rotation) -> float:
    return (Rotation.from_quat(q) * expected.inv()).magnitude()


def test_slerp_is_exact_at_the_ends_and_stable_for_close_quaternions(rng):
    q0, q1 = Rotation.random(2, random_state=rng).as_quat()
    np.testing.assert_array_equal(rk.slerp(q0, q1, 0.0), rc.canonical_quaternion(q0))
    assert angle_between(rk.slerp(q0, q1, 1.0), Rotation.from_quat(q1)) < 4e-16
    for fraction in (0.25, 0.5, 0.9):
        expected = Slerp([0.0, 1.0], Rotation.from_quat([q0, q1]))(fraction)
        assert angle_between(rk.slerp(q0, q1, fraction), expected) < 4e-16
    # 1e-9 rad apart: the step is 0.3e-9 rad to the rounding of q0 (acos of their dot
    # product, 1.0 in float64, would give a step of 0).
    axis = np.array([0.6, 0.0, 0.8])
    q1 = (Rotation.from_quat(q0) * Rotation.from_rotvec(1e-9 * axis)).as_quat()
    step = (Rotation.from_quat(q0).inv() * Rotation.from_quat(rk.slerp(q0, q1, 0.3))).as_rotvec()
    np.testing.assert_allclose(step, 0.3e-9 * axis, rtol=0, atol=4e-16)
    # The shorter way round whatever the signs of the ends.
    assert angle_between(rk.slerp(q0, -q0, 0.5), Rotation.from_quat(q0)) < 4e-16


def test_slerp_close_quaternions_relative_accuracy():
    # Exact relative step for a tiny rotation: q1 = q0 (x) exp(v) built in one product,
    # so the only error is slerp's; the step must come back as 0.3 v to ~1e-15 relative.
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    v = np.array([3e-10, -4e-10, 1.2e-9])
    q1 = np.array([*(0.5 * v), 1.0])   # exp(v) to 1e-28, normalised below
    q1 /= np.linalg.norm(q1)
    result = rk.slerp(q0, q1, 0.3)
    np.testing.assert_allclose(Rotation.from_quat(result).as_rotvec(), 0.3 * v, rtol=1e-14)
