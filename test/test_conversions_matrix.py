"""Tests of rotation_node.conversions._matrix: quaternion <-> rotation matrix, nearest rotation."""
import mp_reference as mpr
import numpy as np
import pytest
from rotation_dev.hard_cases import (
    diagonal_rotations, hard_matrices, hard_quaternions, noisy_matrices)
from rotation_node import conversions as rc
from scipy.spatial.transform import Rotation
import transforms3d

BOUND = 8
ROUND_TRIP = 16


def test_matrix_from_quaternion_matches_scipy_and_transforms3d(rng):
    q = rng.normal(size=(50, 4))
    m = rc.matrix_from_quaternion(q)
    assert np.allclose(m, Rotation.from_quat(q).as_matrix(), atol=1e-15)
    assert np.allclose(m[0], transforms3d.quaternions.quat2mat(np.roll(q[0], 1)), atol=1e-15)


def test_matrix_from_quaternion_hard_cases(rng):
    q = hard_quaternions(rng, 200)
    m = rc.matrix_from_quaternion(q)
    assert np.abs(np.einsum('nji,njk->nik', m, m) - np.eye(3)).max() <= 8 * mpr.EPS
    errors = [mpr.error_in_eps(mpr.nearest_rotation_quaternion(r), t) for r, t in zip(m, q)]
    assert max(errors) <= BOUND


def test_quaternion_from_matrix_hard_cases(rng):
    m = hard_matrices(rng, 200)
    q = rc.quaternion_from_matrix(m)
    assert np.all(q[:, 3] >= 0)
    errors = [mpr.error_in_eps(x, mpr.nearest_rotation_quaternion(r)) for x, r in zip(q, m)]
    assert max(errors) <= BOUND


@pytest.mark.parametrize('index', range(3))
def test_rotation_by_pi_about_coordinate_axis(index):
    q = rc.quaternion_from_matrix(diagonal_rotations()[index])
    expected = np.zeros(4)
    expected[index] = 1.0
    assert np.array_equal(q, expected)


def test_round_trip_quaternion_matrix_quaternion(rng):
    q = hard_quaternions(rng, 300)
    back = rc.quaternion_from_matrix(rc.matrix_from_quaternion(q))
    assert rc.quaternion_distance(q, back).max() <= ROUND_TRIP * mpr.EPS


@pytest.mark.parametrize('sigma', [1e-16, 1e-13, 1e-10, 1e-7, 1e-4, 1e-2, 1e-1])
def test_noisy_matrix_gives_nearest_rotation(rng, sigma):
    noisy, _ = noisy_matrices(rng, 40, sigma)
    q = rc.quaternion_from_matrix(noisy)
    errors = [mpr.error_in_eps(x, mpr.nearest_rotation_quaternion(r)) for x, r in zip(q, noisy)]
    assert max(errors) <= BOUND


def test_nearest_rotation_agrees_with_svd(rng):
    noisy, _ = noisy_matrices(rng, 80, 0.3)
    noisy = noisy[np.linalg.det(noisy) > 0]
    u, _, vt = np.linalg.svd(noisy)
    d = np.sign(np.linalg.det(u @ vt))
    u[:, :, 2] *= d[:, None]
    nearest = u @ vt
    assert np.allclose(rc.matrix_from_quaternion(rc.quaternion_from_matrix(noisy)), nearest,
                       atol=1e-13)


def test_scaled_rotation_projects_to_rotation(rng):
    r = rc.matrix_from_quaternion(rng.normal(size=4))
    assert rc.quaternion_distance(rc.quaternion_from_matrix(2.0 * r),
                                  rc.quaternion_from_matrix(r)) <= 4 * mpr.EPS


def test_det_not_positive_is_rejected():
    with pytest.raises(ValueError, match=r'`R` at index \(1,\) has det <= 0'):
        rc.quaternion_from_matrix([np.eye(3), np.diag([1.0, 1, -1])])
    with pytest.raises(ValueError, match='det <= 0'):
        rc.quaternion_from_matrix(np.zeros((3, 3)))


def test_non_orthonormal_raise_mode():
    m = np.eye(3)
    m[0, 1] = 1e-3
    with pytest.raises(ValueError, match='orthonormal'):
        rc.quaternion_from_matrix(m, non_orthonormal='raise')
    assert np.allclose(rc.quaternion_from_matrix(m, non_orthonormal='raise',
                                                 orthonormal_tolerance=1e-2)[3], 1.0, atol=1e-6)


def test_defaults_given_explicitly_act_as_the_defaults(rng):
    """The defaults are recognised by identity (no check): equal values take the checked path."""
    m = rc.matrix_from_quaternion(rng.normal(size=4)) + rng.normal(scale=1e-3, size=(3, 3))
    tolerance, mode = float('1e-6'), ''.join(['pro', 'ject'])   # equal, distinct objects
    for function in (rc.quaternion_from_matrix, rc.rotation_vector_from_matrix,
                     lambda r, **k: rc.euler_from_matrix(r, 'zyz', **k)):
        assert np.array_equal(function(m, orthonormal_tolerance=tolerance, non_orthonormal=mode),
                              function(m))
    for got, expected in zip(rc.axis_angle_from_matrix(m, orthonormal_tolerance=tolerance,
                                                       non_orthonormal=mode),
                             rc.axis_angle_from_matrix(m)):
        assert np.array_equal(got, expected)
    with pytest.raises(ValueError, match='orthonormal'):   # the default tolerance, raise mode
        rc.euler_from_matrix(m, 'zyz', non_orthonormal='raise')


def test_float32_roundoff_passes_default_tolerance_in_raise_mode(rng):
    m = rc.matrix_from_quaternion(rng.normal(size=(20, 4))).astype(np.float32)
    q = rc.quaternion_from_matrix(m, non_orthonormal='raise')
    assert q.shape == (20, 4)


@pytest.mark.parametrize('count', [1, 7, 3000])   # one matrix, a few, a batch (>= BATCH_SAMPLES)
def test_every_from_matrix_conversion_is_the_quaternion_path(rng, count):
    # Exact, slightly noisy (Newton-Schulz) and far-from-orthonormal (eigenvector method) matrices:
    # the fused single call, its fallback and the batch route must all give the same answers.
    exact = rc.matrix_from_quaternion(rng.normal(size=(count, 4)))
    kinds = [exact, exact + rng.normal(scale=1e-9, size=exact.shape),
             exact + rng.normal(scale=0.4, size=exact.shape)]
    for m in kinds:
        m = m[np.linalg.det(m) > 0]
        if count == 1:
            m = m.reshape(-1, 3, 3)[:1].reshape(3, 3) if m.size else exact[0]
        q = rc.quaternion_from_matrix(m)
        assert np.array_equal(rc.euler_from_matrix(m, 'ZYX', degrees=True),
                              rc.euler_from_quaternion(q, 'ZYX', degrees=True))
        assert np.array_equal(rc.rotation_vector_from_matrix(m),
                              rc.rotation_vector_from_quaternion(q))
        for got, expected in zip(rc.axis_angle_from_matrix(m), rc.axis_angle_from_quaternion(q)):
            assert np.array_equal(got, expected)


def test_from_matrix_conversions_name_the_bad_matrix():
    m = np.stack([np.eye(3)] * 3)
    m[2, 1, 1] = np.nan
    for function in (rc.rotation_vector_from_matrix, rc.axis_angle_from_matrix,
                     lambda r: rc.euler_from_matrix(r, 'xyz')):
        with pytest.raises(ValueError, match=r'`R` at index \(2,\) has a NaN'):
            function(m)
    message = "`non_orthonormal` to be 'project' or 'raise', got 'snap'"
    with pytest.raises(ValueError, match=message):
        rc.euler_from_matrix(np.eye(3), 'xyz', non_orthonormal='snap')
    for tolerance in (-1e-6, float('nan'), '1e-6', np.array([1e-6, 1e-3])):
        with pytest.raises(ValueError, match='`orthonormal_tolerance` to be a number >= 0'):
            rc.quaternion_from_matrix(np.eye(3), orthonormal_tolerance=tolerance)
