"""
The world alignment ``W``, mounting ``M`` and time offset ``dt`` of two orientation streams.

Least squares on SO(3) of the residuals ``r_i = log(R_ref(t_i)^T W R_est(t_i + dt) M)`` over
the reference samples (``docs/compare.md``, "How they are estimated"): ``dt`` from the rate
magnitudes unless given, a closed-form start (Kabsch on the body rates, chordal means),
Gauss-Newton on ``W exp(a)``, ``M exp(b)``, ``dt + c`` with the estimate evaluated by a
Gaussian local fit, and a covariance that counts the residuals sharing that fit's noise.
Degenerate motion is refused from ``J^T J`` before any step is taken.
"""
from __future__ import annotations

from typing import NamedTuple, Optional, TYPE_CHECKING

import numpy as np

from ._series import checked_series, interpolate_orientations, median_step, orientation_errors
from ._smoothing import smoothed_orientations, WINDOW_BANDWIDTHS
from ._time_offset import default_rate_bandwidth, smoothed_rates, time_offset_candidates
from .. import conversions
from ..errors import ComparisonError, DegenerateMotionError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
#: Fewer matched samples than this are too short a record.
MIN_MATCHED = 20
#: Normalised information below this: parameters not separable.
MIN_INFORMATION = 1e-3
#: Root mean square angular rate (rad/s) below which a time offset is undetermined.
MIN_RMS_RATE = 0.05
_MAX_ITERATIONS = 50
#: Bandwidth of the estimate's local fit, in its median steps: wider averages more noise
#: (its derivative enters the time offset); 3 steps measured best on 60 s at 1 deg.
FIT_STEPS = 3.0
#: Another correlation peak whose orientations agree within this factor of the best
#: residual makes the time offset ambiguous (noise alone moves it by about 1/sqrt(n)).
AMBIGUOUS_RESIDUAL = 1.1


class Alignment(NamedTuple):
    """
    What :func:`estimate_alignment` found: ``R_ref(t) = W R_est(t + dt) M``.

    Attributes
    ----------
    time_offset, time_offset_std : float
        ``dt`` (s) and its standard deviation (0 when given).
    world, mounting : ndarray, shape (4,)
        ``W`` and ``M``, unit quaternions (x, y, z, w), ``w >= 0``.
    world_std, mounting_std : ndarray, shape (3,)
        Standard deviations (rad) of ``a``, ``b`` in ``W exp(a)``, ``M exp(b)`` (0 when fixed).
    matched : int
        Reference samples used.
    residual_rms : float
        Root mean square residual angle (rad).

    """

    time_offset: float
    time_offset_std: float
    world: FloatArray
    world_std: FloatArray
    mounting: FloatArray
    mounting_std: FloatArray
    matched: int
    residual_rms: float


class AlignedSeries(NamedTuple):
    """
    The reference samples matched by the aligned estimate.

    Attributes
    ----------
    reference_index : ndarray of int, shape (n,)
        Indices of the matched reference samples.
    times : ndarray, shape (n,)
        Their times (s).
    reference, estimate : ndarray, shape (n, 4)
        Their orientations, and ``W q_est(t + dt) M`` (the estimate slerped at ``t + dt``).
    errors : ndarray, shape (n, 3)
        :func:`orientation_errors` of the two (rad, reference body axes).

    """

    reference_index: np.ndarray
    times: FloatArray
    reference: FloatArray
    estimate: FloatArray
    errors: FloatArray


def chordal_mean(q: FloatArray) -> FloatArray:
    """Return the chordal mean of rotations ``q (N, 4)``: the top eigenvector of ``sum q q^T``."""
    _, vectors = np.linalg.eigh(q.T @ q)
    return conversions.canonical_quaternion(vectors[:, -1])


def kabsch(a: FloatArray, b: FloatArray) -> FloatArray:
    """Return the rotation (a quaternion) minimising ``sum |b_i - R a_i|^2`` (SVD, det +1)."""
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    return conversions.quaternion_from_matrix(u @ d @ vt)


def _skew(v):
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def inverse_right_jacobian(r: FloatArray) -> FloatArray:
    """``J_r^-1(r)`` of SO(3): ``log(exp(r) exp(d)) = r + J_r^-1(r) d + O(d^2)``; ``(n, 3, 3)``."""
    theta = np.linalg.norm(r, axis=-1)
    k = _skew(r)
    with np.errstate(invalid='ignore', divide='ignore'):
        general = 1.0 / theta ** 2 - (1.0 + np.cos(theta)) / (2.0 * theta * np.sin(theta))
    coefficient = np.where(theta < 1e-4, 1.0 / 12.0 + theta ** 2 / 720.0, general)
    return np.eye(3) + 0.5 * k + coefficient[:, None, None] * (k @ k)


class _Problem:
    """The residuals of the selected reference samples and their Jacobian."""

    def __init__(self, t_ref, q_ref, t_est, q_est, bandwidth, max_gap, rates_est):
        self.t_ref, self.q_ref, self.t_est, self.q_est = t_ref, q_ref, t_est, q_est
        self.rates_est = rates_est
        self.rate_bandwidth = default_rate_bandwidth(median_step(t_ref), bandwidth)
        self.bandwidth, self.max_gap = bandwidth, max_gap
        self.margin = 3.0 * bandwidth
        self.selected_at = None
        self._cached: tuple = (None, None)

    def select(self, dt):
        """Choose the reference samples usable for any offset within the margin of ``dt``."""
        query = self.t_ref + dt
        usable, _ = interpolate_orientations(self.t_est, self.q_est, query, max_gap=self.max_gap)
        for shift in (-self.margin, 0.0, self.margin):
            valid, _ = smoothed_orientations(self.t_est, self.q_est, query + shift, self.bandwidth)
            usable &= valid
            usable &= self._rates_at(query + shift)[0]
        self.index = np.flatnonzero(usable)
        if self.index.size < MIN_MATCHED:
            raise ComparisonError(
                f'only {self.index.size} reference samples fall within the estimate stream '
                f'(time offset {dt:.6f} s); at least {MIN_MATCHED} are needed: the streams '
                'hardly overlap in time')
        self.selected_at = dt

    def estimate_at(self, dt):
        key = (dt, self.selected_at)
        if self._cached[0] != key:
            _, q = smoothed_orientations(self.t_est, self.q_est, self.t_ref[self.index] + dt,
                                         self.bandwidth)
            self._cached = (key, q)
        return self._cached[1]

    def _rates_at(self, query):
        """Return the estimate's body rates at ``query``, smoothed: ``(valid, rates)``."""
        return smoothed_rates(self.t_est, self.q_est, self.rates_est, query,
                              self.rate_bandwidth, 'estimate')

    def linearised(self, world, mounting, dt, columns):
        """``(r (3n,), J (3n, p))`` for the parameter blocks ``columns``."""
        if self.selected_at is None or abs(dt - self.selected_at) > 0.5 * self.margin:
            self.select(dt)
        estimate = self.estimate_at(dt)
        r = _residuals(self.q_ref[self.index], estimate, world, mounting)
        blocks = [_rotation_jacobian(r, estimate, mounting, columns)]
        if 'time_offset' in columns:
            # R_est(t + dt + c) = R_est(t + dt) exp(w_est c): dr/dc = J_r^-1(r) M^T w_est.
            _, rates = self._rates_at(self.t_ref[self.index] + dt)
            body = conversions.rotate_vector(conversions.quaternion_conjugate(mounting), rates)
            blocks.append(inverse_right_jacobian(r) @ body[:, :, None])
        jacobian = np.concatenate(blocks, axis=2)
        return r.reshape(-1), jacobian.reshape(r.size, -1)   # (p may be 0)


def _check_determined(information, columns, count):
    """Raise :class:`DegenerateMotionError` where ``J^T J`` leaves a parameter undetermined."""
    names = [name for name in columns for _ in range(1 if name == 'time_offset' else 3)]
    if 'time_offset' in columns:
        rms_rate = float(np.sqrt(information[-1, -1] / count))
        if rms_rate < MIN_RMS_RATE:
            raise DegenerateMotionError(
                f'too little motion to estimate the time offset: root mean square angular '
                f'rate {rms_rate:.3f} rad/s < {MIN_RMS_RATE}')
    scale = 1.0 / np.sqrt(np.diag(information))
    values, vectors = np.linalg.eigh(information * np.outer(scale, scale))
    if values[0] >= MIN_INFORMATION:
        return
    weight = {name: float(np.sum(vectors[[i for i, n in enumerate(names) if n == name], 0] ** 2))
              for name in columns}
    if weight.get('time_offset', 0.0) > 0.1:
        raise DegenerateMotionError(
            'the time offset cannot be told from a fixed rotation: the motion turns at a '
            'constant rate about one axis (give --time-offset, or record varied motion)')
    if 'world' in columns and 'mounting' in columns:
        raise DegenerateMotionError(
            'world alignment and mounting cannot be told apart: the motion turns about one '
            'axis only, or hardly turns (align one of them, or record motion about several axes)')
    raise DegenerateMotionError(f'too little motion to estimate {" and ".join(columns)}')


def estimate_alignment(t_ref: ArrayLike, q_ref: ArrayLike, t_est: ArrayLike, q_est: ArrayLike,
                       *, time_offset: Optional[float] = None, world: bool = True,
                       mounting: bool = True, rates_ref: Optional[ArrayLike] = None,
                       rates_est: Optional[ArrayLike] = None, max_gap: Optional[float] = None,
                       max_offset: Optional[float] = None) -> Alignment:
    """
    Estimate ``W``, ``M`` and ``dt`` with ``R_ref(t) = W R_est(t + dt) M``.

    Parameters
    ----------
    t_ref, t_est : array_like, shape (N,), (K,)
        Sample times (s) on one clock, strictly increasing.
    q_ref, q_est : array_like, shape (N, 4), (K, 4)
        Orientations (x, y, z, w), body to world.
    time_offset : float, optional
        ``dt`` (s) if known; estimated when None.
    world, mounting : bool, optional
        Estimate ``W`` (``M``); the identity when False.
    rates_ref, rates_est : array_like, shape (N, 3), (K, 3), optional
        Body angular rates (rad/s) at the sample times, for the first ``dt`` and ``M``;
        differentiated from the orientations if not given.
    max_gap : float, optional
        Leave out reference samples whose estimate neighbours (at ``t + dt``) are further
        apart (s); default 5 median steps of the estimate.
    max_offset : float, optional
        Largest ``|dt|`` searched (s), see :func:`estimate_time_offset`.

    Returns
    -------
    Alignment

    Raises
    ------
    DegenerateMotionError
        The motion does not determine what was asked.
    ComparisonError
        Bad arrays, or fewer than 20 reference samples within the estimate.

    """
    t_ref, q_ref = checked_series(t_ref, q_ref, 'reference')
    t_est, q_est = checked_series(t_est, q_est, 'estimate')
    step_est = median_step(t_est)
    if time_offset is None:   # the correlation peak at which the orientations agree best
        starts = [candidate.seconds for candidate in time_offset_candidates(
            t_ref, q_ref, t_est, q_est, rates_ref=rates_ref, rates_est=rates_est,
            max_offset=max_offset)]
    else:
        starts = [float(time_offset)]
    columns = [name for name, wanted in (('world', world), ('mounting', mounting),
                                         ('time_offset', time_offset is None)) if wanted]
    problem = _Problem(t_ref, q_ref, t_est, q_est, FIT_STEPS * step_est,
                       5.0 * step_est if max_gap is None else float(max_gap), rates_est)
    dt = _best_start(problem, starts, world, mounting, rates_ref, rates_est)
    problem.select(dt)   # (the last start scored may have chosen other samples)
    w, m = _initial_rotations(problem, dt, world, mounting, rates_ref, rates_est)
    # Residuals are correlated within the reach of the estimate's local fit.
    return _least_squares(problem.linearised, w, m, dt, columns,
                          lambda: problem.t_ref[problem.index],
                          2.0 * WINDOW_BANDWIDTHS * problem.bandwidth)


def _best_start(problem, starts, world, mounting, rates_ref, rates_est):
    """
    Return the start ``dt`` at which the closed-form ``W``, ``M`` leave the smallest residual.

    Another as good (a motion repeating itself up to a rotation) is a DegenerateMotionError.
    """
    scored, refused = [], []
    for start in starts:
        try:
            problem.select(start)
        except ComparisonError as error:   # (at a wrong peak the streams may hardly overlap)
            refused.append(error)
            continue
        w, m = _initial_rotations(problem, start, world, mounting, rates_ref, rates_est)
        residuals = _residuals(problem.q_ref[problem.index], problem.estimate_at(start), w, m)
        scored.append((_rms_angle(residuals), start))
    if not scored:
        raise refused[0]
    scored.sort()
    best, dt = scored[0]
    alike = [start for residual, start in scored[1:]
             if residual <= AMBIGUOUS_RESIDUAL * best and abs(start - dt) > problem.margin]
    if alike:
        offsets = ', '.join(sorted({f'{start:+.4f}' for start in [dt, *alike]}, key=float))
        raise DegenerateMotionError(
            f'the time offset is ambiguous: the motion repeats itself, and the orientations '
            f'agree as well at {offsets} s; give the offset, or bound the search (max_offset, '
            '--max-offset)')
    return dt


def _least_squares(linearised, w, m, dt, columns, times=None, span=0.0):
    """
    Gauss-Newton from ``(w, m, dt)`` to the :class:`Alignment` of the solution.

    ``linearised(w, m, dt, columns) -> (r, J)``; ``J^T J`` is checked for degenerate motion
    at the start and at the solution. The variances are those of ``s^2 (J^T J)^-1`` or, given
    ``times()`` of the last linearised samples, of :func:`_correlated_covariance` where larger.
    """
    count = None
    for iteration in range(_MAX_ITERATIONS + 1):
        r, jacobian = linearised(w, m, dt, columns)
        count = r.size // 3
        if not columns:
            break
        information = jacobian.T @ jacobian
        if iteration == 0:
            _check_determined(information, columns, count)
        step = -np.linalg.solve(information, jacobian.T @ r)
        if np.max(np.abs(step)) < 1e-10 or iteration == _MAX_ITERATIONS:
            break
        w, m, dt = _updated(w, m, dt, step, columns)
    std = np.zeros(0)
    if columns:
        _check_determined(information, columns, count)
        dof = max(r.size - jacobian.shape[1], 1)
        variance = np.diag(np.linalg.inv(information)) * float(r @ r) / dof
        if times is not None:   # (never below the independent one: S sums lags, may be < 0)
            variance = np.maximum(variance, np.diag(_correlated_covariance(
                information, jacobian, r, times(), span, r.size / dof)))
        std = np.sqrt(variance)
    std = _blocks(std, columns)
    return Alignment(time_offset=float(dt),
                     time_offset_std=float(std.get('time_offset', [0.0])[0]),
                     world=conversions.canonical_quaternion(w),
                     world_std=std.get('world', np.zeros(3)),
                     mounting=conversions.canonical_quaternion(m),
                     mounting_std=std.get('mounting', np.zeros(3)),
                     matched=r.size // 3, residual_rms=_rms_angle(r))


def _residuals(q_ref, q_est, w, m):
    """Rotation vectors ``log(R_ref^T W R_est M)`` of matched samples."""
    return orientation_errors(
        q_ref, conversions.quaternion_product(conversions.quaternion_product(w, q_est), m))


def _rms_angle(r):
    """Root mean square of the angles of rotation vectors ``r`` (flat or (n, 3))."""
    return float(np.sqrt(np.mean(np.sum(r.reshape(-1, 3) ** 2, axis=1))))


def _correlated_covariance(information, jacobian, r, times, span, scale):
    """
    ``(J^T J)^-1 S (J^T J)^-1``: ``S`` the sum of ``g_i g_j^T`` over ``|t_i - t_j| <= span``.

    ``g_i = J_i^T r_i``. Samples closer than ``span`` share the estimate fit's noise, which
    ``s^2 (J^T J)^-1`` would count as independent (and the smoothing shrinks ``s^2``).
    """
    p = jacobian.shape[1]
    score = np.einsum('ikp,ik->ip', jacobian.reshape(-1, 3, p), r.reshape(-1, 3))
    total = np.concatenate([np.zeros((1, p)), np.cumsum(score, axis=0)])
    low = np.searchsorted(times, times - span, side='left')
    high = np.searchsorted(times, times + span, side='right')
    nearby = total[high] - total[low]
    middle = score.T @ nearby
    middle = 0.5 * (middle + middle.T) * scale
    inverse = np.linalg.inv(information)
    return inverse @ middle @ inverse


def _pair_linearised(q_ref, q_est):
    """``linearised(w, m, dt, columns)`` of matched pairs (``dt`` unused)."""
    def linearised(w, m, dt, columns):
        r = _residuals(q_ref, q_est, w, m)
        jacobian = _rotation_jacobian(r, q_est, m, columns)
        return r.reshape(-1), jacobian.reshape(r.size, -1)   # (p may be 0)
    return linearised


def _rotation_jacobian(r, estimate, mounting, columns):
    """Jacobian blocks ``(n, 3, p)`` of the residuals ``r`` in ``W exp(a)`` and ``M exp(b)``."""
    jr_inv = inverse_right_jacobian(r)
    blocks = []
    if 'world' in columns:
        body = conversions.matrix_from_quaternion(
            conversions.quaternion_product(estimate, mounting))
        blocks.append(jr_inv @ np.swapaxes(body, -1, -2))
    if 'mounting' in columns:
        blocks.append(jr_inv)
    return np.concatenate(blocks, axis=2) if blocks else np.zeros(r.shape + (0,))


def align_pairs(q_ref: ArrayLike, q_est: ArrayLike, *, world: bool = True,
                mounting: bool = True) -> Alignment:
    """
    ``W`` and ``M`` minimising ``sum |log(R_ref_i^T W R_est_i M)|^2`` over matched pairs.

    :func:`estimate_alignment` without time: the same start (``M`` by Kabsch on the relative
    rotations of consecutive pairs when both are estimated) and Gauss-Newton steps.

    Parameters
    ----------
    q_ref, q_est : array_like, shape (N, 4)
        Matched orientations (x, y, z, w), body to world.
    world, mounting : bool, optional
        Estimate ``W`` (``M``); the identity when False.

    Returns
    -------
    Alignment
        With ``time_offset`` 0 and ``matched`` N.

    Raises
    ------
    DegenerateMotionError
        The pairs do not determine what was asked.

    """
    q_ref = conversions.canonical_quaternion(q_ref)
    q_est = conversions.canonical_quaternion(q_est)
    if q_ref.shape != q_est.shape or q_ref.ndim != 2 or q_ref.shape[0] < 2:
        raise ComparisonError(f'expected two (N >= 2, 4) arrays of matched quaternions, got '
                              f'{q_ref.shape} and {q_est.shape}')
    columns = [name for name, wanted in (('world', world), ('mounting', mounting)) if wanted]
    w = m = IDENTITY
    if world and mounting:
        # Relative rotations of consecutive pairs: log(R_ref_i^T R_ref_j) = M^T log(est ...).
        m = kabsch(orientation_errors(q_ref[:-1], q_ref[1:]),
                   orientation_errors(q_est[:-1], q_est[1:]))
    w, m = _closed_form(q_ref, q_est, w, m, world, mounting)
    return _least_squares(_pair_linearised(q_ref, q_est), w, m, 0.0, columns)


def _blocks(vector, columns):
    out, start = {}, 0
    for name in columns:
        size = 1 if name == 'time_offset' else 3
        out[name] = vector[start:start + size]
        start += size
    return out


def _updated(w, m, dt, step, columns):
    blocks = _blocks(step, columns)
    if 'world' in blocks:
        w = conversions.canonical_quaternion(conversions.quaternion_product(
            w, conversions.quaternion_from_rotation_vector(blocks['world'])))
    if 'mounting' in blocks:
        m = conversions.canonical_quaternion(conversions.quaternion_product(
            m, conversions.quaternion_from_rotation_vector(blocks['mounting'])))
    if 'time_offset' in blocks:
        dt = dt + float(blocks['time_offset'][0])
    return w, m, dt


def _initial_rotations(problem, dt, world, mounting, rates_ref, rates_est):
    """Closed-form first ``(W, M)``: Kabsch on the body rates for both, chordal means for one."""
    q_ref = problem.q_ref[problem.index]
    estimate = problem.estimate_at(dt)
    w = m = IDENTITY
    if world and mounting:
        times = problem.t_ref[problem.index]
        bandwidth = problem.rate_bandwidth
        valid_ref, w_ref = smoothed_rates(problem.t_ref, problem.q_ref, rates_ref, times,
                                          bandwidth, 'reference')
        valid_est, w_est = smoothed_rates(problem.t_est, problem.q_est, rates_est, times + dt,
                                          bandwidth, 'estimate')
        both = valid_ref & valid_est
        m = kabsch(w_ref[both[valid_ref]], w_est[both[valid_est]])
    return _closed_form(q_ref, estimate, w, m, world, mounting)


def _closed_form(q_ref, q_est, w, m, world, mounting):
    """Return ``W`` given ``M`` (when estimated), else ``M`` given ``W``: chordal means."""
    if world:
        w = chordal_mean(conversions.quaternion_product(
            q_ref, conversions.quaternion_conjugate(conversions.quaternion_product(q_est, m))))
    elif mounting:
        m = chordal_mean(conversions.quaternion_product(
            conversions.quaternion_conjugate(conversions.quaternion_product(w, q_est)), q_ref))
    return w, m


def aligned_series(t_ref: ArrayLike, q_ref: ArrayLike, t_est: ArrayLike, q_est: ArrayLike, *,
                   time_offset: float = 0.0, world: ArrayLike = IDENTITY,
                   mounting: ArrayLike = IDENTITY,
                   max_gap: Optional[float] = None) -> AlignedSeries:
    """
    Return the estimate slerped at the reference stamps ``t + dt``, aligned, and the errors.

    Parameters
    ----------
    t_ref, q_ref, t_est, q_est : array_like
        The two series, as for :func:`estimate_alignment`.
    time_offset : float, optional
        ``dt`` (s).
    world, mounting : array_like, shape (4,), optional
        ``W`` and ``M`` (x, y, z, w); the identity by default.
    max_gap : float, optional
        As for :func:`interpolate_orientations`.

    Returns
    -------
    AlignedSeries

    Raises
    ------
    ComparisonError
        No reference sample falls within the estimate at ``t + dt``.

    """
    t_ref, q_ref = checked_series(t_ref, q_ref, 'reference')
    t_est, q_est = checked_series(t_est, q_est, 'estimate')
    valid, estimate = interpolate_orientations(t_est, q_est, t_ref + time_offset,
                                               max_gap=max_gap)
    if not np.any(valid):
        raise ComparisonError(f'the streams do not overlap in time (with the time offset '
                              f'{time_offset:.6f} s)')
    aligned = conversions.canonical_quaternion(conversions.quaternion_product(
        conversions.quaternion_product(world, estimate), mounting))
    index = np.flatnonzero(valid)
    return AlignedSeries(index, t_ref[index], q_ref[index], aligned,
                         orientation_errors(q_ref[index], aligned))
