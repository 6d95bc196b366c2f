"""Tests of rotation_node.conversions._axis_angle: axis-angle, rotation vectors (exp/log maps)."""
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
import mp_reference as mpr
import numpy as np
import pytest
from rotation_dev.hard_cases import hard_matrices, hard_quaternions, hard_rotation_vectors
from rotation_node import conversions as rc
from scipy.spatial.transform import Rotation

BOUND = 8  # eps, geodesic error of one conversion (the documented bound)
ROUND_TRIP = 16


def _max_error(got_quaternions, truths):
    return max(mpr.error_in_eps(g, t) for g, t in zip(got_quaternions, truths))


def test_quaternion_from_rotation_vector_hard_cases(rng):
    v = hard_rotation_vectors(rng, 200)
    got = rc.quaternion_from_rotation_vector(v)
    assert _max_error(got, [mpr.quaternion_from_rotation_vector(x) for x in v]) <= BOUND
    assert np.all(got[:, 3] >= 0)


def test_rotation_vector_from_quaternion_hard_cases(rng):
    q = hard_quaternions(rng, 200)
    v = rc.rotation_vector_from_quaternion(q)
    assert np.all(np.linalg.norm(v, axis=1) <= np.pi * (1 + 2 * mpr.EPS))
    errors = [mpr.error_in_eps(mpr.quaternion_from_rotation_vector(x), mpr.mpf_vector(t))
              for x, t in zip(v, q)]
    assert max(errors) <= BOUND


def test_rotation_vector_of_tiny_rotation_is_exact():
    theta = 1e-300
    v = rc.rotation_vector_from_quaternion([np.sin(theta / 2), 0, 0, np.cos(theta / 2)])
    assert v[0] == pytest.approx(theta, rel=2 * mpr.EPS)


def test_axis_angle_from_quaternion_hard_cases(rng):
    q = hard_quaternions(rng, 200)
    axis, angle = rc.axis_angle_from_quaternion(q)
    assert np.all((angle >= 0) & (angle <= np.pi))
    assert np.allclose(np.linalg.norm(axis, axis=1), 1.0, atol=4e-16)
    errors = [mpr.error_in_eps(mpr.quaternion_from_axis_angle(a, t), mpr.mpf_vector(x))
              for a, t, x in zip(axis, angle, q)]
    assert max(errors) <= BOUND


def test_axis_angle_of_identity_is_x_axis_zero():
    axis, angle = rc.axis_angle_from_quaternion([0, 0, 0, 3.0])
    assert np.array_equal(axis, [1, 0, 0]) and angle == 0.0


def test_quaternion_from_axis_angle_hard_cases(rng):
    axis = rng.normal(size=(200, 3)) * 10.0 ** rng.uniform(-100, 100, (200, 1))
    angle = np.concatenate([hard_rotation_vectors(rng, 100)[:, 0], rng.uniform(-10, 10, 100)])
    got = rc.quaternion_from_axis_angle(axis, angle)
    expected = [mpr.quaternion_from_axis_angle(a, t) for a, t in zip(axis, angle)]
    assert _max_error(got, expected) <= BOUND


def test_axis_angle_broadcasts_scalar_angle():
    q = rc.quaternion_from_axis_angle([[1, 0, 0], [0, 2, 0]], np.pi / 2)
    assert q.shape == (2, 4)
    assert np.allclose(q[1], [0, np.sqrt(0.5), 0, np.sqrt(0.5)])


def test_matrix_forms_match_scipy(rng):
    v = rng.normal(size=(50, 3))
    assert np.allclose(rc.matrix_from_rotation_vector(v), Rotation.from_rotvec(v).as_matrix(),
                       atol=1e-15)
    axis, angle = v, np.linalg.norm(v, axis=1)
    assert np.allclose(rc.matrix_from_axis_angle(axis, angle),
                       Rotation.from_rotvec(v).as_matrix(), atol=1e-15)
    m = Rotation.from_rotvec(v).as_matrix()
    assert np.allclose(rc.rotation_vector_from_matrix(m),
                       Rotation.from_matrix(m).as_rotvec(), atol=1e-14)
    a2, t2 = rc.axis_angle_from_matrix(m)
    assert np.allclose(a2 * t2[:, None], Rotation.from_matrix(m).as_rotvec(), atol=1e-14)


def test_rotation_vector_from_matrix_near_pi(rng):
    m = hard_matrices(rng, 100)
    v = rc.rotation_vector_from_matrix(m)
    errors = [mpr.error_in_eps(mpr.quaternion_from_rotation_vector(x),
                               mpr.nearest_rotation_quaternion(r))
              for x, r in zip(v, m)]
    assert max(errors) <= BOUND


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(v=arrays(np.float64, 3, elements=st.floats(-3.0, 3.0)))
def test_exp_log_round_trip(v):
    if np.linalg.norm(v) >= np.pi:
        v = v * (3.0 / np.linalg.norm(v))
    back = rc.rotation_vector_from_quaternion(rc.quaternion_from_rotation_vector(v))
    assert np.allclose(back, v, rtol=ROUND_TRIP * mpr.EPS, atol=ROUND_TRIP * mpr.EPS * np.pi)


@pytest.mark.parametrize('angle', [np.pi, -np.pi, 3 * np.pi, np.nextafter(np.pi, 4), 1e10])
def test_quaternion_from_axis_angle_is_canonical_at_and_beyond_pi(angle):
    q = rc.quaternion_from_axis_angle([-1.0, 2.0, 0.5], angle)
    assert q[3] > 0 or (q[3] == 0 and q[np.flatnonzero(q)[0]] > 0)
    assert abs(np.linalg.norm(q) - 1) <= 2 * mpr.EPS
    assert mpr.error_in_eps(q, mpr.quaternion_from_axis_angle([-1.0, 2.0, 0.5], angle)) <= BOUND


def test_batch_schedule_equals_the_fused_kernel_bit_for_bit(rng):
    # Large enough for the staged schedule (vectorised sin/cos); hard cases throughout,
    # and one chunk with an angle beyond the branch-free reduction's range.
    v = np.concatenate([hard_rotation_vectors(rng, 3000), rng.normal(size=(3000, 3)) * 1e6])
    axis, angle = rng.normal(size=(6000, 3)), np.concatenate([v[:3000, 0], [3e6], v[3001:, 1]])
    for batch, single in ((rc.quaternion_from_rotation_vector(v),
                           rc.quaternion_from_rotation_vector),
                          (rc.matrix_from_rotation_vector(v), rc.matrix_from_rotation_vector)):
        assert np.array_equal(batch[::7], [single(x) for x in v[::7]])
    for function in (rc.quaternion_from_axis_angle, rc.matrix_from_axis_angle):
        batch = function(axis, angle)
        assert np.array_equal(batch[::7], [function(a, t) for a, t in zip(axis[::7], angle[::7])])


def test_batch_schedule_reports_the_first_bad_sample(rng):
    axis, angle = rng.normal(size=(2, 5000, 3)), rng.normal(size=(2, 5000))
    axis[1, 4500] = 0.0
    angle[1, 4700] = np.inf
    with pytest.raises(ValueError, match=r'`axis` at index \(1, 4500\) has zero norm'):
        rc.quaternion_from_axis_angle(axis, angle)
    axis[1, 4500] = 1.0
    with pytest.raises(ValueError, match=r'`angle` at index \(1, 4700\) has a NaN or Inf'):
        rc.matrix_from_axis_angle(axis, angle)
    v = rng.normal(size=(9000, 3))
    v[8000, 1] = np.nan
    with pytest.raises(ValueError, match=r'`v` at index \(8000,\) has a NaN'):
        rc.quaternion_from_rotation_vector(v)


def _grid_quaternions():
    """Quaternions with components in {0, +-1/2, +-sqrt(1/2), +-1}, unit or not, any sign of w."""
    values = (0.0, 0.5, -0.5, np.sqrt(0.5), -np.sqrt(0.5), 1.0, -1.0)
    q = np.stack(np.meshgrid(values, values, values, values, indexing='ij'), -1).reshape(-1, 4)
    return q[np.abs(q).max(axis=1) > 0]


def test_angles_are_in_zero_to_pi_on_every_route():
    q = _grid_quaternions()
    m = rc.matrix_from_quaternion(q)
    many = np.tile(q, (2, 1))
    angles = [rc.axis_angle_from_quaternion(q)[1], rc.axis_angle_from_quaternion(many)[1],
              rc.axis_angle_from_matrix(m)[1],
              np.array([rc.axis_angle_from_quaternion(x)[1] for x in q]),
              np.array([rc.axis_angle_from_matrix(x)[1] for x in m])]
    for a in angles:
        assert np.all((a >= 0.0) & (a <= np.pi))
    truth = mpr.rotation_distance(q / np.linalg.norm(q, axis=1, keepdims=True), [0, 0, 0, 1])
    assert np.max(np.abs(angles[0] - truth)) <= 1e-15


def test_quaternions_from_axis_angle_and_rotation_vectors_are_canonical():
    steps = np.arange(-8, 9) * (np.pi / 2)
    axes = np.concatenate([np.eye(3), -np.eye(3), [[1.0, 1.0, 0.0], [0.0, -1.0, 1.0]]])
    axis = np.repeat(axes, len(steps), axis=0)
    angle = np.tile(steps, len(axes))
    for q in (rc.quaternion_from_axis_angle(axis, angle),
              rc.quaternion_from_rotation_vector(axis * angle[:, None]),
              rc.quaternion_from_axis_angle(np.tile(axis, (80, 1)), np.tile(angle, 80))):
        assert mpr.is_canonical(q)
    q = _grid_quaternions()
    assert mpr.is_canonical(rc.canonical_quaternion(q))
    assert mpr.is_canonical(rc.quaternion_from_matrix(rc.matrix_from_quaternion(q)))
