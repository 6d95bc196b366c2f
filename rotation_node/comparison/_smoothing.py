"""
Gaussian-weighted local polynomial fits of a stamped series, at any times.

Slerp between noisy samples has a noise variance that depends on the fraction ``u`` between
them, which pulls a least-squares time offset towards half a step; a Gaussian fit of
bandwidth >= one step has the same variance at every ``u`` (to ~1e-9) and a symmetric window.
Orientations are fitted (quadratic) in the tangent space of the sample nearest each query,
vectors (angular rates) directly (linear).
"""
from __future__ import annotations

from typing import NamedTuple, Tuple, TYPE_CHECKING

import numpy as np

from .. import conversions

if TYPE_CHECKING:
    from ..type_aliases import FloatArray

#: Half width of the window, in bandwidths (weights below exp(-12.5) ~ 4e-6 are left out).
WINDOW_BANDWIDTHS = 5.0
#: A fit needs at least this many samples within 3 bandwidths of the query, on both sides.
MIN_SAMPLES = 4
#: Queries fitted at a time (bounds the memory of long records).
CHUNK = 8192


class _Windows(NamedTuple):
    valid: np.ndarray      # (K,) queries with enough samples around them
    centre: np.ndarray     # (k,) index of the sample nearest to each valid query
    samples: np.ndarray    # (k, W) sample indices of each window
    weight: FloatArray     # (k, W) Gaussian weights, 0 outside the series
    offset: FloatArray     # (k, W) (t_sample - t_query) / bandwidth


def _windows(t: FloatArray, query: FloatArray, bandwidth: float) -> _Windows:
    steps = int(np.ceil(1.5 * WINDOW_BANDWIDTHS * bandwidth / np.median(np.diff(t)))) + 1
    steps = min(steps, t.size)
    right = np.clip(np.searchsorted(t, query), 1, t.size - 1)
    centre = np.where(query - t[right - 1] <= t[right] - query, right - 1, right)
    index = centre[:, None] + np.arange(-steps, steps + 1)
    inside = (index >= 0) & (index < t.size)
    index = np.clip(index, 0, t.size - 1)
    offset = (t[index] - query[:, None]) / bandwidth
    near = inside & (np.abs(offset) <= WINDOW_BANDWIDTHS)
    weight = np.where(near, np.exp(-0.5 * offset ** 2), 0.0)
    close = inside & (np.abs(offset) <= 3.0)
    valid = ((query >= t[0]) & (query <= t[-1]) & (np.sum(close, axis=1) >= MIN_SAMPLES)
             & np.any(close & (offset <= 0.0), axis=1) & np.any(close & (offset >= 0.0), axis=1))
    return _Windows(valid, centre[valid], index[valid], weight[valid], offset[valid])


def _fit(window: _Windows, values: FloatArray, degree: int) -> FloatArray:
    """Weighted least squares coefficients ``(k, degree + 1, m)`` of ``values (k, W, m)``."""
    powers = [np.ones_like(window.offset)]
    for _ in range(degree):
        powers.append(powers[-1] * window.offset)
    basis = np.stack(powers, axis=1)                                    # (k, d, W)
    weighted = basis * window.weight[:, None, :]
    normal = weighted @ np.swapaxes(basis, 1, 2)                        # (k, d, d)
    return np.asarray(np.linalg.solve(normal, weighted @ values), dtype=np.float64)


def _in_chunks(fit, query):
    """Apply ``fit(query_chunk) -> (valid, values)`` to bounded chunks: memory stays flat."""
    valid, values = [], []
    for start in range(0, max(query.size, 1), CHUNK):
        chunk_valid, chunk_values = fit(query[start:start + CHUNK])
        valid.append(chunk_valid)
        values.append(chunk_values)
    return np.concatenate(valid), np.concatenate(values)


def smoothed_vectors(t: FloatArray, v: FloatArray, query: FloatArray,
                     bandwidth: float) -> Tuple[np.ndarray, FloatArray]:
    """
    Local linear fit of vectors ``v (N, m)`` at ``query``: ``(valid (K,), values (k, m))``.

    Valid: queries with samples on both sides within three bandwidths (four at least).
    """
    def fit(chunk):
        window = _windows(t, chunk, bandwidth)
        return window.valid, _fit(window, v[window.samples], 1)[:, 0, :]
    return _in_chunks(fit, query)


def smoothed_orientations(t: FloatArray, q: FloatArray, query: FloatArray,
                          bandwidth: float) -> Tuple[np.ndarray, FloatArray]:
    """
    Local quadratic fit of unit quaternions ``q (N, 4)`` at ``query``: ``(valid, quaternions)``.

    ``q_c exp(a)``, ``q_c`` the nearest sample, ``a`` the fitted ``log(q_c* q_j)``.
    """
    def fit(chunk):
        window = _windows(t, chunk, bandwidth)
        centre = q[window.centre]
        tangent = conversions.rotation_vector_from_quaternion(conversions.quaternion_product(
            conversions.quaternion_conjugate(centre)[:, None, :], q[window.samples]))
        value = _fit(window, tangent, 2)[:, 0, :]
        return window.valid, conversions.canonical_quaternion(conversions.quaternion_product(
            centre, conversions.quaternion_from_rotation_vector(value)))
    return _in_chunks(fit, query)
