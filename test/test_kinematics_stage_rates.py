"""Tests of rotation_node.kinematics._stage_rates: rates at the integrators' stage times."""
import numpy as np
import pytest

from rotation_node.kinematics._integration import _METHODS
from rotation_node.kinematics._stage_rates import stage_rates
from rotation_node.kinematics._validation import sample_times

ALL_NODES = np.array(sorted({c for _, nodes in _METHODS.values() for c in nodes}))


def polynomial(degree, rng):
    """Return a random vector polynomial of ``degree`` as a function of time, shape (..., 3)."""
    coefficients = rng.normal(size=(degree + 1, 3))
    return lambda times: np.moveaxis(np.polynomial.polynomial.polyval(times, coefficients), 0, -1)


def stage_times(t, nodes):
    t, h = sample_times(t)
    return t[:-1, None] + nodes[None, :] * h[:, None]


@pytest.mark.parametrize('n_samples, degree', [(2, 1), (3, 2), (4, 3), (9, 3)])
def test_samples_are_read_off_the_local_polynomial_exactly(rng, n_samples, degree):
    """Exact for polynomials up to degree min(N, 4) - 1 on a non-uniform grid."""
    t = np.cumsum(rng.uniform(0.2, 1.0, size=n_samples))
    f = polynomial(degree, rng)
    t_checked, h = sample_times(t)
    rates = stage_rates(f(t), t_checked, h, ALL_NODES)
    assert rates.shape == (n_samples - 1, len(ALL_NODES), 3)
    np.testing.assert_allclose(rates, f(stage_times(t, ALL_NODES)), rtol=1e-12, atol=1e-12)


def test_sample_times_return_the_samples_themselves(rng):
    t = np.cumsum(rng.uniform(0.2, 1.0, size=7))
    samples = rng.normal(size=(2, 7, 3))
    t_checked, h = sample_times(t)
    rates = stage_rates(samples, t_checked, h, np.array([0.0, 1.0]))
    np.testing.assert_allclose(rates[..., 0, :], samples[:, :-1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(rates[..., 1, :], samples[:, 1:], rtol=0, atol=1e-15)


def test_interpolation_is_fourth_order():
    errors = []
    for n in (41, 81):
        t = np.linspace(0.0, 2.0, n)
        t_checked, h = sample_times(t)
        rates = stage_rates(np.sin(3 * t)[:, None] * [1, 2, 3], t_checked, h, ALL_NODES)
        exact = np.sin(3 * stage_times(t, ALL_NODES))[..., None] * [1, 2, 3]
        errors.append(np.abs(rates - exact).max())
    assert np.log2(errors[0] / errors[1]) == pytest.approx(4.0, abs=0.3)


def test_function_values_are_used_as_returned(rng):
    t_checked, h = sample_times([0.0, 0.5, 2.0])
    f = polynomial(7, rng)
    rates = stage_rates(lambda times: np.stack([f(times)] * 2), t_checked, h, ALL_NODES)
    assert rates.shape == (2, 2, len(ALL_NODES), 3)
    np.testing.assert_array_equal(rates[1], f(stage_times([0.0, 0.5, 2.0], ALL_NODES)))
