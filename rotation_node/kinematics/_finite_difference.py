"""
Angular velocity from a time series of orientations by finite differences, and slerp.

The rotation vector (``atan2`` log map, the shorter way round) of ``q_k^-1 q_{k+1}`` (body) or
``q_{k+1} q_k^-1`` (world) over the step is, by the Magnus expansion, ``h w(t_k + h/2) +
O(h^3)``: second order at the midpoint, exact for a constant rate, aliased once ``|w| h >= pi``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ._validation import is_world_frame, sample_times
from .. import conversions
from ..conversions.kernels import (
    BOOL, FLAT_IN, FLAT_OUT, float_array, kernel, product, quaternion_status, raise_sample_error,
    rotation_vector_from_quaternion_scalar, samples, scaled_quaternion)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT, BOOL)
def _finite_difference_kernel(q, h, out, world):
    n = h.shape[0] + 1
    fq, fo = samples(q, 4), samples(out, 3)
    for series in range(fq.shape[0] // n):
        first = series * n
        bad = quaternion_status(fq, first, 0)
        if bad >= 0:
            return bad
        px, py, pz, pw = scaled_quaternion(fq[first, 0], fq[first, 1], fq[first, 2], fq[first, 3])
        for k in range(n - 1):
            s = first + k + 1
            bad = quaternion_status(fq, s, 0)
            if bad >= 0:
                return bad
            qx, qy, qz, qw = scaled_quaternion(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
            if world:  # q_{k+1} (x) q_k*
                rx, ry, rz, rw = product(qx, qy, qz, qw, -px, -py, -pz, pw)
            else:  # q_k* (x) q_{k+1}
                rx, ry, rz, rw = product(-px, -py, -pz, pw, qx, qy, qz, qw)
            vx, vy, vz = rotation_vector_from_quaternion_scalar(rx, ry, rz, rw)
            o = series * (n - 1) + k
            fo[o, 0], fo[o, 1], fo[o, 2] = vx / h[k], vy / h[k], vz / h[k]
            px, py, pz, pw = qx, qy, qz, qw
    return -1


def angular_velocity_from_quaternions(q: ArrayLike, t: ArrayLike,
                                      frame: str = 'body') -> FloatArray:
    """
    Angular velocity between consecutive orientations of a time series.

    Parameters
    ----------
    q : array_like, shape (..., N, 4)
        Orientations (x, y, z, w), body-to-world, at the times ``t``; any non-zero norm and
        either sign per sample (sign flips between samples do no harm).
    t : array_like, shape (N,)
        Sample times (s), strictly increasing, N >= 2. The steps are computed in float64:
        pass times from a recent origin (seconds since the epoch round to ~2e-7 s).
    frame : {'body', 'world'}, optional
        ``'body'``: ``w_b = log(q_k^-1 q_{k+1}) / h_k``; ``'world'``:
        ``w_w = log(q_{k+1} q_k^-1) / h_k``.

    Returns
    -------
    ndarray, shape (..., N - 1, 3)
        Angular velocity (rad/s) in ``frame`` over each step, at the midpoint times
        ``(t[:-1] + t[1:]) / 2``: second order there, exact for a constant rate. Two samples
        give one value: ``angular_velocity_from_quaternions([q_prev, q], [t_prev, t])[0]``.
        A rotation of pi or more per step aliases to the shorter way round.

    Raises
    ------
    ValueError
        Bad ``frame``; ``q`` not (..., N, 4), or with a NaN/Inf or zero sample; ``t`` of the wrong
        shape, NaN/Inf or not strictly increasing.

    """
    world = is_world_frame(frame)
    a = float_array(q, 'q', (4,))
    if a.ndim < 2:
        raise ValueError(f'Expected `q` to have shape (..., N, 4) (a time series), got {a.shape}.')
    _, h = sample_times(t, a.shape[-2], 'q')
    out = np.empty(a.shape[:-2] + (a.shape[-2] - 1, 3))
    bad = _finite_difference_kernel(a.reshape(-1), h, out.reshape(-1), world)
    if bad >= 0:
        raise_sample_error(bad, ('q',), (a,), ((4,),))
    return out


def slerp(q0: ArrayLike, q1: ArrayLike, fraction: ArrayLike) -> FloatArray:
    """
    Spherical linear interpolation, the shorter way: ``q0 (x) exp(u log(q0* (x) q1))``.

    Through the ``atan2`` exponential and logarithm maps: stable for nearly equal quaternions,
    where ``acos`` of the dot product loses half the digits.

    Parameters
    ----------
    q0, q1 : array_like, shape (..., 4)
        Unit quaternions (x, y, z, w); either sign.
    fraction : array_like, shape (...)
        ``u``: 0 gives ``q0`` (exactly, canonical), 1 gives ``q1`` (to rounding).

    Returns
    -------
    ndarray, shape (..., 4)
        Unit canonical quaternions.

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf, or a zero quaternion.

    """
    q0 = conversions.canonical_quaternion(q0)
    step = conversions.rotation_vector_from_quaternion(
        conversions.quaternion_product(conversions.quaternion_conjugate(q0), q1))
    part = conversions.quaternion_from_rotation_vector(
        step * np.asarray(fraction, dtype=np.float64)[..., None])
    return conversions.canonical_quaternion(conversions.quaternion_product(q0, part))
