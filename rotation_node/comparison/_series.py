"""Two orientation series side by side: slerp at the other's stamps, errors, statistics."""
from __future__ import annotations

from typing import NamedTuple, Optional, Tuple, TYPE_CHECKING

import numpy as np

from .. import conversions
from ..errors import ComparisonError
from ..kinematics import slerp

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray

#: Default gap tolerance, in median sample steps of the interpolated series.
GAP_STEPS = 5.0


def checked_series(t: ArrayLike, q: ArrayLike, name: str) -> Tuple[FloatArray, FloatArray]:
    """Return ``(t, q)`` checked (ComparisonError) as float64 arrays, ``q`` unit and canonical."""
    times = np.asarray(t, dtype=np.float64)
    if times.ndim != 1 or times.size < 2:
        raise ComparisonError(f'{name}: expected at least 2 sample times, got shape {times.shape}')
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0.0):
        raise ComparisonError(f'{name}: sample times must be finite and strictly increasing')
    quaternions = np.asarray(q, dtype=np.float64)
    if quaternions.shape != times.shape + (4,):
        raise ComparisonError(f'{name}: expected quaternions of shape ({times.size}, 4), '
                              f'got {quaternions.shape}')
    try:
        return times, conversions.canonical_quaternion(quaternions)
    except ValueError as error:
        raise ComparisonError(f'{name}: {error}') from None


def median_step(t: FloatArray) -> float:
    """Median time between consecutive samples."""
    return float(np.median(np.diff(t)))


def interpolate_orientations(t: ArrayLike, q: ArrayLike, t_query: ArrayLike, *,
                             max_gap: Optional[float] = None) -> Tuple[np.ndarray, FloatArray]:
    """
    Slerp a stamped orientation series at other times, within a gap tolerance.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times (s), strictly increasing.
    q : array_like, shape (N, 4)
        Orientations (x, y, z, w) at ``t``.
    t_query : array_like, shape (K,)
        Where to interpolate.
    max_gap : float, optional
        Drop a query whose two neighbouring samples are further apart (s); default
        :data:`GAP_STEPS` median steps of ``t``.

    Returns
    -------
    valid : ndarray of bool, shape (K,)
        The queries inside ``[t[0], t[-1]]`` and not in a gap.
    quaternions : ndarray, shape (valid.sum(), 4)
        The orientations at ``t_query[valid]``; on a sample time, that sample exactly.

    """
    t, q = checked_series(t, q, 'series')
    query = np.asarray(t_query, dtype=np.float64).reshape(-1)
    gap = GAP_STEPS * median_step(t) if max_gap is None else float(max_gap)
    k = np.clip(np.searchsorted(t, query, side='right') - 1, 0, t.size - 2)
    valid = (query >= t[0]) & (query <= t[-1]) & (t[k + 1] - t[k] <= gap)
    k = k[valid]
    fraction = (query[valid] - t[k]) / (t[k + 1] - t[k])
    return valid, slerp(q[k], q[k + 1], fraction)


def orientation_errors(q_reference: ArrayLike, q_estimate: ArrayLike) -> FloatArray:
    """
    Rotation vectors of the error rotations between two orientation series.

    ``E = q_ref* (x) q_est`` (``R_est = R_ref E``) turns the reference body frame: its
    rotation vector holds the errors about the reference body's x, y and z axes, its norm the
    error angle (the geodesic distance).

    Parameters
    ----------
    q_reference, q_estimate : array_like, shape (..., 4)
        Orientations (x, y, z, w), body to world; leading dimensions broadcast.

    Returns
    -------
    ndarray, shape (..., 3)
        Rotation vectors (rad), norm in [0, pi].

    """
    return conversions.rotation_vector_from_quaternion(conversions.quaternion_product(
        conversions.quaternion_conjugate(q_reference), q_estimate))


class ErrorStatistics(NamedTuple):
    """Statistics of error rotation vectors (radians): of their angle, and per body axis."""

    rmse: float
    mean: float
    median: float
    p95: float
    maximum: float
    axis_rmse: FloatArray
    axis_maximum: FloatArray


def error_statistics(errors: ArrayLike) -> ErrorStatistics:
    """
    Statistics of the error angles and of each axis' error.

    Parameters
    ----------
    errors : array_like, shape (N, 3)
        Error rotation vectors (:func:`orientation_errors`), N >= 1.

    Returns
    -------
    ErrorStatistics
        Of the angles ``|e|``: root mean square, mean, median, 95th percentile (as
        ``numpy.percentile``), maximum; per axis: root mean square and maximum of ``|e_i|``.

    """
    e = np.asarray(errors, dtype=np.float64)
    if e.ndim != 2 or e.shape[1] != 3 or e.shape[0] == 0:
        raise ComparisonError(f'expected error vectors of shape (N >= 1, 3), got {e.shape}')
    angle = np.linalg.norm(e, axis=1)
    return ErrorStatistics(
        rmse=float(np.sqrt(np.mean(angle ** 2))), mean=float(np.mean(angle)),
        median=float(np.median(angle)), p95=float(np.percentile(angle, 95.0)),
        maximum=float(np.max(angle)), axis_rmse=np.sqrt(np.mean(e ** 2, axis=0)),
        axis_maximum=np.max(np.abs(e), axis=0))
