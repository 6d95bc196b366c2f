"""Tests of rotation_node.conversions._quaternion: product, conjugate, canonical, distance."""
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
import mp_reference as mpr
import numpy as np
import pytest
from rotation_dev.hard_cases import hard_quaternions
from rotation_node import conversions as rc
from scipy.spatial.transform import Rotation

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
nonzero_quaternions = arrays(np.float64, 4, elements=finite).filter(
    lambda q: np.linalg.norm(q) > 1e-3)


def test_product_matches_scipy_composition(rng):
    p, q = rng.normal(size=(2, 50, 4))
    expected = (Rotation.from_quat(p) * Rotation.from_quat(q)).as_quat()
    got = rc.canonical_quaternion(rc.quaternion_product(p, q))
    assert np.allclose(got, rc.canonical_quaternion(expected), atol=1e-15)


def test_product_is_hamilton_ijk():
    i, j, k = np.eye(4)[:3]
    assert np.array_equal(rc.quaternion_product(i, j), k)
    assert np.array_equal(rc.quaternion_product(j, i), -k)
    assert np.array_equal(rc.quaternion_product(i, i), [0, 0, 0, -1])


def test_product_broadcasts_leading_dimensions(rng):
    p = rng.normal(size=(5, 1, 4))
    q = rng.normal(size=(3, 4))
    out = rc.quaternion_product(p, q)
    assert out.shape == (5, 3, 4)
    assert np.allclose(out[2, 1], rc.quaternion_product(p[2, 0], q[1]))


def test_conjugate_is_inverse(rng):
    q = rc.canonical_quaternion(rng.normal(size=(20, 4)))
    identity = rc.quaternion_product(q, rc.quaternion_conjugate(q))
    assert np.allclose(identity, [0, 0, 0, 1], atol=4e-16)


@pytest.mark.parametrize('scale', [1e-160, 1e-6, 1.0, 1e6, 1e160, -1.0, -1e160])
def test_canonical_is_unit_with_nonnegative_w_for_any_scale(rng, scale):
    q = rng.normal(size=(100, 4))
    out = rc.canonical_quaternion(q * scale)
    assert np.all(out[:, 3] >= 0)
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0, atol=4e-16)
    assert np.allclose(out, rc.canonical_quaternion(q), atol=4e-16)


@pytest.mark.parametrize('q', [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -2, 0], [-1, 1, 0, 0],
                               [-0.0, -0.0, -1, -0.0]])
def test_canonical_is_unique_for_w_zero(q):
    q = np.asarray(q, dtype=float)
    a, b = rc.canonical_quaternion(q), rc.canonical_quaternion(-q)
    assert np.array_equal(a, b)
    assert a[3] == 0 and not np.signbit(a[3])
    assert a[np.flatnonzero(a)[0]] > 0


def test_distance_is_exact_for_tiny_angles():
    angle = 1e-12
    q = [np.sin(angle / 2), 0, 0, np.cos(angle / 2)]
    assert rc.quaternion_distance([0, 0, 0, 1], q) == pytest.approx(angle, rel=4 * mpr.EPS)


def test_distance_ignores_sign_and_scale(rng):
    p, q = rng.normal(size=(2, 30, 4))
    d = rc.quaternion_distance(p, q)
    assert np.allclose(rc.quaternion_distance(-1e160 * p, 1e-160 * q), d, rtol=1e-15)
    assert np.all((d >= 0) & (d <= np.pi))


def test_distance_hard_cases_against_mpmath(rng):
    p, q = hard_quaternions(rng, 64), hard_quaternions(rng, 64)
    got = rc.quaternion_distance(p, q)
    for a, b, d in zip(p, q, got):
        truth = float(mpr.distance(mpr.mpf_vector(a), mpr.mpf_vector(b)))
        assert abs(d - truth) <= 4 * mpr.EPS * max(truth, 1e-300) + 1e-300


def test_distance_of_a_rotation_to_itself_is_exactly_zero(rng):
    """Reported: quaternion_distance(q, q) was 2.3e-17 for [0.1, 0.1, 0.6, 0.9], up to 1.6e-16."""
    assert rc.quaternion_distance([0.1, 0.1, 0.6, 0.9], [0.1, 0.1, 0.6, 0.9]) == 0.0
    q = np.concatenate([rng.normal(size=(2000, 4)), hard_quaternions(rng, 500)])
    assert np.all(rc.quaternion_distance(q, q) == 0.0)
    assert np.all(rc.quaternion_distance(q, -q) == 0.0)
    assert all(rc.quaternion_distance(x, s * x) == 0.0 for x in q[::50] for s in (1.0, -1.0))


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(q=nonzero_quaternions, sign=st.sampled_from([1.0, -1.0]))
def test_distance_to_the_same_or_negated_quaternion_is_zero(q, sign):
    assert rc.quaternion_distance(q, sign * np.asarray(q)) == 0.0


def test_rotate_vector_matches_matrix(rng):
    q = rng.normal(size=(40, 4))
    v = rng.normal(size=(40, 3))
    expected = np.einsum('nij,nj->ni', rc.matrix_from_quaternion(q), v)
    assert np.allclose(rc.rotate_vector(q, v), expected, atol=1e-14)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(p=nonzero_quaternions, q=nonzero_quaternions)
def test_distance_is_symmetric_and_bounded(p, q):
    d = rc.quaternion_distance(p, q)
    assert 0.0 <= d <= np.pi
    assert abs(d - rc.quaternion_distance(q, p)) <= 8 * mpr.EPS * max(d, 1.0)


def test_rotate_vector_of_huge_vector_does_not_overflow(rng):
    q = rng.normal(size=(20, 4))
    v = rng.normal(size=(20, 3))
    v /= np.abs(v).max(axis=1, keepdims=True)
    huge = rc.rotate_vector(q, v * 1e308)
    assert np.all(np.isfinite(huge))
    assert np.allclose(huge / 1e308, rc.rotate_vector(q, v), rtol=1e-15, atol=1e-15)


def test_rotate_vector_rescaled_samples_agree_bit_for_bit_with_plain_ones(rng):
    # Chunks of plain samples take the SIMD loop; a chunk holding a sample
    # that needs rescaling is computed again with the rescaling formulas.
    # Scaling by a power of two commutes with rounding, so both must agree
    # to the bit (signed zeros included).
    q = rc.canonical_quaternion(rng.normal(size=(1000, 4)))
    q[::7, 3] = 0.0          # rotations by pi: the sign rule decides on x, y, z
    v = rng.normal(size=(1000, 3))
    v[::5] = [0.0, -0.0, 1.0]
    # signed zeros out: the sign rule (w > 0, and w = +0.0 after a flip) decides them
    q[500:503] = [[0.0, 0.0, -0.0, -1.0], [0.0, 0.0, 1.0, -0.0], [0.0, 0.0, -1.0, 0.0]]
    v[500:503] = [[-2.0, -0.0, 0.0], [-2.0, -0.0, -0.0], [0.0, 1.0, -0.0]]
    plain = rc.rotate_vector(q, v)
    q[300] *= 2.0 ** -600    # tiny: rescaled, the same rotation
    q[301] *= -(2.0 ** 600)  # huge and negated: the same rotation
    v[700] *= 2.0 ** 600     # huge vector: rotated at a rescaled size
    rescaled = rc.rotate_vector(q, v)
    plain[700] *= 2.0 ** 600
    assert np.array_equal(rescaled.view(np.int64), plain.view(np.int64))


def test_product_of_a_batch_equals_the_products_of_its_samples(rng):
    p, q = rng.normal(size=(2, 600, 4))
    p[5] *= 1e-300           # tiny and huge: checked sample by sample, computed alike
    q[400] *= 1e300
    p[::9, :3] = -0.0
    batch = rc.quaternion_product(p, q)
    one_by_one = np.array([rc.quaternion_product(a, b) for a, b in zip(p, q)])
    assert np.array_equal(batch.view(np.int64), one_by_one.view(np.int64))


@pytest.mark.parametrize('function, trailing', [(rc.quaternion_product, 4),
                                                (rc.rotate_vector, 3)])
def test_the_first_bad_sample_of_a_batch_is_named(rng, function, trailing):
    q = rng.normal(size=(1000, 4))
    second = rng.normal(size=(1000, trailing))
    name = 'p' if function is rc.quaternion_product else 'q'
    q[900] = 0.0
    with pytest.raises(ValueError, match=rf'`{name}` at index \(900,\) has zero norm'):
        function(q, second)
    second[700, 1] = np.nan
    with pytest.raises(ValueError, match=r'at index \(700,\) has a NaN or Inf'):
        function(q, second)
