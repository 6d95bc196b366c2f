"""Tests of rotation_node.kinematics._integration: attitude integration, rates at stage times."""
import numpy as np
import pytest

from rotation_node import conversions as rc
from rotation_node import kinematics as rk
from rotation_node.kinematics._integration import _METHODS, _stage_rates
from rotation_node.kinematics._validation import sample_times
from test_kinematics_coning import coning_orientation, coning_rate

EPS = np.finfo(float).eps
NOMINAL_ORDER = {'euler': 1, 'midpoint_exp': 2, 'rk4': 4, 'magnus4': 4, 'coning2': 4}
DURATION = 2.0  # s of coning motion: 0.64 turns of the cone
ALL_NODES = np.array(sorted({c for _, nodes in _METHODS.values() for c in nodes}))


def coning_error(method, steps, source, frame='body'):
    """Largest geodesic error (rad) of integrated coning motion with ``steps`` steps."""
    t = np.linspace(0.0, DURATION, steps + 1)
    if source == 'function':
        def omega(times):
            return coning_rate(times, frame)
    else:
        omega = coning_rate(t, frame)
    q = rk.integrate_angular_velocity(coning_orientation(0.0), omega, t, method=method,
                                      frame=frame)
    return rc.quaternion_distance(q, coning_orientation(t)).max()


def test_methods_are_documented_ones():
    assert set(rk.INTEGRATION_METHODS) == set(NOMINAL_ORDER)


@pytest.mark.parametrize('source', ['function', 'samples'])
@pytest.mark.parametrize('method', sorted(NOMINAL_ORDER))
def test_convergence_order_on_coning_motion(method, source):
    """Halving the step divides the error by about 2, 4, 16, 16, 16."""
    coarse, fine = coning_error(method, 40, source), coning_error(method, 80, source)
    assert fine > 1e3 * EPS  # well above rounding, so the ratio measures truncation
    assert np.log2(coarse / fine) == pytest.approx(NOMINAL_ORDER[method], abs=0.3)


@pytest.mark.parametrize('method', sorted(NOMINAL_ORDER))
def test_world_frame_matches_body_frame(method):
    body = coning_error(method, 40, 'function', 'body')
    world = coning_error(method, 40, 'function', 'world')
    assert world == pytest.approx(body, rel=1e-6)


@pytest.mark.parametrize('frame', ['body', 'world'])
@pytest.mark.parametrize('method', ['midpoint_exp', 'magnus4', 'coning2'])
def test_exponential_methods_are_exact_for_constant_rate(rng, method, frame):
    t = np.cumsum(rng.uniform(0.05, 0.3, size=30))
    omega = np.array([0.4, -1.2, 2.5])
    q0 = rc.canonical_quaternion(rng.normal(size=4))
    q = rk.integrate_angular_velocity(q0, np.broadcast_to(omega, (30, 3)), t, method=method,
                                      frame=frame)
    step = rc.quaternion_from_rotation_vector(omega * (t - t[0])[:, None])
    truth = rc.quaternion_product(q0, step) if frame == 'body' else rc.quaternion_product(step, q0)
    assert rc.quaternion_distance(q, truth).max() < 1e-13


@pytest.mark.parametrize('method', sorted(NOMINAL_ORDER))
def test_output_is_unit_canonical_and_starts_at_q0(rng, method):
    q0 = np.array([0.2, -0.4, 0.1, -0.9]) * 3.0  # non-unit, w < 0
    t = np.linspace(0.0, 5.0, 51)
    q = rk.integrate_angular_velocity(q0, rng.normal(size=(51, 3)) * 3, t, method=method)
    assert q.shape == (51, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, rtol=0, atol=4 * EPS)
    assert (q[:, 3] >= 0).all()
    np.testing.assert_allclose(q[0], rc.canonical_quaternion(q0), rtol=0, atol=EPS)


def test_leading_dimensions_broadcast(rng):
    q0 = rc.canonical_quaternion(rng.normal(size=(3, 1, 4)))
    t = np.linspace(0.0, 1.0, 11)
    samples = rng.normal(size=(2, 11, 3))
    q = rk.integrate_angular_velocity(q0, samples, t, method='rk4')
    assert q.shape == (3, 2, 11, 4)
    np.testing.assert_array_equal(q[2, 1], rk.integrate_angular_velocity(q0[2, 0], samples[1], t,
                                                                         method='rk4'))


def test_function_is_called_once_with_the_stage_times():
    calls = []

    def omega(times):
        calls.append(times.copy())
        return np.zeros(times.shape + (3,))

    t = np.array([0.0, 1.0, 3.0])
    rk.integrate_angular_velocity([0, 0, 0, 1], omega, t, method='rk4')
    assert len(calls) == 1
    np.testing.assert_array_equal(calls[0], [0.0, 0.5, 1.0, 1.0, 2.0, 3.0])


def test_inputs_are_not_modified(rng):
    q0 = rng.normal(size=4)
    samples = rng.normal(size=(5, 3))
    t = np.arange(5.0)
    copies = q0.copy(), samples.copy(), t.copy()
    rk.integrate_angular_velocity(q0, samples, t, frame='world')
    for original, copy in zip((q0, samples, t), copies):
        np.testing.assert_array_equal(original, copy)


T3 = np.array([0.0, 0.1, 0.2])


@pytest.mark.parametrize('kwargs, message', [
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((3, 3)), 't': T3, 'method': 'rk45'},
     '`method` to be one of'),
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((3, 3)), 't': T3, 'method': None}, '`method`'),
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((3, 3)), 't': T3, 'frame': 'Body'}, '`frame`'),
    ({'q0': [0, 0, 0, 0], 'omega': np.zeros((3, 3)), 't': T3}, '`q0` has zero norm'),
    ({'q0': [0, 0, 1], 'omega': np.zeros((3, 3)), 't': T3}, r'`q0` to have shape \(\.\.\., 4\)'),
    ({'q0': [[0, 0, 0, 1], [np.nan, 0, 0, 1]], 'omega': np.zeros((3, 3)), 't': T3},
     r'`q0` at index \(1,\) has a NaN'),
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((2, 3)), 't': T3},
     r'`omega` samples of shape \(\.\.\., 3, 3\)'),
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((3, 2)), 't': T3},
     r'`omega` to have shape \(\.\.\., 3\)'),
    ({'q0': [0, 0, 0, 1], 'omega': [[0, 0, 0], [0, np.inf, 0], [0, 0, 0]], 't': T3},
     r'`omega` at index \(1,\) has a NaN or Inf'),
    ({'q0': [0, 0, 0, 1], 'omega': lambda times: np.zeros(3), 't': T3},
     r'`omega\(t\)` to return shape \(\.\.\., 4, 3\)'),
    ({'q0': [0, 0, 0, 1], 'method': 'euler', 't': T3,
      'omega': lambda times: np.where(times[:, None] > 0.05, np.nan, np.zeros(3))},
     r'`omega\(t\)` returned a NaN or Inf at t = 0.1'),
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((3, 3)), 't': [0.0, 0.2, 0.1]},
     '`t` to be strictly increasing'),
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((3, 3)), 't': [[0.0, 0.1, 0.2]]},
     r'`t` to have shape \(N,\)'),
    ({'q0': [0, 0, 0, 1], 'omega': np.zeros((1, 3)), 't': [0.0]}, 'N >= 2 samples'),
    ({'q0': np.ones((2, 4)), 'omega': np.zeros((3, 3, 3)), 't': T3}, 'do not broadcast'),
])
def test_bad_input_raises_naming_the_argument(kwargs, message):
    with pytest.raises(ValueError, match=message):
        rk.integrate_angular_velocity(**kwargs)


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
    rates = _stage_rates(f(t), t_checked, h, ALL_NODES)
    assert rates.shape == (n_samples - 1, len(ALL_NODES), 3)
    np.testing.assert_allclose(rates, f(stage_times(t, ALL_NODES)), rtol=1e-12, atol=1e-12)


def test_sample_times_return_the_samples_themselves(rng):
    t = np.cumsum(rng.uniform(0.2, 1.0, size=7))
    samples = rng.normal(size=(2, 7, 3))
    t_checked, h = sample_times(t)
    rates = _stage_rates(samples, t_checked, h, np.array([0.0, 1.0]))
    np.testing.assert_allclose(rates[..., 0, :], samples[:, :-1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(rates[..., 1, :], samples[:, 1:], rtol=0, atol=1e-15)


def test_interpolation_is_fourth_order():
    errors = []
    for n in (41, 81):
        t = np.linspace(0.0, 2.0, n)
        t_checked, h = sample_times(t)
        rates = _stage_rates(np.sin(3 * t)[:, None] * [1, 2, 3], t_checked, h, ALL_NODES)
        exact = np.sin(3 * stage_times(t, ALL_NODES))[..., None] * [1, 2, 3]
        errors.append(np.abs(rates - exact).max())
    assert np.log2(errors[0] / errors[1]) == pytest.approx(4.0, abs=0.3)


def test_function_values_are_used_as_returned(rng):
    t_checked, h = sample_times([0.0, 0.5, 2.0])
    f = polynomial(7, rng)
    rates = _stage_rates(lambda times: np.stack([f(times)] * 2), t_checked, h, ALL_NODES)
    assert rates.shape == (2, 2, len(ALL_NODES), 3)
    np.testing.assert_array_equal(rates[1], f(stage_times([0.0, 0.5, 2.0], ALL_NODES)))
