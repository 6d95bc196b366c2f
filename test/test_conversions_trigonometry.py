"""Tests of rotation_node.conversions._trigonometry: the branch-free sin, cos and atan2."""
import math

import mpmath
import numpy as np
import pytest
from rotation_node.conversions._trigonometry import (
    atan2, atan2_in_place_kernel, reduced_sin_cos, REDUCTION_LIMIT, sin_cos,
    sin_cos_in_place_kernel)

mpmath.mp.prec = 300


def _angles(rng):
    """Ordinary, tiny, near multiples of pi/2 (zeros of sin or cos), and beyond the limit."""
    k = [int(v) for v in rng.integers(1, REDUCTION_LIMIT / 1.6, 300)] + [1, 2, 3, 4]
    multiples = [float(mpmath.mpf(n) * mpmath.pi / 2) for n in k]
    return np.concatenate([
        rng.uniform(-10, 10, 500), 10.0 ** rng.uniform(-320, 0, 300), [0.0, -0.0],
        multiples, np.nextafter(multiples, np.inf), -np.nextafter(multiples, -np.inf),
        rng.uniform(-REDUCTION_LIMIT, REDUCTION_LIMIT, 300),
        [REDUCTION_LIMIT, np.nextafter(REDUCTION_LIMIT, np.inf)],
        10.0 ** rng.uniform(5.8, 308, 200) * rng.choice([-1, 1], 200)])


@pytest.mark.slow
def test_sin_cos_is_accurate(rng):
    for a in _angles(rng):
        got = sin_cos(a)
        for value, truth in zip(got, (mpmath.sin(mpmath.mpf(a)), mpmath.cos(mpmath.mpf(a)))):
            error = abs(mpmath.mpf(value) - truth)
            # 0.7 ulp of the result, or 4e-21 absolute next to a zero (see the module).
            assert error <= max(0.75 * np.spacing(abs(float(truth))), 4e-21), (a, value)


def test_sin_cos_keeps_signs_and_symmetry(rng):
    assert sin_cos(0.0) == (0.0, 1.0)
    assert np.signbit(sin_cos(-0.0)[0])
    for a in rng.uniform(0, 100, 200):
        s, c = sin_cos(a)
        assert sin_cos(-a) == (-s, c)


@pytest.mark.slow
def test_batch_form_equals_the_scalar_form_bit_for_bit(rng):
    for angles in (rng.uniform(-50, 50, 5000), _angles(rng)):   # the second has |a| > limit
        sines, cosines = angles.copy(), np.empty_like(angles)
        sin_cos_in_place_kernel(sines, cosines)
        expected = np.array([sin_cos(a) for a in angles])
        assert np.array_equal(sines, expected[:, 0]) and np.array_equal(cosines, expected[:, 1])


@pytest.mark.slow
def test_reduced_form_is_the_full_form_within_the_limit(rng):
    for a in rng.uniform(-REDUCTION_LIMIT, REDUCTION_LIMIT, 1000):
        assert reduced_sin_cos(a) == sin_cos(a)


@pytest.mark.parametrize('a', [1e6, -3e7, 1e300])
def test_beyond_the_limit_sin_cos_is_the_c_library_s(a):
    assert sin_cos(a) == (math.sin(a), math.cos(a))


# Where atan2's reduction changes interval, at 1 (the diagonal) and where the argument is scaled.
_INTERVAL_BOUNDARIES = [0.4375, 0.6875, 1.1875, 2.4375, 1.0, 0.5, 1.5]


def _atan2_arguments(rng):
    """(y, x) pairs: ordinary, near every interval boundary, tiny and huge ratios and sizes."""
    n = 400
    sign = rng.choice([-1.0, 1.0], (2, n))
    x = rng.uniform(0.1, 10, n)
    pairs = [rng.normal(size=(2, 2000)), sign * 10.0 ** rng.uniform(-300, 300, (2, n)),
             sign * 10.0 ** rng.uniform(-320, -300, (2, n)),       # subnormals
             sign * 10.0 ** rng.uniform(300, 308, (2, n))]          # beyond 2^1000
    for c in _INTERVAL_BOUNDARIES:
        pairs.append(sign * [c * x, x])                           # ratio on the boundary
        pairs.append(sign * [np.nextafter(c * x, 0), x])
        pairs.append(sign * [np.nextafter(c * x, np.inf), x])
        pairs.append(sign * [c * x * (1 + rng.uniform(-1e-6, 1e-6, n)), x])
    exact = np.array([0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 1e-310, 2.0 ** -900, 2.0 ** 1000,
                      1.7976931348623157e308, -1.7976931348623157e308, 2.5, 1e-20])
    grid_y, grid_x = np.meshgrid(exact, exact)
    pairs.append(np.array([grid_y.ravel(), grid_x.ravel()]))
    return np.concatenate(pairs, axis=1)


@pytest.mark.slow
def test_atan2_is_accurate_to_0_8_ulp(rng):
    # Zero arguments (signed zeros, which mpmath does not have) are the next test's.
    arguments = _atan2_arguments(rng)
    for y, x in arguments[:, arguments.all(axis=0)].T:
        got = atan2(y, x)
        truth = mpmath.atan2(mpmath.mpf(y), mpmath.mpf(x))
        error = abs(mpmath.mpf(got) - truth)
        assert error <= 0.8 * np.spacing(abs(float(truth))), (y, x, got)


@pytest.mark.parametrize('y', [0.0, -0.0, 1.0, -1.0, 1e-300, -3e300])
@pytest.mark.parametrize('x', [0.0, -0.0, 1.0, -1.0, 1e-300, -3e300])
def test_atan2_quadrant_boundaries_are_the_c_library_s(y, x):
    # Signed zeros, +-pi, +-pi/2, +-pi/4 and +-3 pi/4 exactly, with their signs.
    got, expected = atan2(y, x), math.atan2(y, x)
    assert got == expected and math.copysign(1.0, got) == math.copysign(1.0, expected)


def test_atan2_is_odd_in_y(rng):
    for y, x in _atan2_arguments(rng).T[::7]:
        assert atan2(-y, x) == -atan2(y, x)


@pytest.mark.slow
def test_atan2_batch_form_equals_the_scalar_form_bit_for_bit(rng):
    y, x = _atan2_arguments(rng)
    got = y.copy()
    atan2_in_place_kernel(got, x)
    expected = np.array([atan2(a, b) for a, b in zip(y, x)])
    assert np.array_equal(got, expected) and np.array_equal(np.signbit(got), np.signbit(expected))
