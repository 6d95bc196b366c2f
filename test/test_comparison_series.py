"""Tests of rotation_node.comparison._series: slerp at other stamps, errors, statistics."""
import numpy as np
import pytest
from rotation_node import comparison, conversions
from rotation_node.errors import ComparisonError
from scipy.spatial.transform import Rotation, Slerp


def test_slerp_matches_scipy(rng):
    q0, q1 = Rotation.random(200, random_state=rng), Rotation.random(200, random_state=rng)
    u = rng.uniform(0.0, 1.0, 200)
    ours = comparison.slerp(q0.as_quat(), q1.as_quat() * -1.0, u)    # either sign of q1
    expected = [Slerp([0.0, 1.0], Rotation.concatenate([a, b]))(f).as_quat()
                for a, b, f in zip(q0, q1, u)]
    distance = (Rotation.from_quat(ours).inv() * Rotation.from_quat(expected)).magnitude()
    assert np.max(distance) < 1e-14
    assert np.all(ours[:, 3] >= 0.0)


def test_interpolation_at_sample_times_is_exact_and_between_matches_scipy(rng):
    t = np.cumsum(rng.uniform(0.005, 0.015, 300))
    q = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (300, 3)), axis=0))
    query = np.concatenate([t[5:50], rng.uniform(t[0], t[-1], 400)])
    valid, ours = comparison.interpolate_orientations(t, q.as_quat(), query, max_gap=1.0)
    assert valid.all()
    canonical = conversions.canonical_quaternion(q.as_quat())   # the samples as checked
    np.testing.assert_array_equal(ours[:45], canonical[5:50])
    expected = Slerp(t, q)(query[45:])
    assert np.max((Rotation.from_quat(ours[45:]).inv() * expected).magnitude()) < 1e-13


def test_gaps_and_times_outside_the_series_are_dropped():
    t = np.array([0.0, 0.01, 0.02, 0.10, 0.11, 0.12])
    q = Rotation.from_rotvec(np.outer(t, [0.0, 0.0, 1.0])).as_quat()
    query = np.array([-0.001, 0.0, 0.015, 0.05, 0.105, 0.12, 0.121])
    valid, ours = comparison.interpolate_orientations(t, q, query, max_gap=0.05)
    np.testing.assert_array_equal(valid, [False, True, True, False, True, True, False])
    np.testing.assert_allclose(Rotation.from_quat(ours).as_rotvec()[:, 2],
                               [0.0, 0.015, 0.105, 0.12], rtol=0, atol=1e-15)
    # The default tolerance is 5 median steps (0.05 s here): the gap of 0.08 s is dropped.
    assert not comparison.interpolate_orientations(t, q, [0.05])[0][0]
    assert comparison.interpolate_orientations(t, q, [0.05], max_gap=0.08)[0][0]


def test_errors_are_rotation_vectors_about_the_reference_body_axes(rng):
    ref, est = Rotation.random(500, random_state=rng), Rotation.random(500, random_state=rng)
    errors = comparison.orientation_errors(ref.as_quat(), est.as_quat())
    np.testing.assert_allclose(errors, (ref.inv() * est).as_rotvec(), rtol=0, atol=1e-13)
    # A small rotation about the reference body's y axis is an error along y.
    tilted = ref * Rotation.from_rotvec([0.0, 1e-3, 0.0])
    np.testing.assert_allclose(comparison.orientation_errors(ref.as_quat(), tilted.as_quat()),
                               np.broadcast_to([0.0, 1e-3, 0.0], (500, 3)), rtol=1e-9,
                               atol=1e-15)


def test_statistics_match_scipy_on_the_same_pairs(rng):
    ref = Rotation.random(1000, random_state=rng)
    est = ref * Rotation.from_rotvec(rng.normal(0.0, 0.01, (1000, 3)))
    statistics = comparison.error_statistics(
        comparison.orientation_errors(ref.as_quat(), est.as_quat()))
    angle = (ref.inv() * est).magnitude()
    vector = (ref.inv() * est).as_rotvec()
    np.testing.assert_allclose(
        [statistics.rmse, statistics.mean, statistics.median, statistics.p95, statistics.maximum],
        [np.sqrt(np.mean(angle ** 2)), np.mean(angle), np.median(angle),
         np.percentile(angle, 95), np.max(angle)], rtol=1e-12)
    np.testing.assert_allclose(statistics.axis_rmse, np.sqrt(np.mean(vector ** 2, axis=0)),
                               rtol=1e-12)
    np.testing.assert_allclose(statistics.axis_maximum, np.max(np.abs(vector), axis=0),
                               rtol=1e-12)


@pytest.mark.parametrize('t, q, message', [
    ([0.0], [[0, 0, 0, 1]], 'at least 2'),
    ([0.0, 0.0], [[0, 0, 0, 1]] * 2, 'strictly increasing'),
    ([0.0, np.nan], [[0, 0, 0, 1]] * 2, 'strictly increasing'),
    ([0.0, 1.0], [[0, 0, 0, 1]], 'shape'),
    ([0.0, 1.0], [[0, 0, 0, 1], [0, 0, 0, 0]], 'zero'),
])
def test_bad_series_raise(t, q, message):
    with pytest.raises(ComparisonError, match=message):
        comparison.interpolate_orientations(t, q, [0.5])


def test_statistics_of_nothing_raise():
    with pytest.raises(ComparisonError):
        comparison.error_statistics(np.zeros((0, 3)))
