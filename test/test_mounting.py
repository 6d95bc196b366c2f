"""Tests of rotation_node.mounting: R' = W R M, against scipy."""
import math

import numpy as np
import pytest
from rotation_node import conversions as rc
from rotation_node.mounting import IDENTITY, Mounting, quaternion_from_rotation_values
from scipy.spatial.transform import Rotation

M = Rotation.from_euler('xyz', [10.0, -70.0, 135.0], degrees=True)
W = Rotation.from_euler('xyz', [-5.0, 3.0, 200.0], degrees=True)
MOUNTING = Mounting(tuple(M.as_quat()), tuple(W.as_quat()))
EPS = np.finfo(float).eps


def test_orientation_is_w_r_m():
    r = Rotation.random(200, random_state=1)
    got = MOUNTING.quaternion(r.as_quat())
    expected = W * r * M
    assert (expected.inv() * Rotation.from_quat(got)).magnitude().max() < 8 * EPS
    assert np.all(got[:, 3] >= 0)
    # Any norm is kept (the pipeline normalises later).
    scaled = MOUNTING.quaternion(3.0 * r.as_quat())
    assert np.allclose(np.linalg.norm(scaled, axis=1), 3.0, rtol=1e-15, atol=0)


def test_one_sample_is_bit_identical_to_its_row_of_a_block():
    q = Rotation.random(50, random_state=2).as_quat()
    v = np.random.default_rng(3).normal(size=(50, 3))
    block_q, block_b, block_w = (MOUNTING.quaternion(q), MOUNTING.body_vector(v),
                                 MOUNTING.world_vector(v))
    for k in range(50):
        assert np.array_equal(MOUNTING.quaternion(q[k]), block_q[k])
        assert np.array_equal(MOUNTING.body_vector(v[k]), block_b[k])
        assert np.array_equal(MOUNTING.world_vector(v[k]), block_w[k])


def test_angular_velocity_stays_consistent_with_the_orientation():
    """w_world = R w_body holds before and after: M^T w_body and W w_world."""
    r = Rotation.random(100, random_state=4)
    w_body = np.random.default_rng(5).normal(size=(100, 3))
    w_world = r.apply(w_body)
    new_r = Rotation.from_quat(MOUNTING.quaternion(r.as_quat()))
    new_body = MOUNTING.body_vector(w_body)
    assert np.abs(new_body - M.inv().apply(w_body)).max() < 1e-15 * 8
    assert np.abs(new_r.apply(new_body) - MOUNTING.world_vector(w_world)).max() < 1e-14


def test_angular_velocity_of_the_mounted_motion_by_finite_difference():
    """The rate of R(t) M (body) and W R(t) (world), differenced, is what the methods give."""
    w_body = np.array([0.3, -1.2, 0.8])
    t = np.array([0.0, 1e-3])
    r = Rotation.from_quat([0.1, 0.2, 0.3, 0.9]) * Rotation.from_rotvec(np.outer(t, w_body))
    mounted = Rotation.from_quat(MOUNTING.quaternion(r.as_quat()))
    step = (mounted[0].inv() * mounted[1]).as_rotvec() / 1e-3
    assert np.abs(step - MOUNTING.body_vector(w_body)).max() < 1e-12


def test_covariances_rotate_with_their_frame():
    a = np.random.default_rng(6).normal(size=(20, 3, 3))
    c = a @ np.swapaxes(a, -1, -2)
    m, w = M.as_matrix(), W.as_matrix()
    assert np.abs(MOUNTING.body_covariance(c) - m.T @ c @ m).max() < 1e-14 * np.abs(c).max()
    assert np.abs(MOUNTING.world_covariance(c) - w @ c @ w.T).max() < 1e-14 * np.abs(c).max()


def test_covariance_of_samples_through_the_mounting():
    """Monte Carlo: body noise exp(v) on R becomes M^T v on R M; world noise W v on W R."""
    rng = np.random.default_rng(7)
    sigma = np.diag([0.01, 0.02, 0.005]) ** 2
    v = rng.multivariate_normal(np.zeros(3), sigma, size=20000)
    r = Rotation.from_quat([0.3, -0.2, 0.1, 0.9])
    noisy = Rotation.from_quat(MOUNTING.quaternion((r * Rotation.from_rotvec(v)).as_quat()))
    clean = Rotation.from_quat(MOUNTING.quaternion(r.as_quat()))
    body = (clean.inv() * noisy).as_rotvec()
    assert np.abs(np.cov(body.T) - MOUNTING.body_covariance(sigma)).max() < 0.05 * sigma.max()
    noisy_world = Rotation.from_quat(MOUNTING.quaternion((Rotation.from_rotvec(v) * r).as_quat()))
    world = (noisy_world * clean.inv()).as_rotvec()
    assert np.abs(np.cov(world.T) - MOUNTING.world_covariance(sigma)).max() < 0.05 * sigma.max()


def test_yaw_offset_and_declination_add_to_the_ros_yaw_as_robot_localization():
    rpy = np.array([0.2, -0.4, 1.0])
    q = rc.quaternion_from_euler(rpy, 'xyz')
    mounting = Mounting.from_parts(yaw_offset=0.25, magnetic_declination=-0.1)
    got = rc.euler_from_quaternion(mounting.quaternion(q), 'xyz')
    assert np.abs(got - (rpy + [0.0, 0.0, 0.15])).max() < 1e-15 * 4
    # On top of a world rotation: W = Rz(offset + declination) W0.
    world = Mounting.from_parts(world=[0.0, 0.0, 30.0], yaw_offset=math.radians(15.0))
    assert np.abs(np.array(world.world) - Rotation.from_euler(
        'z', 45.0, degrees=True).as_quat()).max() < 1e-16 * 4


def test_rotation_values_quaternion_or_rpy_degrees():
    assert quaternion_from_rotation_values([0.0, 0.0, 0.0, 1.0]) == IDENTITY
    rpy = quaternion_from_rotation_values([10.0, 20.0, -30.0])
    assert np.abs(np.array(rpy) - Rotation.from_euler(
        'xyz', [10.0, 20.0, -30.0], degrees=True).as_quat()).max() < 1e-16 * 4
    assert math.hypot(*quaternion_from_rotation_values([0, 0, 0.6, 0.8 * (1 + 5e-7)])) == \
        pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize('values, message', [
    ([0.0, 0.0, 0.0, 2.0], 'unit quaternion'),
    ([0.0, 0.0], 'got 2 numbers'),
    ([0.0, math.nan, 0.0], 'finite'),
])
def test_bad_rotation_values(values, message):
    with pytest.raises(ValueError, match=message):
        quaternion_from_rotation_values(values)


def test_identity_changes_nothing_and_inverse_undoes():
    assert Mounting().is_identity and not MOUNTING.is_identity
    assert Mounting.from_parts(body=[0.0, 0.0, 0.0]).is_identity
    q = Rotation.random(10, random_state=8).as_quat()
    back = MOUNTING.inverse.quaternion(MOUNTING.quaternion(q))
    assert (Rotation.from_quat(back).inv() * Rotation.from_quat(q)).magnitude().max() < 1e-15
    assert np.array_equal(Mounting().body_vector([1.0, 2.0, 3.0]), [1.0, 2.0, 3.0])


def test_bad_arguments_name_themselves():
    with pytest.raises(ValueError, match='`quaternion`'):
        MOUNTING.quaternion([0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match='`vector`'):
        MOUNTING.body_vector([0.0, np.inf, 1.0])
