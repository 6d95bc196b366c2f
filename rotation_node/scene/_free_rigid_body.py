"""
Free rigid body integrator: Lie-Poisson splitting, fourth order.

The kinetic energy splits into one term per principal axis, ``T = sum_i L_i^2 / (2 I_i)``
(``L = I w``, the body angular momentum). The flow of one term alone is exact: ``L_i`` stays
constant, ``L`` rotates by ``-L_i t / I_i`` about ``e_i`` in the body and the attitude becomes
``q (x) exp(e_i L_i t / I_i)``. So every sub-flow keeps ``|L|`` and the world angular
momentum ``R L`` exactly (to round-off), and the composition is symplectic: the energy error
stays bounded. The Strang composition of the three axis flows is second order; Yoshida's
triple jump makes it fourth order.

References
----------
R. I. McLachlan, "Explicit Lie-Poisson integration and the Euler equations",
Phys. Rev. Lett. 71, 3043 (1993).
H. Yoshida, "Construction of higher order symplectic integrators",
Phys. Lett. A 150, 262 (1990).
F. Fasso, "Comparison of splitting algorithms for the rigid body",
J. Comput. Phys. 189, 527 (2003).

"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba
import numpy as np

if TYPE_CHECKING:
    from rotation_node.type_aliases import FloatArray, IntArray

#: Largest rotation (rad) the fastest axis flow makes in one internal step;
#: 1e-3 keeps the relative energy error near 1e-14 and the trajectory within
#: ~1e-12 of a tight DOP853 reference over 20 s (measured in the tests).
MAX_STEP_ANGLE = 1e-3


def _yoshida_axis_flows():
    """
    Return the axis flows of one fourth-order step as (axes, fractions of the step).

    Strang ``X0(h/2) X1(h/2) X2(h) X1(h/2) X0(h/2)`` composed as Yoshida's
    ``S(c1 h) S(c0 h) S(c1 h)``, adjacent flows about axis 0 merged.
    """
    c1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
    c0 = 1.0 - 2.0 * c1
    flows: list[tuple[int, float]] = []
    for c in (c1, c0, c1):
        for axis, fraction in ((0, c / 2), (1, c / 2), (2, c), (1, c / 2), (0, c / 2)):
            if flows and flows[-1][0] == axis:
                flows[-1] = (axis, flows[-1][1] + fraction)
            else:
                flows.append((axis, fraction))
    axes, fractions = zip(*flows)
    return np.array(axes, dtype=np.int64), np.array(fractions)


#: The fourth-order step: axis flows and their durations as fractions of the step.
AXES, FRACTIONS = _yoshida_axis_flows()


@numba.njit(cache=True)
def _axis_flow(q, momentum, inverse_inertia, axis, duration):
    """Advance (q, L) in place by the exact flow of ``L_axis^2 / (2 I_axis)``."""
    j, k = (axis + 1) % 3, (axis + 2) % 3
    angle = momentum[axis] * inverse_inertia[axis] * duration
    # Body angular momentum turns by -angle about e_axis.
    c, s = math.cos(angle), math.sin(angle)
    lj, lk = momentum[j], momentum[k]
    momentum[j], momentum[k] = c * lj + s * lk, c * lk - s * lj
    # Attitude: q (x) (sin(angle/2) e_axis, cos(angle/2)).
    c, s = math.cos(0.5 * angle), math.sin(0.5 * angle)
    qi, qj, qk, qw = q[axis], q[j], q[k], q[3]
    q[axis], q[j], q[k], q[3] = c * qi + s * qw, c * qj + s * qk, c * qk - s * qj, c * qw - s * qi


@numba.njit(cache=True)
def integrate(q0: FloatArray, momentum0: FloatArray, momentum_norm: float,
              inverse_inertia: FloatArray, t: FloatArray, substeps: int, axes: IntArray,
              fractions: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return a free rigid body's unit quaternions (n, 4) and body angular momenta (n, 3) at ``t``.

    From ``q0`` and ``momentum0 = I w`` at ``t[0]``, ``substeps`` steps of the flows
    ``axes``, ``fractions`` (``AXES``, ``FRACTIONS``) between samples. ``momentum_norm``, the
    ``|L|`` of the motion's start, is held exactly: integrating in pieces gives the same result.
    """
    n = t.shape[0]
    q_out = np.empty((n, 4))
    momentum_out = np.empty((n, 3))
    q = q0.copy()
    momentum = momentum0.copy()
    q_out[0] = q
    momentum_out[0] = momentum
    for sample in range(1, n):
        h = (t[sample] - t[sample - 1]) / substeps
        for _ in range(substeps):
            for flow in range(axes.shape[0]):
                _axis_flow(q, momentum, inverse_inertia, axes[flow], fractions[flow] * h)
        # The flows preserve |q| and |L| exactly; round-off alone moves them
        # (a bias of ~1e-18 per flow): put the state back on both spheres.
        q /= math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
        if momentum_norm > 0.0:
            momentum *= momentum_norm / math.sqrt(
                momentum[0] ** 2 + momentum[1] ** 2 + momentum[2] ** 2)
        q_out[sample] = q
        momentum_out[sample] = momentum
    return q_out, momentum_out
