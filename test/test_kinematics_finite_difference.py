"""Tests of rotation_node.kinematics._finite_difference: angular velocity from orientations."""
import numpy as np
import pytest

from rotation_node import conversions as rc
from rotation_node import kinematics as rk
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
