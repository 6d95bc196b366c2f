"""
The time offset between two orientation streams, from their angular rate magnitudes.

``|w_ref(t)| = |w_est(t + dt)|`` whatever ``W`` and ``M``. Both magnitudes, smoothed with
one Gaussian on a uniform grid, are cross-correlated (over lags where they overlap by half
the shorter); a peak is refined with a parabola, then by least squares in continuous ``dt``,
whose curvature gives the standard deviation. A motion whose rate magnitude repeats has a
peak every period: :func:`time_offset_candidates` returns the best few, and
:func:`~rotation_node.comparison.estimate_alignment` keeps the one where the orientations agree.
"""
from __future__ import annotations

from typing import List, NamedTuple, Optional, Tuple, TYPE_CHECKING

import numpy as np

from ._series import checked_series, median_step
from ._smoothing import smoothed_vectors
from .. import kinematics
from ..errors import ComparisonError, DegenerateMotionError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray

#: Below this standard deviation of the smoothed rate magnitude (rad/s) a stream
#: holds too little motion to time it.
MIN_RATE_VARIATION = 0.02
#: Below this peak normalised cross-correlation the rate magnitudes do not match.
MIN_CORRELATION = 0.5
#: The rate magnitudes are searched on at most this many grid points (memory).
MAX_GRID_POINTS = 20_000_000
#: Correlation peaks tried by estimate_alignment (a periodic motion has one a period).
MAX_CANDIDATES = 8


class TimeOffset(NamedTuple):
    """``R_ref(t)`` matches ``R_est(t + seconds)``; ``std`` its standard deviation (s)."""

    seconds: float
    std: float
    correlation: float


def default_rate_bandwidth(step_ref: float, step_est: float) -> float:
    """Return the bandwidth (s) smoothing rate magnitudes: 20 ms, or 3 steps of the slower one."""
    return max(0.02, 3.0 * max(step_ref, step_est))


def smoothed_rates(t: FloatArray, q: FloatArray, rates: Optional[ArrayLike], query: FloatArray,
                   bandwidth: float, name: str) -> Tuple[np.ndarray, FloatArray]:
    """Body angular rates (given, else differentiated from ``q``) smoothed at ``query``."""
    if rates is None:
        times = 0.5 * (t[1:] + t[:-1])
        values = kinematics.angular_velocity_from_quaternions(q, t)
    else:
        times, values = t, np.asarray(rates, dtype=np.float64)
        if values.shape != t.shape + (3,) or not np.all(np.isfinite(values)):
            raise ComparisonError(f'{name}: expected finite angular rates of shape '
                                  f'({t.size}, 3), got {values.shape}')
    return smoothed_vectors(times, values, query, bandwidth)


def _correlations(a, ma, b, mb):
    """Return ``(lags L, pair counts, Pearson correlation of a[i] and b[i + L])`` by FFT."""
    size = 1 << int(np.ceil(np.log2(2 * a.size)))

    def correlate(x, y):
        return np.fft.irfft(np.conj(np.fft.rfft(x, size)) * np.fft.rfft(y, size), size)

    n = correlate(ma, mb)
    sab, sa, sb = correlate(a, b), correlate(a, mb), correlate(ma, b)
    saa, sbb = correlate(a * a, mb), correlate(ma, b * b)
    lags = np.concatenate([np.arange(0, a.size), np.arange(-a.size + 1, 0)])
    pick = np.concatenate([np.arange(0, a.size), np.arange(size - a.size + 1, size)])
    n = np.round(n[pick])
    with np.errstate(invalid='ignore', divide='ignore'):
        covariance = sab[pick] - sa[pick] * sb[pick] / n
        variance = (saa[pick] - sa[pick] ** 2 / n) * (sbb[pick] - sb[pick] ** 2 / n)
        pearson = covariance / np.sqrt(np.maximum(variance, 0.0))
    order = np.argsort(lags)
    return lags[order], n[order], pearson[order]


def estimate_time_offset(t_ref: ArrayLike, q_ref: ArrayLike, t_est: ArrayLike, q_est: ArrayLike,
                         *, rates_ref: Optional[ArrayLike] = None,
                         rates_est: Optional[ArrayLike] = None,
                         max_offset: Optional[float] = None,
                         bandwidth: Optional[float] = None) -> TimeOffset:
    """
    Estimate ``dt`` with ``|w_ref(t)| = |w_est(t + dt)|`` from the two streams' angular rates.

    The highest correlation peak; where the rate magnitude repeats,
    :func:`estimate_alignment` decides between the peaks by the orientations.

    Parameters
    ----------
    t_ref, t_est : array_like, shape (N,), (M,)
        Sample times (s) on one clock, strictly increasing.
    q_ref, q_est : array_like, shape (N, 4), (M, 4)
        Orientations (x, y, z, w), body to world.
    rates_ref, rates_est : array_like, shape (N, 3), (M, 3), optional
        Body angular rates (rad/s) at the sample times; differentiated from the
        orientations where not given.
    max_offset : float, optional
        Search ``|dt| <= max_offset`` (s); default every lag at which the streams overlap
        by at least half the shorter one.
    bandwidth : float, optional
        Standard deviation (s) of the Gaussian smoothing the rate magnitudes; default
        :func:`default_rate_bandwidth`.

    Returns
    -------
    TimeOffset
        ``seconds``, its standard deviation ``std`` and the peak normalised
        cross-correlation of the rate magnitudes.

    Raises
    ------
    DegenerateMotionError
        A stream's rate magnitude varies by less than 0.02 rad/s (standard deviation), the
        two do not correlate (peak below 0.5), or the peak is on the edge of the searched lags.
    ComparisonError
        Bad arrays, or the streams span more than 20 million grid steps (different clocks).

    """
    return time_offset_candidates(t_ref, q_ref, t_est, q_est, rates_ref=rates_ref,
                                  rates_est=rates_est, max_offset=max_offset,
                                  bandwidth=bandwidth, count=1)[0]


def time_offset_candidates(t_ref: ArrayLike, q_ref: ArrayLike, t_est: ArrayLike,
                           q_est: ArrayLike, *, rates_ref: Optional[ArrayLike] = None,
                           rates_est: Optional[ArrayLike] = None,
                           max_offset: Optional[float] = None,
                           bandwidth: Optional[float] = None,
                           count: int = MAX_CANDIDATES) -> List[TimeOffset]:
    """
    Return up to ``count`` offsets at the highest correlation peaks, the highest first.

    As :func:`estimate_time_offset` (whose answer is the first); the others are the next
    local maxima above the correlation threshold, inside the searched range.
    """
    t_ref, q_ref = checked_series(t_ref, q_ref, 'reference')
    t_est, q_est = checked_series(t_est, q_est, 'estimate')
    step_ref, step_est = median_step(t_ref), median_step(t_est)
    bandwidth = (default_rate_bandwidth(step_ref, step_est) if bandwidth is None
                 else float(bandwidth))
    grid_step = min(step_ref, step_est, bandwidth / 8.0)
    start = min(t_ref[0], t_est[0])
    points = int((max(t_ref[-1], t_est[-1]) - start) / grid_step) + 1
    if points > MAX_GRID_POINTS:
        raise ComparisonError(
            f'the two streams span {points * grid_step:.6g} s together: too long to search for '
            f'the time offset at {grid_step * 1e3:.3g} ms steps (are their stamps on one clock? '
            'give the time offset)')
    grid = start + grid_step * np.arange(points)

    def magnitudes(t, q, rates, name):
        valid, values = smoothed_rates(t, q, rates, grid, bandwidth, name)
        signal = np.zeros(grid.size)
        signal[valid] = np.linalg.norm(values, axis=1)
        if np.count_nonzero(valid) < 8 or np.std(signal[valid]) < MIN_RATE_VARIATION:
            raise DegenerateMotionError(
                f'too little motion to estimate the time offset: the {name} angular rate '
                f'varies by less than {MIN_RATE_VARIATION} rad/s')
        return signal, valid.astype(np.float64)

    a, ma = magnitudes(t_ref, q_ref, rates_ref, 'reference')
    b, mb = magnitudes(t_est, q_est, rates_est, 'estimate')
    lags, overlap, pearson = _correlations(a, ma, b, mb)
    allowed = overlap >= 0.5 * min(ma.sum(), mb.sum())
    if max_offset is not None:
        allowed &= np.abs(lags * grid_step) <= max_offset * (1.0 + 1e-9)
    pearson = np.where(allowed & np.isfinite(pearson), pearson, -np.inf)
    peak = int(np.argmax(pearson))
    if not np.isfinite(pearson[peak]) or pearson[peak] < MIN_CORRELATION:
        searched = lags[allowed] * grid_step
        where = (f'within +-{max_offset:g} s' if max_offset is not None else
                 f'in [{searched.min():.3f}, {searched.max():.3f}] s')
        raise DegenerateMotionError(
            f'the angular rates of the two streams do not match at any time offset {where} '
            f'(peak correlation {max(pearson[peak], -1.0):.2f} < {MIN_CORRELATION}): different '
            'motions, too little motion, or a larger offset')
    if (peak == 0 or peak == pearson.size - 1 or not np.isfinite(pearson[peak - 1])
            or not np.isfinite(pearson[peak + 1])):
        raise DegenerateMotionError(
            'the time offset lies at the edge of the searched range (the streams overlap by '
            'less than half, or |offset| > max_offset)')
    inner = pearson[1:-1]
    maxima = 1 + np.flatnonzero((inner >= pearson[:-2]) & (inner > pearson[2:])
                                & (inner >= MIN_CORRELATION))
    others = maxima[maxima != peak]
    others = others[np.argsort(-pearson[others], kind='stable')][:max(count - 1, 0)]
    candidates = []
    for index in [peak, *others.tolist()]:
        left, centre, right = pearson[index - 1:index + 2]
        curvature = left - 2.0 * centre + right
        fraction = 0.5 * (left - right) / curvature if curvature < 0.0 else 0.0
        seconds = (lags[index] + fraction) * grid_step
        seconds, std = _refined(grid, a, ma, b, mb, seconds, grid_step, bandwidth)
        candidates.append(TimeOffset(seconds, std, float(centre)))
    return candidates


def _refined(grid, a, ma, b, mb, seconds, grid_step, bandwidth):
    """Least squares of ``a(t) - g b(t + dt) - c`` in continuous ``dt``; ``(dt, std)``."""
    slope = np.gradient(b, grid_step)
    use = ma > 0
    std = np.inf
    for _ in range(20):
        shifted = grid + seconds
        inside = use & (shifted >= grid[0]) & (shifted <= grid[-1])
        inside[inside] = np.interp(shifted[inside], grid, mb) == 1.0
        x = np.interp(shifted[inside], grid, b)
        dx = np.interp(shifted[inside], grid, slope)
        design = np.column_stack([x, np.ones_like(x)])
        (gain, constant), *_ = np.linalg.lstsq(design, a[inside], rcond=None)
        residual = a[inside] - gain * x - constant
        jacobian = -gain * dx
        information = float(jacobian @ jacobian)
        if information <= 0.0:
            break
        step = -float(jacobian @ residual) / information
        step = float(np.clip(step, -grid_step, grid_step))
        seconds += step
        # Residuals are correlated over the smoothing: one independent value per
        # 2 sqrt(pi) bandwidths (the Gaussian's equivalent width).
        correlated = max(1.0, 2.0 * np.sqrt(np.pi) * bandwidth / grid_step)
        sigma2 = float(residual @ residual) / max(residual.size - 3, 1)
        std = float(np.sqrt(sigma2 * correlated / information))
        if abs(step) < 1e-9:
            break
    return float(seconds), std
