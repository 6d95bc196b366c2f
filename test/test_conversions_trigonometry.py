"""Tests of rotation_node.conversions._trigonometry: the branch-free sin and cos."""
import math

import mpmath
import numpy as np
import pytest

from rotation_node.conversions._trigonometry import (REDUCTION_LIMIT, reduced_sin_cos, sin_cos,
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


def test_batch_form_equals_the_scalar_form_bit_for_bit(rng):
    for angles in (rng.uniform(-50, 50, 5000), _angles(rng)):   # the second has |a| > limit
        sines, cosines = angles.copy(), np.empty_like(angles)
        sin_cos_in_place_kernel(sines, cosines)
        expected = np.array([sin_cos(a) for a in angles])
        assert np.array_equal(sines, expected[:, 0]) and np.array_equal(cosines, expected[:, 1])


def test_reduced_form_is_the_full_form_within_the_limit(rng):
    for a in rng.uniform(-REDUCTION_LIMIT, REDUCTION_LIMIT, 1000):
        assert reduced_sin_cos(a) == sin_cos(a)


@pytest.mark.parametrize('a', [1e6, -3e7, 1e300])
def test_beyond_the_limit_sin_cos_is_the_c_library_s(a):
    assert sin_cos(a) == (math.sin(a), math.cos(a))
