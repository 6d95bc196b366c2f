"""
Attitude integration: orientations from angular velocity.

Solves ``qdot = 1/2 q (x) (w_b(t), 0)`` from ``q(t_0) = q0`` (the world frame is the body
problem of ``q*`` with rate ``-w_w``). The rate multiplies from the right, so every method
steps as ``q_{k+1} = normalise(q_k (x) dq_k)`` with an increment ``dq_k`` made of the rates
within the step (normalising the product equals normalising ``dq_k`` first):

==================  =====  ========================  ========================================
method              order  rates per step, at t_k +  increment ``dq``
==================  =====  ========================  ========================================
``'euler'``         1      1: ``0``                  ``(h/2 w(t_k), 1)``: forward Euler
``'midpoint_exp'``  2      1: ``h/2``                ``exp(h w(t_k + h/2))``
``'rk4'``           4      3: ``0, h/2, h``          classical RK4 (4 stages, the midpoint
                                                     rate used twice)
``'magnus4'``       4      2: Gauss points           ``exp(h/2 (w1 + w2)
                           ``(1/2 -+ sqrt(3)/6) h``  + sqrt(3)/12 h^2 w1 x w2)``
``'coning2'``       4      4: Gauss points of each   ``exp(d1 + d2 + 2/3 d1 x d2)``, ``d1``,
                           half step                 ``d2`` the half-step angle increments
==================  =====  ========================  ========================================

``exp`` is the rotation-vector-to-quaternion map. Magnus-4 uses the two-point Gauss rule [1]_
(its commutator's sign is that of right multiplication, ``Y' = Y A``); the two-sample coning
algorithm [2]_ gets its angle increments by Gauss quadrature (exact for cubic rates).

References
----------
.. [1] A. Iserles and S. P. Norsett, "On the solution of linear differential
   equations in Lie groups", Phil. Trans. R. Soc. A 357, 1999.
.. [2] R. B. Miller, "A new strapdown attitude algorithm", J. Guidance,
   Control, and Dynamics 6(4), 1983.

"""
from __future__ import annotations

import math
from typing import Callable, TYPE_CHECKING

import numpy as np

from ._validation import is_world_frame, sample_times
from ..conversions.kernels import (
    array_type, canonical_kernel, canonical_unit_quaternion, FLAT_IN, float_array, INT, jit,
    kernel, kernel_ready, product, quaternion_from_rotation_vector_scalar, raise_sample_error,
    ROWS_IN)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray

_GAUSS = math.sqrt(3.0) / 6.0  # Gauss-Legendre nodes on [0, 1]: 1/2 -+ sqrt(3)/6

EULER, MIDPOINT_EXP, RK4, MAGNUS4, CONING2 = range(5)

# name: (kernel code, stage fractions of the step)
_METHODS = {
    'euler': (EULER, (0.0,)),
    'midpoint_exp': (MIDPOINT_EXP, (0.5,)),
    'rk4': (RK4, (0.0, 0.5, 1.0)),
    'magnus4': (MAGNUS4, (0.5 - _GAUSS, 0.5 + _GAUSS)),
    'coning2': (CONING2, (0.5 * (0.5 - _GAUSS), 0.5 * (0.5 + _GAUSS),
                          0.5 * (1.5 - _GAUSS), 0.5 * (1.5 + _GAUSS))),
}

#: The methods of :func:`integrate_angular_velocity`.
INTEGRATION_METHODS = tuple(_METHODS)


@jit
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@jit
def _rk4_stage(kx, ky, kz, kw, c, r):
    """``(1 + c K) (x) (r/2, 0)``: the next RK4 stage as a right multiplier."""
    return product(c * kx, c * ky, c * kz, 1.0 + c * kw, 0.5 * r[0], 0.5 * r[1], 0.5 * r[2], 0.0)


@jit
def _increment(method, h, r):
    """Increment quaternion ``dq`` of a step of length ``h`` from the stage rates ``r`` (S, 3)."""
    if method == EULER:
        return 0.5 * h * r[0, 0], 0.5 * h * r[0, 1], 0.5 * h * r[0, 2], 1.0
    if method == MIDPOINT_EXP:
        return quaternion_from_rotation_vector_scalar(h * r[0, 0], h * r[0, 1], h * r[0, 2])
    if method == RK4:
        k1x, k1y, k1z, k1w = 0.5 * r[0, 0], 0.5 * r[0, 1], 0.5 * r[0, 2], 0.0
        k2x, k2y, k2z, k2w = _rk4_stage(k1x, k1y, k1z, k1w, 0.5 * h, r[1])
        k3x, k3y, k3z, k3w = _rk4_stage(k2x, k2y, k2z, k2w, 0.5 * h, r[1])
        k4x, k4y, k4z, k4w = _rk4_stage(k3x, k3y, k3z, k3w, h, r[2])
        c = h / 6.0
        return (c * (k1x + 2.0 * (k2x + k3x) + k4x), c * (k1y + 2.0 * (k2y + k3y) + k4y),
                c * (k1z + 2.0 * (k2z + k3z) + k4z), 1.0 + c * (k1w + 2.0 * (k2w + k3w) + k4w))
    if method == MAGNUS4:
        a, b = r[0], r[1]
        cx, cy, cz = _cross(a[0], a[1], a[2], b[0], b[1], b[2])
        m = math.sqrt(3.0) / 12.0 * h * h
        return quaternion_from_rotation_vector_scalar(0.5 * h * (a[0] + b[0]) + m * cx,
                                                      0.5 * h * (a[1] + b[1]) + m * cy,
                                                      0.5 * h * (a[2] + b[2]) + m * cz)
    # CONING2: angle increments of the two half steps by 2-point Gauss quadrature
    d1x, d1y, d1z = (0.25 * h * (r[0, 0] + r[1, 0]), 0.25 * h * (r[0, 1] + r[1, 1]),
                     0.25 * h * (r[0, 2] + r[1, 2]))
    d2x, d2y, d2z = (0.25 * h * (r[2, 0] + r[3, 0]), 0.25 * h * (r[2, 1] + r[3, 1]),
                     0.25 * h * (r[2, 2] + r[3, 2]))
    cx, cy, cz = _cross(d1x, d1y, d1z, d2x, d2y, d2z)
    return quaternion_from_rotation_vector_scalar(d1x + d2x + 2.0 / 3.0 * cx,
                                                  d1y + d2y + 2.0 / 3.0 * cy,
                                                  d1z + d2z + 2.0 / 3.0 * cz)


@kernel(ROWS_IN, array_type(4), FLAT_IN, array_type(3), INT, returns=None)
def _integrate_kernel(q0, rates, h, out, method):
    """Chain the steps from unit ``q0`` (B, 4): ``rates`` (B, K, S, 3) -> ``out`` (B, K + 1, 4)."""
    for b in range(q0.shape[0]):
        x, y, z, w = q0[b, 0], q0[b, 1], q0[b, 2], q0[b, 3]
        out[b, 0, 0], out[b, 0, 1], out[b, 0, 2], out[b, 0, 3] = x, y, z, w
        for k in range(h.shape[0]):
            dx, dy, dz, dw = _increment(method, h[k], rates[b, k])
            x, y, z, w = product(x, y, z, w, dx, dy, dz, dw)
            x, y, z, w = canonical_unit_quaternion(x, y, z, w)
            out[b, k + 1, 0], out[b, k + 1, 1], out[b, k + 1, 2], out[b, k + 1, 3] = x, y, z, w


def _lagrange_stencils(t, h, nodes):
    """Return the stencils (K, P = min(N, 4)) and weights (K, S, P) of the local cubics."""
    n = t.shape[0]
    points = min(n, 4)
    start = np.clip(np.arange(n - 1) - 1, 0, n - points)
    stencil = start[:, None] + np.arange(points)
    # Times relative to t_k: exact zeros at the stencil's own nodes, no epoch rounding.
    offsets = t[stencil] - t[:-1, None]                                # (K, P)
    x = nodes[None, :] * h[:, None]                                   # (K, S)
    weights = np.ones(x.shape + (points,))
    for m in range(points):
        for other in range(points):
            if other != m:
                weights[:, :, m] *= ((x - offsets[:, None, other])
                                     / (offsets[:, None, m] - offsets[:, None, other]))
    return stencil, weights


def _first_non_finite(values):
    """Index (leading dimensions) of the first vector with a NaN or Inf, or None."""
    bad = ~np.isfinite(values).all(axis=-1)
    if not bad.any():
        return None
    return tuple(int(i) for i in np.unravel_index(np.flatnonzero(bad)[0], bad.shape))


def _stage_rates(omega: ArrayLike | Callable[[FloatArray], ArrayLike], t: FloatArray,
                 h: FloatArray, nodes: FloatArray) -> FloatArray:
    """Return ``omega`` at ``t_k + nodes[s] h_k``, (..., N - 1, S, 3), else a ValueError."""
    steps, stages = h.shape[0], nodes.shape[0]
    if callable(omega):
        times = (t[:-1, None] + nodes[None, :] * h[:, None]).ravel()
        rates = np.asarray(omega(times), dtype=np.float64)
        if rates.shape[-2:] != (times.shape[0], 3):
            raise ValueError(
                f'Expected `omega(t)` to return shape (..., {times.shape[0]}, 3) for t of shape '
                f'({times.shape[0]},), got {rates.shape} (a constant w: '
                f'np.broadcast_to(w, t.shape + (3,))).')
        bad = _first_non_finite(rates)
        if bad is not None:
            raise ValueError(f'`omega(t)` returned a NaN or Inf at t = {float(times[bad[-1]])!r}.')
        return rates.reshape(rates.shape[:-2] + (steps, stages, 3))
    samples = float_array(omega, 'omega', (3,))
    if samples.ndim < 2 or samples.shape[-2] != t.shape[0]:
        raise ValueError(f'Expected `omega` samples of shape (..., {t.shape[0]}, 3) to match `t`, '
                         f'got {samples.shape}.')
    bad = _first_non_finite(samples)
    if bad is not None:
        raise ValueError(f'`omega` at index {bad} has a NaN or Inf component.')
    stencil, weights = _lagrange_stencils(t, h, nodes)
    return np.einsum('ksp,...kpd->...ksd', weights, samples[..., stencil, :])


def _broadcast(a, shape):
    """Return ``a`` broadcast to ``shape``, C-contiguous and writable: a copy only where needed."""
    return kernel_ready(a if a.shape == shape else np.broadcast_to(a, shape))


def integrate_angular_velocity(q0: ArrayLike,
                               omega: ArrayLike | Callable[[FloatArray], ArrayLike],
                               t: ArrayLike, *, method: str = 'magnus4',
                               frame: str = 'body') -> FloatArray:
    """
    Integrate angular velocity into orientations.

    Parameters
    ----------
    q0 : array_like, shape (..., 4)
        Orientation (x, y, z, w), body-to-world, at ``t[0]``; any non-zero norm.
    omega : callable or array_like
        Angular velocity (rad/s) in ``frame``: a function ``omega(times)``, called once with
        the stage times of all steps (non-decreasing, shape (M,)) and returning shape
        (..., M, 3); or samples of shape (..., N, 3) at ``t`` (a gyro), read between samples
        off the local cubic through the four nearest (``O(h^4)``: every method keeps its
        order on smooth data).
    t : array_like, shape (N,)
        Times (s), strictly increasing, N >= 2: the steps and the output times.
    method : {'magnus4', 'rk4', 'coning2', 'midpoint_exp', 'euler'}, optional
        See the module docstring: orders 4, 4, 4, 2, 1 with 2, 3, 4, 1, 1 rate evaluations
        per step. ``'magnus4'`` (default) is the most accurate per rate evaluation.
    frame : {'body', 'world'}, optional
        Frame of ``omega``: ``qdot = 1/2 q (x) (w_b, 0)`` or ``1/2 (w_w, 0) (x) q``.

    Returns
    -------
    ndarray, shape (..., N, 4)
        Unit canonical (``w >= 0``) orientations at ``t``, the first ``q0`` normalised;
        leading dimensions those of ``q0`` and ``omega`` broadcast.

    Raises
    ------
    ValueError
        Unknown ``method`` or ``frame``; bad ``q0``, ``t`` or ``omega`` (wrong shape, NaN/Inf,
        zero quaternion, times not strictly increasing, leading shapes that do not broadcast).

    """
    try:
        code, nodes = _METHODS[method]
    except (KeyError, TypeError):
        raise ValueError(f'Expected `method` to be one of {", ".join(INTEGRATION_METHODS)}, '
                         f'got {method!r}.') from None
    world = is_world_frame(frame)
    q0 = float_array(q0, 'q0', (4,))
    q = np.empty(q0.shape)
    bad = canonical_kernel(q0.reshape(-1), q.reshape(-1))
    if bad >= 0:
        raise_sample_error(bad, ('q0',), (q0,), ((4,),))
    t, h = sample_times(t)
    rates = _stage_rates(omega, t, h, np.asarray(nodes))
    if world:  # the body problem of q*: rate -w_w
        q, rates = q * np.array([-1.0, -1.0, -1.0, 1.0]), -rates
    try:
        lead = np.broadcast_shapes(q.shape[:-1], rates.shape[:-3])
    except ValueError:
        raise ValueError(f'Leading shapes of `q0` {q.shape[:-1]} and `omega` {rates.shape[:-3]} '
                         'do not broadcast.') from None
    q, rates = _broadcast(q, lead + (4,)), _broadcast(rates, lead + rates.shape[-3:])
    out = np.empty(lead + (t.shape[0], 4))
    # One compiled specialisation: the kernel sees (B, ...) views of the broadcast arrays.
    _integrate_kernel(q.reshape(-1, 4), rates.reshape((-1,) + rates.shape[-3:]), h,
                      out.reshape(-1, t.shape[0], 4), code)
    if world:
        out[..., :3] *= -1.0
    return out
