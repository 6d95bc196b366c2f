"""
Orientation covariance between representations, to first order (``J Sigma J^T``).

The common form is the covariance of a small rotation vector ``d`` perturbing the estimate
``R_hat`` (quaternion ``q_hat``) in one of two frames, with ``d_world = R_hat d_body``:
``'world'`` (REP 145's fixed axes, ``R = exp([d]x) R_hat``) or ``'body'``
(``R = R_hat exp([d]x)``).

- Euler angles: ``d = J(a) da``, ``J`` the matrix mapping Euler rates to angular velocity
  (:mod:`rotation_node.kinematics`); its inverse is unbounded at gimbal lock.
- Quaternion components ``(x, y, z, w)``: ``dq = M d / 2``, the three columns of ``M``
  orthonormal and orthogonal to ``q_hat``.

Round trips are exact to rounding. Every function takes array_like input with any leading
dimensions (broadcast), never modifies it, and raises ``ValueError`` naming the argument.
Formulas and accuracy: docs/covariance.md.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, TYPE_CHECKING
import warnings

import numpy as np

from ._arrays import finite_array
from .conversions import matrix_from_quaternion, parse_sequence
from .kinematics import (
    angular_velocity_from_euler_rates, DEFAULT_SINGULARITY_THRESHOLD,
    euler_rates_from_angular_velocity, EulerSingularityWarning)
from .kinematics._validation import is_world_frame

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = [
    'body_rotation_vector_covariance', 'covariance_defect',
    'euler_covariance_from_rotation_vector_covariance', 'euler_linearisation_ratio',
    'MAX_ROTATION_VECTOR_VARIANCE',
    'quaternion_covariance_from_rotation_vector_covariance', 'rotation_vector_covariance_jacobian',
    'rotation_vector_covariance_from_euler_covariance',
    'rotation_vector_covariance_from_quaternion_covariance', 'world_rotation_vector_covariance',
]

_IDENTITY = np.eye(3)

#: Largest variance (rad^2) of a rotation-vector component that says anything about an
#: orientation: a standard deviation of pi rad spans every rotation about that axis. Above
#: it a covariance stands for "unknown" (drivers write 1e9 or DBL_MAX, 1.8e308, for that).
MAX_ROTATION_VECTOR_VARIANCE = math.pi ** 2

#: Relative tolerance of :func:`covariance_defect`: asymmetry and correlations beyond +-1
#: (and a negative determinant of the correlation matrix) within it are rounding.
COVARIANCE_TOLERANCE = 1e-9


def covariance_defect(covariance: Sequence[float]) -> Optional[str]:
    """
    Say why a finite 3 x 3 matrix (9 floats, row-major) is not a covariance; None if it is.

    Returns ``'a negative variance'``, ``'not symmetric'`` or ``'not positive semi-definite'``
    (a correlation beyond +-1, or a negative determinant), each beyond a relative rounding of
    :data:`COVARIANCE_TOLERANCE`. Plain float arithmetic: cheap enough for every message.
    """
    s00, s01, s02, s10, s11, s12, s20, s21, s22 = (float(v) for v in covariance)
    variances = (s00, s11, s22)
    if min(variances) < 0.0:
        return 'a negative variance'
    tolerance = COVARIANCE_TOLERANCE
    scales = (math.sqrt(s00 * s11), math.sqrt(s00 * s22), math.sqrt(s11 * s22))
    pairs = ((s01, s10), (s02, s20), (s12, s21))
    if any(abs(a - b) > tolerance * scale for (a, b), scale in zip(pairs, scales)):
        return 'not symmetric'
    # Correlations of the symmetric part; a zero variance allows no covariance with it.
    correlations = []
    for (a, b), scale in zip(pairs, scales):
        mean = 0.5 * a + 0.5 * b
        if scale == 0.0:
            if mean != 0.0:
                return 'not positive semi-definite'
            correlations.append(0.0)
            continue
        correlation = mean / scale
        if abs(correlation) > 1.0 + tolerance:
            return 'not positive semi-definite'
        correlations.append(correlation)
    c01, c02, c12 = correlations
    determinant = 1.0 + 2.0 * c01 * c02 * c12 - c01 * c01 - c02 * c02 - c12 * c12
    if determinant < -tolerance:
        return 'not positive semi-definite'
    return None


def _congruence(a: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Return ``a sigma a^T`` over leading dimensions, made exactly symmetric."""
    out = a @ sigma @ np.swapaxes(a, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def _unit_quaternion(quaternion) -> np.ndarray:
    """Return the checked quaternion normalised; a ValueError for a zero one."""
    q = finite_array(quaternion, 'quaternion', (4,))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if not (norm > 0.0).all():
        raise ValueError('`quaternion` has zero norm (a zero quaternion is not a rotation).')
    return q / norm


def rotation_vector_covariance_jacobian(angles: ArrayLike, seq: str, frame: str = 'world',
                                        degrees: bool = False) -> np.ndarray:
    """
    Jacobian ``J = dd/da`` of the rotation-vector perturbation w.r.t. the Euler angles.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        Euler angles (first, second, third of ``seq``), radians unless ``degrees``.
    seq : str
        One of the 24 conventions of :func:`rotation_node.conversions.euler_from_quaternion`.
    frame : {'world', 'body'}, optional
        Frame of the perturbation ``d``.
    degrees : bool, optional
        Angles in degrees: ``J`` is then in rad per degree.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``J``, with ``d = J da``; defined everywhere (singular at gimbal lock).

    Raises
    ------
    ValueError
        Bad ``seq`` or ``frame``; wrong shape or NaN/Inf ``angles``.

    """
    world = is_world_frame(frame)
    a = finite_array(angles, 'angles', (3,))
    columns = angular_velocity_from_euler_rates(a[..., None, :], _IDENTITY, seq,
                                                'world' if world else 'body', degrees)
    return np.swapaxes(columns, -1, -2)


def rotation_vector_covariance_from_euler_covariance(angles: ArrayLike, covariance: ArrayLike,
                                                     seq: str, frame: str = 'world',
                                                     degrees: bool = False) -> np.ndarray:
    """
    Rotation-vector covariance of an orientation whose Euler angles have ``covariance``.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        Euler angles of the estimate, radians unless ``degrees``.
    covariance : array_like, shape (..., 3, 3)
        Covariance of the three angles (rad^2, or deg^2 if ``degrees``).
    seq : str
        One of the 24 conventions.
    frame : {'world', 'body'}, optional
        Frame of the returned rotation-vector covariance.
    degrees : bool, optional
        Angles in degrees and ``covariance`` in deg^2.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``J Sigma_a J^T`` in rad^2, exactly symmetric. Defined everywhere.

    Raises
    ------
    ValueError
        Bad ``seq`` or ``frame``; wrong shape or NaN/Inf, naming the argument.

    """
    sigma = finite_array(covariance, 'covariance', (3, 3))
    return _congruence(rotation_vector_covariance_jacobian(angles, seq, frame, degrees), sigma)


def euler_covariance_from_rotation_vector_covariance(
        angles: ArrayLike, covariance: ArrayLike, seq: str, frame: str = 'world',
        degrees: bool = False, *,
        singularity_threshold: float = DEFAULT_SINGULARITY_THRESHOLD) -> np.ndarray:
    """
    First-order covariance of the Euler angles of an uncertain orientation.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        Euler angles of the estimate in ``seq``, radians unless ``degrees``.
    covariance : array_like, shape (..., 3, 3)
        Rotation-vector covariance (rad^2) in ``frame``.
    seq : str
        One of the 24 conventions.
    frame : {'world', 'body'}, optional
        Frame of ``covariance``.
    degrees : bool, optional
        Angles in degrees; the result is then in deg^2.
    singularity_threshold : float, optional
        Radians, whatever ``degrees``; in [0, pi/2]. Samples whose middle angle
        is within this distance of gimbal lock get an all-NaN covariance.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``J^-1 Sigma_d J^-T`` (rad^2, or deg^2), exactly symmetric. It grows as
        ``1 / margin^2`` towards gimbal lock; it describes the angles' spread
        only while the orientation's standard deviation is small compared
        with that margin: check :func:`euler_linearisation_ratio`.

    Warns
    -----
    EulerSingularityWarning
        Once per call if any sample was within ``singularity_threshold`` of
        gimbal lock, with their count; the mask is ``np.isnan(result[..., 0, 0])``.

    Raises
    ------
    ValueError
        Bad ``seq`` or ``frame``, ``singularity_threshold`` outside [0, pi/2]; wrong shape or
        NaN/Inf, naming the argument.

    """
    world = is_world_frame(frame)
    a = finite_array(angles, 'angles', (3,))
    sigma = finite_array(covariance, 'covariance', (3, 3))
    # One row of angles per column of J^-1: equal leading shapes need no broadcast copy.
    rows = np.repeat(a[..., None, :], 3, axis=-2)
    try:
        near = bool(np.any(_middle_margin(a, parse_sequence(seq), degrees)
                           <= float(singularity_threshold) * (1.0 + 1e-9)))
    except (TypeError, ValueError):
        near = True   # the call below names what was wrong
    frame_name = 'world' if world else 'body'
    # The warning below replaces the Euler rates' one. Caught only when needed: catch_warnings
    # resets the warning registries (a 'default' warning already shown would show again).
    if near:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', EulerSingularityWarning)
            columns = euler_rates_from_angular_velocity(
                rows, _IDENTITY, seq, frame_name, degrees,
                singularity_threshold=singularity_threshold)
    else:
        columns = euler_rates_from_angular_velocity(
            rows, _IDENTITY, seq, frame_name, degrees,
            singularity_threshold=singularity_threshold)
    out = _congruence(np.swapaxes(columns, -1, -2), sigma)
    singular = np.isnan(columns[..., 0, 0])
    if singular.any():
        out[np.broadcast_to(singular, out.shape[:-2])] = np.nan
        count = int(np.count_nonzero(singular))
        warnings.warn(
            f'{count} of {singular.size} orientations are within {singularity_threshold:g} rad '
            f'of gimbal lock in {seq!r}: their Euler covariance is unbounded and returned as '
            'NaN.', EulerSingularityWarning, stacklevel=2)
    return out


def _middle_margin(angles: np.ndarray, spec, degrees: bool) -> np.ndarray:
    """Return the distance (rad, in [0, pi/2]) of the middle angle from its singular values."""
    middle = np.radians(angles[..., 1]) if degrees else angles[..., 1]
    c, s = np.abs(np.cos(middle)), np.abs(np.sin(middle))
    return np.arctan2(s, c) if spec.proper else np.arctan2(c, s)


def euler_linearisation_ratio(angles: ArrayLike, covariance: ArrayLike, seq: str,
                              degrees: bool = False) -> np.ndarray:
    """
    How far the first-order Euler covariance can be trusted: ``sigma_max / margin``.

    ``sigma_max`` is the rotation vector's largest standard deviation (the same in the world
    and the body frame), ``margin`` the middle angle's distance from its singular value
    (+-pi/2 Tait-Bryan, 0 or pi proper Euler). Against Monte Carlo (docs/covariance.md) the
    first-order standard deviations are within 1 % below a ratio of about 0.1, 10 % below 0.3.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        Euler angles of the estimate in ``seq``, radians unless ``degrees``.
    covariance : array_like, shape (..., 3, 3)
        Rotation-vector covariance (rad^2), world or body frame.
    seq : str
        One of the 24 conventions.
    degrees : bool, optional
        Angles in degrees.

    Returns
    -------
    ndarray, shape (...)
        The ratio; ``inf`` at gimbal lock (unless the covariance is zero).

    Raises
    ------
    ValueError
        Bad ``seq``; wrong shape or NaN/Inf, naming the argument.

    """
    a = finite_array(angles, 'angles', (3,))
    sigma = finite_array(covariance, 'covariance', (3, 3))
    margin = _middle_margin(a, parse_sequence(seq), degrees)
    largest = np.linalg.eigvalsh(0.5 * (sigma + np.swapaxes(sigma, -1, -2)))[..., -1]
    std = np.sqrt(np.maximum(largest, 0.0))
    # std / margin, with 0 / 0 = 0 (no uncertainty) and std / 0 = inf (gimbal lock)
    std, margin = np.broadcast_arrays(std, margin)
    out = np.where(std > 0.0, np.inf, 0.0)
    np.divide(std, margin, out=out, where=margin > 0.0)
    return out


def _tangent_basis(q: np.ndarray, world: bool) -> np.ndarray:
    """Return ``M`` (..., 4, 3): orthonormal columns, ``dq = M d / 2``, for unit ``q``."""
    x, y, z, w = np.moveaxis(q, -1, 0)
    s = 1.0 if world else -1.0  # w I - s [v]x
    m = np.empty(q.shape[:-1] + (4, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 0, 2] = w, s * z, -s * y
    m[..., 1, 0], m[..., 1, 1], m[..., 1, 2] = -s * z, w, s * x
    m[..., 2, 0], m[..., 2, 1], m[..., 2, 2] = s * y, -s * x, w
    m[..., 3, 0], m[..., 3, 1], m[..., 3, 2] = -x, -y, -z
    return m


def quaternion_covariance_from_rotation_vector_covariance(quaternion: ArrayLike,
                                                          covariance: ArrayLike,
                                                          frame: str = 'world') -> np.ndarray:
    """
    4x4 covariance of the quaternion components of an uncertain orientation.

    Parameters
    ----------
    quaternion : array_like, shape (..., 4)
        The estimate ``(x, y, z, w)``, any non-zero norm (it is normalised).
    covariance : array_like, shape (..., 3, 3)
        Rotation-vector covariance (rad^2) in ``frame``.
    frame : {'world', 'body'}, optional
        Frame of ``covariance``.

    Returns
    -------
    ndarray, shape (..., 4, 4)
        ``M Sigma_d M^T / 4`` at the normalised quaternion, rows and columns ordered
        ``(x, y, z, w)``; rank 3, ``q_hat`` in its null space. The same for ``q`` and ``-q``.

    Raises
    ------
    ValueError
        Bad ``frame``; wrong shape, NaN/Inf or a zero quaternion, naming the argument.

    """
    m = _tangent_basis(_unit_quaternion(quaternion), is_world_frame(frame))
    return 0.25 * _congruence(m, finite_array(covariance, 'covariance', (3, 3)))


def rotation_vector_covariance_from_quaternion_covariance(quaternion: ArrayLike,
                                                          covariance: ArrayLike,
                                                          frame: str = 'world') -> np.ndarray:
    """
    Rotation-vector covariance of an orientation given its 4x4 quaternion covariance.

    Parameters
    ----------
    quaternion : array_like, shape (..., 4)
        The estimate ``(x, y, z, w)``, any non-zero norm (it is normalised).
    covariance : array_like, shape (..., 4, 4)
        Covariance of the components in the order ``(x, y, z, w)``. For a
        ``(w, x, y, z)`` covariance ``C`` (PX4) pass ``C[..., p, :][..., :, p]``
        with ``p = [1, 2, 3, 0]``.
    frame : {'world', 'body'}, optional
        Frame of the returned covariance.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``4 M^T Sigma_q M`` (rad^2): the tangent-space part of ``Sigma_q``;
        what lies along ``q_hat`` (uncertainty of the norm) is dropped.

    Raises
    ------
    ValueError
        Bad ``frame``; wrong shape, NaN/Inf or a zero quaternion, naming the argument.

    """
    m = _tangent_basis(_unit_quaternion(quaternion), is_world_frame(frame))
    sigma = finite_array(covariance, 'covariance', (4, 4))
    return 4.0 * _congruence(np.swapaxes(m, -1, -2), sigma)


def world_rotation_vector_covariance(quaternion: ArrayLike,
                                     body_covariance: ArrayLike) -> np.ndarray:
    """
    World-frame (fixed axes) rotation-vector covariance from the body-frame one.

    Parameters
    ----------
    quaternion : array_like, shape (..., 4)
        The estimate ``(x, y, z, w)``, body to world, any non-zero norm.
    body_covariance : array_like, shape (..., 3, 3)
        Covariance of ``d`` in ``R = R_hat exp([d]x)``, rad^2.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R_hat Sigma_body R_hat^T``: the covariance of ``d`` in
        ``R = exp([d]x) R_hat``.

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf or a zero quaternion, naming the argument.

    """
    r = matrix_from_quaternion(_unit_quaternion(quaternion))
    return _congruence(r, finite_array(body_covariance, 'body_covariance', (3, 3)))


def body_rotation_vector_covariance(quaternion: ArrayLike,
                                    world_covariance: ArrayLike) -> np.ndarray:
    """
    Body-frame rotation-vector covariance from the world-frame (fixed axes) one.

    Parameters
    ----------
    quaternion : array_like, shape (..., 4)
        The estimate ``(x, y, z, w)``, body to world, any non-zero norm.
    world_covariance : array_like, shape (..., 3, 3)
        Covariance of ``d`` in ``R = exp([d]x) R_hat``, rad^2.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R_hat^T Sigma_world R_hat``: the covariance of ``d`` in
        ``R = R_hat exp([d]x)``.

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf or a zero quaternion, naming the argument.

    """
    r = matrix_from_quaternion(_unit_quaternion(quaternion))
    return _congruence(np.swapaxes(r, -1, -2),
                       finite_array(world_covariance, 'world_covariance', (3, 3)))
