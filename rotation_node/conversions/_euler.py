"""
Euler angles in all 24 conventions (12 axis sequences, intrinsic or extrinsic).

Quaternion to angles follows Bernardes and Viollet [1]_: ratios fed to ``atan2``, so the
norm does not matter, and nothing is snapped near gimbal lock. Only at exact degeneracy
(middle angle exactly singular) is the third angle set to 0, the first carrying the
whole rotation about that axis (docs/numerics.md).

References
----------
.. [1] E. Bernardes and S. Viollet, "Quaternion to Euler angles conversion: a
   direct, general and computationally efficient method", PLOS ONE 17(11),
   e0276302, 2022.

"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ._matrix import (
    convert_matrices, DEFAULT_NON_ORTHONORMAL, DEFAULT_ORTHONORMAL_TOLERANCE, EIGENVECTOR_PENDING,
    quaternion_of_matrix, store_rotation)
from ._quaternion import (
    needs_sign_flip, product, quaternion_status, scaled_quaternion, vector_status)
from ._runtime import (
    call_unary, FLAT_IN, FLAT_OUT, FLOAT, INT, jit, kernel, matrix_samples, ROWS_IN, ROWS_OUT,
    samples, STAGE_CHUNK)
from ._trigonometry import atan2_in_place_kernel, sin_cos
from ._validation import parse_sequence, SEQUENCE_TABLE

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray, FloatArrayOrScalar, Quaternion4, Vector3

_TWO_PI = 2.0 * math.pi
_DEGREES_PER_RADIAN = 180.0 / math.pi
_RADIANS_PER_DEGREE = math.pi / 180.0


@jit
def _elementary(axis, angle):
    """Quaternion of a rotation by ``angle`` about coordinate axis ``axis`` (0, 1, 2)."""
    s, c = sin_cos(0.5 * angle)
    if axis == 0:
        return s, 0.0, 0.0, c
    if axis == 1:
        return 0.0, s, 0.0, c
    return 0.0, 0.0, s, c


@jit
def quaternion_from_euler_scalar(a1: float, a2: float, a3: float, i: int, j: int, k: int,
                                 intrinsic: bool) -> Quaternion4:
    """Return the unit canonical quaternion of Euler angles (radians) about axes i, j, k."""
    e1x, e1y, e1z, e1w = _elementary(i, a1)
    e2x, e2y, e2z, e2w = _elementary(j, a2)
    e3x, e3y, e3z, e3w = _elementary(k, a3)
    if intrinsic:  # R1 R2 R3
        x, y, z, w = product(e1x, e1y, e1z, e1w, e2x, e2y, e2z, e2w)
        x, y, z, w = product(x, y, z, w, e3x, e3y, e3z, e3w)
    else:  # R3 R2 R1
        x, y, z, w = product(e3x, e3y, e3z, e3w, e2x, e2y, e2z, e2w)
        x, y, z, w = product(x, y, z, w, e1x, e1y, e1z, e1w)
    if needs_sign_flip(x, y, z, w):
        return -x, -y, -z, -w
    return x, y, z, w + 0.0


@jit
def _wrap(angle):
    """Wrap an angle in [-2 pi, 2 pi] to (-pi, pi]."""
    if angle > math.pi:
        return angle - _TWO_PI
    if angle <= -math.pi:
        return angle + _TWO_PI
    return angle


@jit
def _working_axes(i, j, k, intrinsic):
    """
    Axes ``(i, j, k)`` in extrinsic working order, the permutation sign, and whether proper.

    An intrinsic sequence is the extrinsic one reversed; a proper one uses the third axis as k.
    """
    if intrinsic:
        i, k = k, i
    proper = i == k
    if proper:
        k = 3 - i - j
    return i, j, k, (i - j) * (j - k) * (k - i) // 2, proper


@jit
def _bernardes_viollet_terms(x, y, z, w, i, j, k, intrinsic):
    """
    Return the quantities (a, b, c, d) of [1]_ and ``h_ab = |(a, b)|``, ``h_cd = |(c, d)|``.

    Rescaled so that the norms cannot overflow; where they underflow, the split of the
    outer angles they decide moves the rotation by less than 1e-150 of the norm.
    """
    x, y, z, w = scaled_quaternion(x, y, z, w)
    i, j, k, sign, proper = _working_axes(i, j, k, intrinsic)
    v = (x, y, z)
    qi, qj, qk = v[i], v[j], v[k] * sign
    if proper:
        a, b, c, d = w, qi, qj, qk
    else:
        a, b, c, d = w - qj, qi + qk, qj + w, qk - qi
    return a, b, c, d, math.sqrt(a * a + b * b), math.sqrt(c * c + d * d)


@jit
def euler_atan2_arguments(x: float, y: float, z: float, w: float, i: int, j: int, k: int,
                          intrinsic: bool) -> tuple[Vector3, Vector3]:
    """
    Return the three ``atan2`` argument pairs: ``(y1, y2, y3), (x1, x2, x3)``.

    ``atan2(y1, x1)`` is half the middle angle (in [0, pi/2]), ``atan2(y2, x2)`` and
    ``atan2(y3, x3)`` the half sum and half difference of the outer angles.
    """
    a, b, c, d, h_ab, h_cd = _bernardes_viollet_terms(x, y, z, w, i, j, k, intrinsic)
    return (h_cd, b, d), (h_ab, a, c)


@jit
def euler_from_half_angles(half_middle: float, half_sum: float, half_diff: float, h_ab: float,
                           i: int, j: int, k: int, intrinsic: bool) -> Vector3:
    """
    Euler angles from the ``atan2`` of :func:`euler_atan2_arguments`.

    ``half_middle == 0`` is exactly the degeneracy at 0; ``h_ab == 0`` (the first ``x``
    argument) the one at pi.
    """
    _, _, _, sign, proper = _working_axes(i, j, k, intrinsic)
    middle = 2.0 * half_middle
    # Exact degeneracy: only the sum (middle 0) or difference (middle pi) of the
    # outer angles is defined; choose the split that makes the caller's third
    # angle zero (the first of the extrinsic working order when intrinsic).
    if half_middle == 0.0:
        half_diff = half_sum if intrinsic else -half_sum
    elif h_ab == 0.0:
        half_sum = half_diff if intrinsic else -half_diff
    first = _wrap(half_sum - half_diff)
    # The sign before the wrap: wrapping first would turn +pi into -pi.
    third = _wrap(half_sum + half_diff if proper else sign * (half_sum + half_diff))
    if not proper:
        middle -= 0.5 * math.pi
    if intrinsic:
        return third, middle, first
    return first, middle, third


@jit
def euler_from_quaternion_scalar(x: float, y: float, z: float, w: float, i: int, j: int, k: int,
                                 intrinsic: bool) -> Vector3:
    """Euler angles (radians) of a quaternion for the sequence ``(i, j, k)``."""
    (y1, y2, y3), (x1, x2, x3) = euler_atan2_arguments(x, y, z, w, i, j, k, intrinsic)
    return euler_from_half_angles(math.atan2(y1, x1), math.atan2(y2, x2), math.atan2(y3, x3),
                                  x1, i, j, k, intrinsic)


@jit
def singularity_margin_scalar(x: float, y: float, z: float, w: float, i: int, j: int, k: int,
                              intrinsic: bool) -> float:
    """
    Distance (rad) of the middle angle from its nearest singular value, to an ulp (even 1e-300).

    ``2 atan2(h_cd, h_ab)`` in [0, pi] is singular at 0 and pi for every convention.
    """
    _, _, _, _, h_ab, h_cd = _bernardes_viollet_terms(x, y, z, w, i, j, k, intrinsic)
    return 2.0 * math.atan2(min(h_ab, h_cd), max(h_ab, h_cd))


# ----------------------------------------------------------------- kernels

@jit
def unpack_convention(convention: int) -> tuple[int, int, int, bool, bool]:
    """Axes ``(i, j, k)``, intrinsic flag and degrees flag of a convention code."""
    return (convention & 3, (convention >> 2) & 3, (convention >> 4) & 3,
            (convention >> 6) & 1 == 1, (convention >> 7) == 1)


@jit
def _rotations_from_euler(fa, fo, convention):
    """Quaternions or matrices (``fo`` (n, 4) or (n, 9)) of the Euler angles ``fa`` (n, 3)."""
    i, j, k, intrinsic, degrees = unpack_convention(convention)
    scale = _RADIANS_PER_DEGREE if degrees else 1.0
    for s in range(fa.shape[0]):
        bad = vector_status(fa, s, 0)
        if bad >= 0:
            return bad
        x, y, z, w = quaternion_from_euler_scalar(
            fa[s, 0] * scale, fa[s, 1] * scale, fa[s, 2] * scale, i, j, k, intrinsic)
        store_rotation(fo, s, x, y, z, w)
    return -1


@kernel(FLAT_IN, FLAT_OUT, INT)
def _quaternion_from_euler_kernel(angles, out, convention):
    return _rotations_from_euler(samples(angles, 3), samples(out, 4), convention)


@kernel(FLAT_IN, ROWS_OUT, INT)
def _matrix_from_euler_kernel(angles, out, convention):
    return _rotations_from_euler(samples(angles, 3), samples(out, 9), convention)


@jit
def _store_euler(fo, s, x, y, z, w, convention):
    """Write the Euler angles of ``q`` (unit as ``convention`` says) into row ``s`` of ``fo``."""
    i, j, k, intrinsic, degrees = unpack_convention(convention)
    scale = _DEGREES_PER_RADIAN if degrees else 1.0
    a1, a2, a3 = euler_from_quaternion_scalar(x, y, z, w, i, j, k, intrinsic)
    fo[s, 0], fo[s, 1], fo[s, 2] = a1 * scale, a2 * scale, a3 * scale


@kernel(FLAT_IN, FLAT_OUT, INT)
def _euler_from_quaternion_kernel(q, out, convention):
    fq, fo = samples(q, 4), samples(out, 3)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        _store_euler(fo, s, fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3], convention)
    return -1


@kernel(FLAT_IN, FLAT_OUT, INT)
def _euler_from_quaternion_batch_kernel(q, out, convention):
    """
    Batch schedule of ``_euler_from_quaternion_kernel``: each chunk's ``atan2`` in one SIMD loop.

    The branch-free ``atan2`` (0.8 ulp, the C library's 0.5) may differ in the last bit.
    """
    i, j, k, intrinsic, degrees = unpack_convention(convention)
    scale = _DEGREES_PER_RADIAN if degrees else 1.0
    fq, fo = samples(q, 4), samples(out, 3)
    n = fq.shape[0]
    y, x = np.empty(3 * min(n, STAGE_CHUNK)), np.empty(3 * min(n, STAGE_CHUNK))
    for start in range(0, n, STAGE_CHUNK):
        stop = min(n, start + STAGE_CHUNK)
        for s in range(start, stop):
            bad = quaternion_status(fq, s, 0)
            if bad >= 0:
                return bad
            c = 3 * (s - start)
            (y[c], y[c + 1], y[c + 2]), (x[c], x[c + 1], x[c + 2]) = euler_atan2_arguments(
                fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3], i, j, k, intrinsic)
        m = 3 * (stop - start)
        atan2_in_place_kernel(y[:m], x[:m])
        for s in range(start, stop):
            c = 3 * (s - start)
            a1, a2, a3 = euler_from_half_angles(y[c], y[c + 1], y[c + 2], x[c],
                                                i, j, k, intrinsic)
            fo[s, 0], fo[s, 1], fo[s, 2] = a1 * scale, a2 * scale, a3 * scale
    return -1


@kernel(ROWS_IN, FLAT_OUT, FLOAT, INT)
def _euler_from_matrix_kernel(m, out, tolerance, convention):
    """Euler angles of matrices, one loop (the fused kernel of ``convert_matrices``)."""
    fm, fo = matrix_samples(m), samples(out, 3)
    pending = 0
    for s in range(fm.shape[0]):
        bad, x, y, z, w = quaternion_of_matrix(fm, s, tolerance)
        if bad >= 0:
            return bad
        pending += bad == EIGENVECTOR_PENDING
        _store_euler(fo, s, x, y, z, w, convention)
    return -1 - pending


@kernel(FLAT_IN, FLAT_OUT, INT)
def _singularity_margin_kernel(q, out, convention):
    i, j, k, intrinsic, _ = unpack_convention(convention)
    fq, fo = samples(q, 4), samples(out, 0)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        fo[s] = singularity_margin_scalar(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3],
                                          i, j, k, intrinsic)
    return -1


# ------------------------------------------------------------ public API

# The kernels' code of every sequence: i | j << 2 | k << 4 | intrinsic << 6 (| 128: degrees).
_RADIAN_CODES = {name: spec.axes[0] | spec.axes[1] << 2 | spec.axes[2] << 4
                 | int(spec.intrinsic) << 6 for name, spec in SEQUENCE_TABLE.items()}
_DEGREE_CODES = {name: code | 1 << 7 for name, code in _RADIAN_CODES.items()}


def _convention(seq: str, degrees: bool = False) -> int:
    """Return the kernels' code of ``seq`` and the angle unit; ValueError for another ``seq``."""
    try:
        return (_DEGREE_CODES if degrees else _RADIAN_CODES)[seq]
    except (KeyError, TypeError):
        parse_sequence(seq)  # raises the explanatory ValueError
        raise


def quaternion_from_euler(angles: ArrayLike, seq: str, *, degrees: bool = False) -> FloatArray:
    """
    Quaternions of Euler angles.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        First, second and third angle of ``seq``, in radians (degrees if ``degrees``).
    seq : str
        Axis sequence: three of x, y, z, no two consecutive alike; upper case
        intrinsic (``R = R1 R2 R3``), lower case extrinsic (``R = R3 R2 R1``).
        ROS roll-pitch-yaw is ``'xyz'``.
    degrees : bool, optional
        Angles are in degrees.

    Returns
    -------
    ndarray, shape (..., 4)
        Unit quaternions (x, y, z, w), canonical (``w >= 0``).

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf, or an invalid ``seq``.

    """
    return call_unary(_quaternion_from_euler_kernel, angles, 'angles', (3,), (4,),
                      _convention(seq, degrees))


def matrix_from_euler(angles: ArrayLike, seq: str, *, degrees: bool = False) -> FloatArray:
    """
    Rotation matrices of Euler angles.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        First, second and third angle of ``seq`` (radians unless ``degrees``).
    seq : str
        Axis sequence, as in :func:`quaternion_from_euler`. For example
        ``'ZXZ'`` gives the textbook ``R_WB = R_Z(phi) R_X(theta) R_Z(psi)``.
    degrees : bool, optional
        Angles are in degrees.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Body-to-world rotation matrices.

    """
    return call_unary(_matrix_from_euler_kernel, angles, 'angles', (3,), (3, 3),
                      _convention(seq, degrees))


def euler_from_quaternion(q: ArrayLike, seq: str, *, degrees: bool = False) -> FloatArray:
    """
    Euler angles of quaternions.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm.
    seq : str
        Axis sequence, as in :func:`quaternion_from_euler`.
    degrees : bool, optional
        Return degrees instead of radians.

    Returns
    -------
    ndarray, shape (..., 3)
        First, second and third angle of ``seq``. First and third in (-pi, pi]; the middle
        in [-pi/2, pi/2] for Tait-Bryan sequences (three different axes) and in [0, pi] for
        proper Euler sequences. At exact gimbal lock the third angle is 0; near it the
        angles are exact (compare rotations, not angles: they are ill-conditioned there).

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf, a zero quaternion, or an invalid ``seq``.

    References
    ----------
    .. [1] E. Bernardes and S. Viollet, PLOS ONE 17(11), e0276302, 2022.

    """
    return call_unary(_euler_from_quaternion_kernel, q, 'q', (4,), (3,), _convention(seq, degrees),
                      batch_kernel=_euler_from_quaternion_batch_kernel)


def euler_from_matrix(R: ArrayLike, seq: str, *, degrees: bool = False,
                      orthonormal_tolerance: float = DEFAULT_ORTHONORMAL_TOLERANCE,
                      non_orthonormal: str = DEFAULT_NON_ORTHONORMAL) -> FloatArray:
    """
    Euler angles of rotation matrices.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Body-to-world rotation matrices, ``det(R) > 0``.
    seq : str
        Axis sequence, as in :func:`quaternion_from_euler`.
    degrees : bool, optional
        Return degrees instead of radians.
    orthonormal_tolerance, non_orthonormal
        As in :func:`quaternion_from_matrix`: by default every matrix is
        replaced by its nearest rotation.

    Returns
    -------
    ndarray, shape (..., 3)
        Angles as in :func:`euler_from_quaternion` (computed through the
        quaternion: no ``asin`` of a matrix element).

    """
    return convert_matrices(R, orthonormal_tolerance, non_orthonormal, (3,),
                            _euler_from_matrix_kernel, _euler_from_quaternion_kernel,
                            _convention(seq, degrees), _euler_from_quaternion_batch_kernel)


def euler_singularity_margin(q: ArrayLike, seq: str) -> FloatArrayOrScalar:
    """
    How far each orientation is from gimbal lock in the convention ``seq``.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm.
    seq : str
        Axis sequence, as in :func:`quaternion_from_euler`.

    Returns
    -------
    ndarray, shape (...)
        Radians between the middle angle and its nearest singular value
        (+-pi/2 for Tait-Bryan, 0 or pi for proper Euler), in [0, pi/2];
        exact to an ulp even for tiny margins. Compare with a threshold to flag
        samples whose first and third angles are ill-conditioned.

    """
    return call_unary(_singularity_margin_kernel, q, 'q', (4,), (), _convention(seq))
