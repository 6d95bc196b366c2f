"""
Tests of rotation_node.covariance: orientation covariance between representations.

Oracles: central finite differences of scipy's conversions (the Jacobians),
Monte Carlo with 10^6 samples of the tangent perturbation (the covariances,
with the statistical error bounded from the sample size), and exact algebraic
identities (round trips, world <-> body).
"""
import warnings

import numpy as np
import pytest
from rotation_node import conversions as rc
from rotation_node import covariance as cv
from rotation_node.kinematics import EulerSingularityWarning
from scipy.spatial.transform import Rotation
from test_kinematics_euler_rates import random_angles, singular_middle_angles

EPS = np.finfo(float).eps
FRAMES = ('world', 'body')
CONVENTIONS = [(seq, frame) for seq in rc.SEQUENCES for frame in FRAMES]
FD_STEP = 1e-5
# A correlated tangent covariance, standard deviations about 1e-3 rad.
CHOLESKY = 1e-3 * np.array([[1.0, 0.0, 0.0], [0.5, 0.8, 0.0], [-0.3, 0.2, 1.2]])
SIGMA = CHOLESKY @ CHOLESKY.T
MC_SAMPLES = 10 ** 6


def random_covariance(rng, n, scale=1e-3):
    a = scale * rng.normal(size=(n, 3, 3))
    return a @ np.swapaxes(a, -1, -2) + scale ** 2 * 0.1 * np.eye(3)


def wrapped(angle):
    """``angle`` (a difference of angles in (-pi, pi]) wrapped to (-pi, pi], as a new array."""
    out = np.array(angle, dtype=float)
    out[out > np.pi] -= 2 * np.pi
    out[out <= -np.pi] += 2 * np.pi
    return out


def perturbed(rotation, d, frame):
    """``exp([d]x) R`` (world) or ``R exp([d]x)`` (body), with scipy."""
    return Rotation.from_rotvec(d) * rotation if frame == 'world' else \
        rotation * Rotation.from_rotvec(d)


def relative_difference(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize('seq, frame', CONVENTIONS)
def test_jacobian_matches_central_difference_of_scipy(rng, seq, frame):
    angles = random_angles(rng, seq, 16)
    jac = cv.rotation_vector_covariance_jacobian(angles, seq, frame)
    for a, j in zip(angles, jac):
        r_hat = Rotation.from_euler(seq, a)
        steps = FD_STEP * np.eye(3)
        plus = Rotation.from_euler(seq, a + steps)
        minus = Rotation.from_euler(seq, a - steps)
        if frame == 'world':
            d_plus, d_minus = (plus * r_hat.inv()).as_rotvec(), (minus * r_hat.inv()).as_rotvec()
        else:
            d_plus, d_minus = (r_hat.inv() * plus).as_rotvec(), (r_hat.inv() * minus).as_rotvec()
        j_fd = ((d_plus - d_minus) / (2 * FD_STEP)).T
        sigma_a = SIGMA * 4.0
        err = relative_difference(j @ sigma_a @ j.T, j_fd @ sigma_a @ j_fd.T)
        assert err < 1e-8, f'{seq} {frame} at {a}: J Sigma J^T vs finite differences {err:.2e}'


@pytest.mark.parametrize('seq, frame', CONVENTIONS)
def test_euler_covariance_matches_central_difference_of_scipy(rng, seq, frame):
    angles = random_angles(rng, seq, 16)
    sigmas = random_covariance(rng, 16)
    euler_cov = cv.euler_covariance_from_rotation_vector_covariance(angles, sigmas, seq, frame)
    for a, sigma, got in zip(angles, sigmas, euler_cov):
        r_hat = Rotation.from_euler(seq, a)
        steps = FD_STEP * np.eye(3)
        plus = perturbed(r_hat, steps, frame).as_euler(seq)
        minus = perturbed(r_hat, -steps, frame).as_euler(seq)
        j_inv = (wrapped(plus - minus) / (2 * FD_STEP)).T
        expected = j_inv @ sigma @ j_inv.T
        err = relative_difference(got, expected)
        assert err < 1e-8, f'{seq} {frame} at {a}: vs finite differences {err:.2e}'


@pytest.mark.parametrize('frame', FRAMES)
def test_quaternion_jacobian_matches_central_difference_of_scipy(rng, frame):
    q = Rotation.random(16, random_state=7).as_quat()
    sigmas = random_covariance(rng, 16)
    got = cv.quaternion_covariance_from_rotation_vector_covariance(q, sigmas, frame)
    for qi, sigma, g in zip(q, sigmas, got):
        r_hat = Rotation.from_quat(qi)
        steps = FD_STEP * np.eye(3)
        plus, minus = perturbed(r_hat, steps, frame).as_quat(), \
            perturbed(r_hat, -steps, frame).as_quat()
        plus *= np.sign(plus @ qi)[:, None]
        minus *= np.sign(minus @ qi)[:, None]
        jac = ((plus - minus) / (2 * FD_STEP)).T
        err = relative_difference(g, jac @ sigma @ jac.T)
        assert err < 1e-8, f'{frame}: quaternion covariance vs finite differences {err:.2e}'


def monte_carlo_orientation(rng):
    """Return an orientation at least 0.3 rad from gimbal lock in all 24 conventions."""
    for q in Rotation.random(200, random_state=11).as_quat():
        if all(rc.euler_singularity_margin(q, seq) > 0.3 for seq in rc.SEQUENCES):
            return q
    raise AssertionError('no orientation far from every gimbal lock')


def statistical_bound(cov, n, k=5.0):
    """``k`` standard deviations of the sample covariance of ``n`` Gaussian samples."""
    var = np.diagonal(cov, axis1=-2, axis2=-1)
    return k * np.sqrt((var[:, None] * var[None, :] + cov ** 2) / n)


@pytest.mark.slow
@pytest.mark.parametrize('frame', FRAMES)
def test_euler_covariance_matches_monte_carlo_every_convention(rng, frame):
    q_hat = monte_carlo_orientation(rng)
    d = rng.standard_normal((MC_SAMPLES, 3)) @ CHOLESKY.T
    dq = rc.quaternion_from_rotation_vector(d)
    q = rc.quaternion_product(dq, q_hat) if frame == 'world' else rc.quaternion_product(q_hat, dq)
    failures = []
    for seq in rc.SEQUENCES:
        a_hat = rc.euler_from_quaternion(q_hat, seq)
        linear = cv.euler_covariance_from_rotation_vector_covariance(a_hat, SIGMA, seq, frame)
        samples = wrapped(rc.euler_from_quaternion(q, seq) - a_hat)
        sampled = np.cov(samples.T)
        bound = statistical_bound(linear, MC_SAMPLES)
        worst = np.abs(sampled - linear).max() / np.abs(linear).max()
        if not (np.abs(sampled - linear) <= bound).all():
            failures.append(f'{seq}: relative {worst:.2e}, '
                            f'{(np.abs(sampled - linear) / bound).max():.2f} x the 5-sigma bound')
    assert not failures, f'first-order vs Monte Carlo ({frame}): ' + '; '.join(failures)


@pytest.mark.slow
@pytest.mark.parametrize('frame', FRAMES)
def test_quaternion_covariance_matches_monte_carlo(rng, frame):
    q_hat = Rotation.from_euler('xyz', [0.4, -0.7, 2.1]).as_quat()
    d = rng.standard_normal((MC_SAMPLES, 3)) @ CHOLESKY.T
    dq = rc.quaternion_from_rotation_vector(d)
    q = rc.quaternion_product(dq, q_hat) if frame == 'world' else rc.quaternion_product(q_hat, dq)
    q *= np.sign(q @ q_hat)[:, None]
    linear = cv.quaternion_covariance_from_rotation_vector_covariance(q_hat, SIGMA, frame)
    sampled = np.cov(q.T)
    var = np.diagonal(linear)
    bound = 5.0 * np.sqrt((var[:, None] * var[None, :] + linear ** 2) / MC_SAMPLES) + 1e-12
    excess = (np.abs(sampled - linear) / bound).max()
    assert excess <= 1.0, f'{frame}: 4x4 covariance vs Monte Carlo, {excess:.2f} x the bound'
    # and back: the sample covariance projected to the tangent space is the input's
    back = cv.rotation_vector_covariance_from_quaternion_covariance(q_hat, sampled, frame)
    err = relative_difference(back, np.cov(d.T))
    assert err < 1e-3, f'{frame}: tangent projection of sampled 4x4 covariance, {err:.2e}'


@pytest.mark.parametrize('seq, frame', CONVENTIONS)
def test_round_trips_are_exact_to_rounding(rng, seq, frame):
    angles = random_angles(rng, seq, 50)
    sigma = random_covariance(rng, 50)
    euler_cov = cv.euler_covariance_from_rotation_vector_covariance(angles, sigma, seq, frame)
    back = cv.rotation_vector_covariance_from_euler_covariance(angles, euler_cov, seq, frame)
    err = (np.abs(back - sigma).max(axis=(-1, -2)) / np.abs(sigma).max(axis=(-1, -2))).max()
    # J^-1 is conditioned by 1 / cos(middle): at MARGIN from lock about 5
    assert err < 200 * EPS, f'{seq} {frame}: d -> a -> d relative error {err / EPS:.1f} eps'
    again = cv.euler_covariance_from_rotation_vector_covariance(angles, back, seq, frame)
    err = (np.abs(again - euler_cov).max(axis=(-1, -2))
           / np.abs(euler_cov).max(axis=(-1, -2))).max()
    assert err < 200 * EPS, f'{seq} {frame}: a -> d -> a relative error {err / EPS:.1f} eps'


@pytest.mark.parametrize('frame', FRAMES)
def test_quaternion_round_trip_is_exact_and_projects_out_the_norm(rng, frame):
    q = rng.normal(size=(100, 4)) * 3.0
    sigma = random_covariance(rng, 100)
    quat_cov = cv.quaternion_covariance_from_rotation_vector_covariance(q, sigma, frame)
    back = cv.rotation_vector_covariance_from_quaternion_covariance(q, quat_cov, frame)
    assert np.abs(back - sigma).max() < 8 * EPS * np.abs(sigma).max()
    assert np.allclose(quat_cov, cv.quaternion_covariance_from_rotation_vector_covariance(
        -q, sigma, frame), rtol=0, atol=4 * EPS * np.abs(quat_cov).max())
    unit = q / np.linalg.norm(q, axis=-1, keepdims=True)
    assert np.abs(np.einsum('...ij,...j->...i', quat_cov, unit)).max() < 8 * EPS * 1e-6
    with_norm = quat_cov + 5e-6 * unit[:, :, None] * unit[:, None, :]
    again = cv.rotation_vector_covariance_from_quaternion_covariance(q, with_norm, frame)
    assert np.abs(again - sigma).max() < 8 * EPS * np.abs(sigma).max()


def test_world_and_body_covariances_are_related_by_the_orientation(rng):
    q = Rotation.random(20, random_state=3).as_quat()
    body = random_covariance(rng, 20)
    world = cv.world_rotation_vector_covariance(q, body)
    r = Rotation.from_quat(q).as_matrix()
    assert relative_difference(world, r @ body @ np.swapaxes(r, -1, -2)) < 1e-14
    assert relative_difference(cv.body_rotation_vector_covariance(q, world), body) < 1e-14
    for seq in ('xyz', 'ZXZ'):
        angles = rc.euler_from_quaternion(q, seq)
        with warnings.catch_warnings():
            warnings.simplefilter('error', EulerSingularityWarning)
            from_world = cv.euler_covariance_from_rotation_vector_covariance(
                angles, world, seq, 'world')
            from_body = cv.euler_covariance_from_rotation_vector_covariance(
                angles, body, seq, 'body')
        assert relative_difference(from_world, from_body) < 1e-10


def test_degrees_scale_the_covariance(rng):
    angles = random_angles(rng, 'xyz', 10)
    sigma = random_covariance(rng, 10)
    rad = cv.euler_covariance_from_rotation_vector_covariance(angles, sigma, 'xyz')
    deg = cv.euler_covariance_from_rotation_vector_covariance(np.degrees(angles), sigma, 'xyz',
                                                              degrees=True)
    assert relative_difference(deg, rad * (180 / np.pi) ** 2) < 1e-13
    back = cv.rotation_vector_covariance_from_euler_covariance(np.degrees(angles), deg, 'xyz',
                                                               degrees=True)
    assert relative_difference(back, sigma) < 1e-13


def test_leading_dimensions_broadcast(rng):
    angles = random_angles(rng, 'ZYX', 6).reshape(2, 3, 3)
    sigma = random_covariance(rng, 3)  # (3, 3, 3): broadcasts along the last leading axis
    got = cv.euler_covariance_from_rotation_vector_covariance(angles, sigma, 'ZYX', 'body')
    assert got.shape == (2, 3, 3, 3)
    for i in range(2):
        for j in range(3):
            one = cv.euler_covariance_from_rotation_vector_covariance(angles[i, j], sigma[j],
                                                                      'ZYX', 'body')
            assert np.array_equal(got[i, j], one)
    assert np.array_equal(got, np.swapaxes(got, -1, -2)), 'not exactly symmetric'
    single = cv.quaternion_covariance_from_rotation_vector_covariance([0, 0, 0, 1], SIGMA)
    assert single.shape == (4, 4)


@pytest.mark.parametrize('seq', ['xyz', 'ZYX', 'zxz', 'YXY'])
def test_gimbal_lock_is_nan_with_a_warning_and_grows_as_one_over_margin_squared(seq):
    low, high = singular_middle_angles(seq)
    margins = np.array([0.0, 1e-9, 1e-6, 1e-3, 1e-1])
    angles = np.zeros((len(margins), 3))
    angles[:, 0], angles[:, 2] = 0.3, -0.8
    angles[:, 1] = high - margins
    with pytest.warns(EulerSingularityWarning, match='2 of 5 orientations'):
        cov = cv.euler_covariance_from_rotation_vector_covariance(angles, SIGMA, seq, 'world')
    assert np.isnan(cov[:2]).all()
    assert np.isfinite(cov[2:]).all()
    # the first angle's variance ~ c / margin^2 with c of order sigma^2
    scaled = cov[2:, 0, 0] * np.sin(margins[2:]) ** 2
    assert np.allclose(scaled[:2], scaled[0], rtol=1e-3), scaled
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        cv.euler_covariance_from_rotation_vector_covariance(angles[2:], SIGMA, seq,
                                                            singularity_threshold=0.0)
    with pytest.warns(EulerSingularityWarning, match='4 of 5'):
        cv.euler_covariance_from_rotation_vector_covariance(angles, SIGMA, seq,
                                                            singularity_threshold=1e-2)


@pytest.mark.parametrize('call, message', [
    (lambda: cv.euler_covariance_from_rotation_vector_covariance([0, 0, 0], np.eye(2), 'xyz'),
     '`covariance`'),
    (lambda: cv.euler_covariance_from_rotation_vector_covariance([0, 0], np.eye(3), 'xyz'),
     '`angles`'),
    (lambda: cv.euler_covariance_from_rotation_vector_covariance([0, 0, 0], np.eye(3), 'xyy'),
     'seq'),
    (lambda: cv.euler_covariance_from_rotation_vector_covariance([0, 0, 0], np.eye(3), 'xyz',
                                                                 'fixed'), '`frame`'),
    (lambda: cv.euler_covariance_from_rotation_vector_covariance(
        [0, 0, 0], np.full((3, 3), np.nan), 'xyz'), '`covariance`'),
    (lambda: cv.euler_covariance_from_rotation_vector_covariance(
        [0, 0, 0], np.eye(3), 'xyz', singularity_threshold=-1), 'singularity_threshold'),
    (lambda: cv.rotation_vector_covariance_from_quaternion_covariance([0, 0, 0, 0], np.eye(4)),
     '`quaternion`'),
    (lambda: cv.rotation_vector_covariance_from_quaternion_covariance([0, 0, 0, 1], np.eye(3)),
     '`covariance`'),
    (lambda: cv.quaternion_covariance_from_rotation_vector_covariance([0, 0, 1], np.eye(3)),
     '`quaternion`'),
    (lambda: cv.world_rotation_vector_covariance([0, 0, 0, 1], [[1, 2, 3]]), '`body_covariance`'),
    (lambda: cv.body_rotation_vector_covariance([0, 0, 0, 1], 'x'), '`world_covariance`'),
])
def test_bad_input_raises_value_error_naming_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_linearisation_ratio_is_largest_std_over_margin(rng):
    sigma = np.diag([1e-4, 9e-4, 4e-4])  # largest std 0.03 rad
    rot = Rotation.random(random_state=2).as_matrix()
    rotated = rot @ sigma @ rot.T  # same eigenvalues
    angles = np.array([[0.3, 1.0, -2.0], [0.3, np.pi / 2, 0.0], [0.3, -1.5, 0.0]])
    ratio = cv.euler_linearisation_ratio(angles, rotated, 'xyz')
    assert np.allclose(ratio[[0, 2]], 0.03 / np.array([np.pi / 2 - 1.0, np.pi / 2 - 1.5]),
                       rtol=1e-12)
    assert ratio[1] == np.inf or ratio[1] > 1e14
    proper = cv.euler_linearisation_ratio([[0.0, 0.2, 0.0], [0.0, np.pi - 0.1, 0.0]], sigma,
                                          'ZXZ')
    assert np.allclose(proper, [0.03 / 0.2, 0.03 / 0.1], rtol=1e-12)
    in_degrees = cv.euler_linearisation_ratio(np.degrees(angles[0]), rotated, 'xyz', True)
    assert np.isclose(in_degrees, ratio[0], rtol=1e-12)
    assert cv.euler_linearisation_ratio([0, np.pi / 2, 0], np.zeros((3, 3)), 'xyz') == 0.0


@pytest.mark.parametrize('matrix, defect', [
    (np.diag([1e-6, 2e-6, 3e-6]), None),
    (np.outer([1e-3, -2e-3, 5e-4], [1e-3, -2e-3, 5e-4]), None),    # rank 1: fully correlated
    (np.diag([1e-6, 0.0, 1e-6]), None),                            # a zero variance
    (np.diag([-1e-30, 1e-6, 1e-6]), 'a negative variance'),
    ([[1e-6, 1e-7, 0], [-1e-7, 1e-6, 0], [0, 0, 1e-6]], 'not symmetric'),
    ([[1e-6, 1e-7 * (1 + 1e-12), 0], [1e-7, 1e-6, 0], [0, 0, 1e-6]], None),   # rounding
    ([[1e-6, 2e-6, 0], [2e-6, 1e-6, 0], [0, 0, 1e-6]], 'not positive semi-definite'),
    ([[0, 1e-9, 0], [1e-9, 1e-6, 0], [0, 0, 1e-6]], 'not positive semi-definite'),
    (np.full((3, 3), -0.9e-6) + np.diag([1.9e-6] * 3), 'not positive semi-definite'),
])
def test_covariance_defect_says_what_makes_a_matrix_no_covariance(matrix, defect):
    """Eigenvalues (numpy) agree: a covariance is symmetric positive semi-definite."""
    values = np.asarray(matrix, dtype=float)
    assert cv.covariance_defect(values.ravel().tolist()) == defect
    if defect is None:
        assert np.linalg.eigvalsh(values).min() >= -1e-15 * np.abs(values).max()
    elif defect == 'not positive semi-definite':
        assert np.linalg.eigvalsh(values).min() < 0.0


@pytest.mark.parametrize('call', [
    lambda frame: cv.rotation_vector_covariance_jacobian([0.1, 0.2, 0.3], 'xyz', frame),
    lambda frame: cv.quaternion_covariance_from_rotation_vector_covariance(
        [0.0, 0.0, 0.0, 1.0], np.eye(3), frame),
    lambda frame: cv.rotation_vector_covariance_from_quaternion_covariance(
        [0.0, 0.0, 0.0, 1.0], np.eye(4), frame),
])
def test_a_frame_other_than_world_or_body_is_refused(call):
    with pytest.raises(ValueError, match="`frame` to be 'body' or 'world', got 'enu'"):
        call('enu')
