"""
Coning motion: the analytic ground truth for the kinematics tests (docs/numerics.md).

Written scalar first there; here scalar last, as everywhere in the package:
``q(t) = (sin(a/2) cos(W t), sin(a/2) sin(W t), 0, cos(a/2))``,
``w_b(t) = (-W sin a sin(W t), W sin a cos(W t), -W (1 - cos a))``.
The test below checks the pair against ``qdot = 1/2 q (x) (w_b, 0)`` with an
independent numpy Hamilton product, so the other tests can trust it.
"""
import numpy as np
import pytest

from rotation_node import conversions as rc

CONE_HALF_ANGLE, CONE_RATE = 0.3, 2.0


def coning_orientation(t):
    """Orientations (..., 4), scalar last, at the times ``t``."""
    t = np.asarray(t, dtype=float)
    s = np.sin(CONE_HALF_ANGLE / 2)
    return np.stack([s * np.cos(CONE_RATE * t), s * np.sin(CONE_RATE * t), np.zeros_like(t),
                     np.full_like(t, np.cos(CONE_HALF_ANGLE / 2))], axis=-1)


def coning_rate(t, frame='body'):
    """Angular velocity (..., 3) in ``frame`` at the times ``t``."""
    t = np.asarray(t, dtype=float)
    a, W = CONE_HALF_ANGLE, CONE_RATE
    body = np.stack([-W * np.sin(a) * np.sin(W * t), W * np.sin(a) * np.cos(W * t),
                     np.full_like(t, -W * (1 - np.cos(a)))], axis=-1)
    return body if frame == 'body' else rc.rotate_vector(coning_orientation(t), body)


def hamilton(p, q):
    """Return the reference Hamilton product, scalar last, written out with numpy."""
    pv, ps, qv, qs = p[..., :3], p[..., 3:], q[..., :3], q[..., 3:]
    return np.concatenate([ps * qv + qs * pv + np.cross(pv, qv),
                           ps * qs - np.sum(pv * qv, axis=-1, keepdims=True)], axis=-1)


@pytest.mark.parametrize('frame', ['body', 'world'])
def test_coning_truth_satisfies_the_kinematic_equation(frame):
    t = np.linspace(0.0, 3.0, 31)
    h = 1e-5
    q_dot = (coning_orientation(t + h) - coning_orientation(t - h)) / (2 * h)
    pure = np.concatenate([coning_rate(t, frame), np.zeros((31, 1))], axis=-1)
    q = coning_orientation(t)
    expected = 0.5 * (hamilton(q, pure) if frame == 'body' else hamilton(pure, q))
    np.testing.assert_allclose(q_dot, expected, rtol=0, atol=1e-10)
