"""
Angular velocity at the stage times ``t_k + c h_k`` of an integration method.

From a function, called once with all those times, or from samples at the step boundaries
read off the local cubic through the four nearest samples (Lagrange form, one-sided at the
ends; all samples when fewer than four): its error is ``O(h^4)``, so no method of order <= 4
loses its order on smooth sampled data.
"""
from __future__ import annotations

from typing import Callable, TYPE_CHECKING

import numpy as np

from ..conversions.kernels import float_array

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray


def _lagrange_stencils(t, h, nodes):
    """Return the stencils (K, P = min(N, 4)) and Lagrange weights (K, S, P) of the cubics."""
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


def stage_rates(omega: ArrayLike | Callable[[FloatArray], ArrayLike], t: FloatArray,
                h: FloatArray, nodes: FloatArray) -> FloatArray:
    """
    Return the angular velocity at ``t_k + nodes[s] h_k``, shape (..., N - 1, S, 3), all finite.

    ``omega`` is a function or samples at the validated times ``t`` (steps ``h``). A
    ValueError names a wrong shape or a NaN/Inf (for a function, the time it returned one at).
    """
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
