"""
Rotation matrices: quaternion <-> matrix, and the nearest rotation of a noisy matrix.

Matrix to quaternion uses Markley's form [1]_ of Shepperd's pivot [2]_ (exact to an ulp or
two, rotations by pi included); a matrix not orthonormal to rounding is first replaced by
its nearest rotation (Frobenius norm): Newton-Schulz iteration [4]_ when close, else the
dominant eigenvector of Bar-Itzhack's symmetric 4x4 matrix [3]_ (docs/numerics.md).

References
----------
.. [1] F. L. Markley, "Unit Quaternion from Rotation Matrix", J. Guidance,
   Control, and Dynamics 31(2), 2008.
.. [2] S. W. Shepperd, "Quaternion from Rotation Matrix", J. Guidance and
   Control 1(3), 1978.
.. [3] I. Y. Bar-Itzhack, "New Method for Extracting the Quaternion from a
   Rotation Matrix", J. Guidance, Control, and Dynamics 23(6), 2000.
.. [4] A. Bjorck and C. Bowie, "An Iterative Algorithm for Computing the Best
   Estimate of an Orthogonal Matrix", SIAM J. Numer. Anal. 8(2), 1971.

"""
from __future__ import annotations

import math
from typing import Any, Optional, TYPE_CHECKING

import numpy as np

from ._quaternion import (
    canonical_kernel, canonical_unit_quaternion, quaternion_status, scaled_quaternion)
from ._runtime import (
    call_unary, FLAT_IN, FLAT_OUT, FLOAT, is_batch, jit, kernel, kernel_layout,
    matrix_samples, new_array, ROWS_IN, ROWS_OUT, samples, single_sample, status)
from ._validation import (
    float_array, NON_FINITE, NOT_ORTHONORMAL, NOT_ROTATION, OK, raise_sample_error)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray, Matrix9, Quaternion4

#: Defaults of the ``*_from_matrix`` conversions' ``orthonormal_tolerance`` and
#: ``non_orthonormal``: every matrix is replaced by its nearest rotation.
DEFAULT_ORTHONORMAL_TOLERANCE = 1e-6
DEFAULT_NON_ORTHONORMAL = 'project'


@jit
def matrix_entries(x: float, y: float, z: float, w: float) -> Matrix9:
    """Row-major entries of ``R(q)``; ``q`` any non-zero scale (rescaled exactly first)."""
    x, y, z, w = scaled_quaternion(x, y, z, w)
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    return (1.0 - (yy + zz), xy - wz, xz + wy,
            xy + wz, 1.0 - (xx + zz), yz - wx,
            xz - wy, yz + wx, 1.0 - (xx + yy))


@jit
def store_matrix(fo: FloatArray, s: int, x: float, y: float, z: float, w: float) -> None:
    """Write ``R(q)`` into row ``s`` of ``fo`` (n, 9), in one assignment (a loop: ~2x slower)."""
    (fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3], fo[s, 4], fo[s, 5],
     fo[s, 6], fo[s, 7], fo[s, 8]) = matrix_entries(x, y, z, w)


@jit
def store_rotation(fo: FloatArray, s: int, x: float, y: float, z: float, w: float) -> None:
    """Write ``q`` into row ``s`` of ``fo``: as it is if ``fo`` is (n, 4), ``R(q)`` if (n, 9)."""
    if fo.shape[1] == 9:
        store_matrix(fo, s, x, y, z, w)
    else:
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = x, y, z, w


# Below this deviation from orthonormality Markley's quaternion is within rounding of the
# nearest rotation's.
EXACT_ORTHONORMAL = 1e-15
# Newton-Schulz converges below 1; beyond this the eigenvector method takes over.
NEWTON_SCHULZ_LIMIT = 0.5
# Status of a matrix left for the eigenvector method (see quaternion_of_matrix).
EIGENVECTOR_PENDING = -2

# The per-matrix functions take 9-tuples of row-major entries: a matrix lives in registers.


@jit
def matrix_at(fm: FloatArray, s: int) -> Matrix9:
    """Matrix ``s`` of ``fm`` (shape (n, 3, 3)) as a 9-tuple, row-major."""
    return (fm[s, 0, 0], fm[s, 0, 1], fm[s, 0, 2],
            fm[s, 1, 0], fm[s, 1, 1], fm[s, 1, 2],
            fm[s, 2, 0], fm[s, 2, 1], fm[s, 2, 2])


@jit
def matrix_defect(m: Matrix9) -> int:
    """Defect code of a matrix (9-tuple): NON_FINITE, NOT_ROTATION (det <= 0) or OK."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    if not (math.isfinite(m00) and math.isfinite(m01) and math.isfinite(m02)
            and math.isfinite(m10) and math.isfinite(m11) and math.isfinite(m12)
            and math.isfinite(m20) and math.isfinite(m21) and math.isfinite(m22)):
        return NON_FINITE
    det = (m00 * (m11 * m22 - m12 * m21)
           - m01 * (m10 * m22 - m12 * m20)
           + m02 * (m10 * m21 - m11 * m20))
    if not det > 0.0:
        return NOT_ROTATION
    return OK


@jit
def gram_entries(m: Matrix9) -> tuple[float, float, float, float, float, float]:
    """Return the six distinct entries of ``m^T m`` (9-tuple): g00, g11, g22, g01, g02, g12."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    return (m00 * m00 + m10 * m10 + m20 * m20,
            m01 * m01 + m11 * m11 + m21 * m21,
            m02 * m02 + m12 * m12 + m22 * m22,
            m00 * m01 + m10 * m11 + m20 * m21,
            m00 * m02 + m10 * m12 + m20 * m22,
            m01 * m02 + m11 * m12 + m21 * m22)


@jit
def gram_deviation(g: tuple[float, float, float, float, float, float]) -> float:
    """Largest absolute element of ``m^T m - I`` from its entries ``g`` (:func:`gram_entries`)."""
    g00, g11, g22, g01, g02, g12 = g
    return max(abs(g00 - 1.0), abs(g11 - 1.0), abs(g22 - 1.0), abs(g01), abs(g02), abs(g12))


@jit
def orthonormality_deviation(m: Matrix9) -> float:
    """Largest absolute element of ``m^T m - I`` (9-tuple)."""
    return gram_deviation(gram_entries(m))


@jit
def newton_schulz_step(m: Matrix9, g: tuple[float, float, float, float, float, float]) -> Matrix9:
    """Take one step ``X <- X (3 I - X^T X) / 2`` of Bjorck and Bowie's iteration (g: X^T X)."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    g00, g11, g22, g01, g02, g12 = g
    w00, w11, w22 = 1.5 - 0.5 * g00, 1.5 - 0.5 * g11, 1.5 - 0.5 * g22
    w01, w02, w12 = -0.5 * g01, -0.5 * g02, -0.5 * g12
    return (m00 * w00 + m01 * w01 + m02 * w02,
            m00 * w01 + m01 * w11 + m02 * w12,
            m00 * w02 + m01 * w12 + m02 * w22,
            m10 * w00 + m11 * w01 + m12 * w02,
            m10 * w01 + m11 * w11 + m12 * w12,
            m10 * w02 + m11 * w12 + m12 * w22,
            m20 * w00 + m21 * w01 + m22 * w02,
            m20 * w01 + m21 * w11 + m22 * w12,
            m20 * w02 + m21 * w12 + m22 * w22)


@jit
def newton_schulz_orthonormalized(m: Matrix9) -> tuple[bool, Matrix9]:
    """``(converged, x)``: the orthogonal polar factor of ``m`` by Newton-Schulz (<= 12 steps)."""
    for _ in range(12):
        g = gram_entries(m)
        if gram_deviation(g) <= EXACT_ORTHONORMAL:
            return True, m
        m = newton_schulz_step(m, g)
    return orthonormality_deviation(m) <= EXACT_ORTHONORMAL, m


@jit
def quaternion_from_orthonormal(m: Matrix9) -> Quaternion4:
    """Markley's quaternion of a rotation matrix (9-tuple), unit and canonical."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    trace = m00 + m11 + m22
    if trace >= m00 and trace >= m11 and trace >= m22:
        x, y, z, w = m21 - m12, m02 - m20, m10 - m01, 1.0 + trace
    elif m00 >= m11 and m00 >= m22:
        x, y, z, w = 1.0 + m00 - m11 - m22, m01 + m10, m02 + m20, m21 - m12
    elif m11 >= m22:
        x, y, z, w = m01 + m10, 1.0 + m11 - m00 - m22, m12 + m21, m02 - m20
    else:
        x, y, z, w = m02 + m20, m12 + m21, 1.0 + m22 - m00 - m11, m10 - m01
    return canonical_unit_quaternion(x, y, z, w)


@jit
def quaternion_of_matrix(fm: FloatArray, s: int,
                         tolerance: float) -> tuple[int, float, float, float, float]:
    """
    ``(bad, x, y, z, w)``: the quaternion of the rotation nearest to matrix ``s`` of ``fm``.

    ``bad``: -1, a defect's status, or ``EIGENVECTOR_PENDING`` (NaN quaternion) for a matrix
    too far from orthonormal for Newton-Schulz (:func:`nearest_rotation_quaternions`).
    """
    nan = math.nan
    m = matrix_at(fm, s)
    code = matrix_defect(m)
    if code != OK:
        return status(s, 0, code), nan, nan, nan, nan
    deviation = orthonormality_deviation(m)
    if deviation > tolerance:
        return status(s, 0, NOT_ORTHONORMAL), nan, nan, nan, nan
    if not deviation <= EXACT_ORTHONORMAL:
        converged = False
        if deviation < NEWTON_SCHULZ_LIMIT:
            converged, m = newton_schulz_orthonormalized(m)
        if not converged:
            return EIGENVECTOR_PENDING, nan, nan, nan, nan
    x, y, z, w = quaternion_from_orthonormal(m)
    return -1, x, y, z, w


@kernel(FLAT_IN, ROWS_OUT)
def _matrix_from_quaternion_kernel(q, out):
    fq, fo = samples(q, 4), samples(out, 9)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        store_matrix(fo, s, fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1


@kernel(ROWS_IN, FLAT_OUT, FLOAT)
def quaternion_from_matrix_kernel(m: FloatArray, out: FloatArray, tolerance: float) -> int:
    """Quaternions of the matrices ``m`` into ``out``; ``-1 - pending``: rows left NaN."""
    fm, fo = matrix_samples(m), samples(out, 4)
    pending = 0
    for s in range(fm.shape[0]):
        bad, x, y, z, w = quaternion_of_matrix(fm, s, tolerance)
        if bad >= 0:
            return bad
        pending += bad == EIGENVECTOR_PENDING
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = x, y, z, w
    return -1 - pending


def nearest_rotation_quaternions(m: FloatArray) -> FloatArray:
    """
    Canonical quaternions (n, 4) of the rotations nearest to finite matrices (n, 3, 3), det > 0.

    The maximiser of ``trace(R(q)^T M)``: the eigenvector of the largest eigenvalue of
    Bar-Itzhack's ``K(M)`` [3]_, the orthogonal Procrustes (SVD) rotation.
    """
    m00, m01, m02 = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    m10, m11, m12 = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    m20, m21, m22 = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    k = np.empty((m.shape[0], 4, 4))
    k[:, 0, 0] = m00 - m11 - m22
    k[:, 1, 1] = m11 - m00 - m22
    k[:, 2, 2] = m22 - m00 - m11
    k[:, 3, 3] = m00 + m11 + m22
    k[:, 0, 1] = k[:, 1, 0] = m01 + m10
    k[:, 0, 2] = k[:, 2, 0] = m02 + m20
    k[:, 1, 2] = k[:, 2, 1] = m12 + m21
    k[:, 0, 3] = k[:, 3, 0] = m21 - m12
    k[:, 1, 3] = k[:, 3, 1] = m02 - m20
    k[:, 2, 3] = k[:, 3, 2] = m10 - m01
    _, vectors = np.linalg.eigh(k)
    q = np.empty((m.shape[0], 4))
    canonical_kernel(np.ascontiguousarray(vectors[:, :, 3]).reshape(-1), q.reshape(-1))
    return q


# ------------------------------------------------------------ public API

def matrix_from_quaternion(q: ArrayLike) -> FloatArray:
    """
    Rotation matrices of quaternions.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), scalar last, any non-zero norm (the rotation
        of ``q / |q|``; norms from 1e-160 to 1e+160 are handled exactly).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R`` mapping body coordinates to world coordinates (active rotation).

    Raises
    ------
    ValueError
        Wrong shape, a NaN/Inf component, or a zero quaternion.

    """
    return call_unary(_matrix_from_quaternion_kernel, q, 'q', (4,), (3, 3))


def _kernel_tolerance(orthonormal_tolerance, non_orthonormal):
    """Return the kernels' ``tolerance``: the deviation beyond which a matrix is an error."""
    try:
        valid = bool(orthonormal_tolerance >= 0.0)
    except (TypeError, ValueError):   # not a number, or an array
        valid = False
    if not valid:
        raise ValueError(
            'Expected `orthonormal_tolerance` to be a number >= 0, got '
            f'{orthonormal_tolerance!r}.')
    if type(non_orthonormal) is str:
        if non_orthonormal == 'project':
            return math.inf
        if non_orthonormal == 'raise':
            return float(orthonormal_tolerance)
    raise ValueError(
        f"Expected `non_orthonormal` to be 'project' or 'raise', got {non_orthonormal!r}.")


def convert_matrices(R: ArrayLike, orthonormal_tolerance: float, non_orthonormal: str,
                     out_trailing: tuple[int, ...], fused_kernel: Any, quaternion_kernel: Any,
                     convention: Optional[int] = None, batch_kernel: Any = None) -> Any:
    """
    Return the body of every ``*_from_matrix`` conversion: a kernel on the quaternions of ``R``.

    Below ``BATCH_SAMPLES`` matrices ``fused_kernel(m, out, tolerance[, convention])`` does
    both steps in one loop; where it returns below -1 (the eigenvector method) or for a
    batch, the quaternions go to ``quaternion_kernel`` (``batch_kernel``; None: the
    quaternions are the result). ``convention`` is named, not ``*args`` (~50 ns a call).
    """
    if (orthonormal_tolerance is DEFAULT_ORTHONORMAL_TOLERANCE
            and non_orthonormal is DEFAULT_NON_ORTHONORMAL):
        tolerance = math.inf   # the defaults themselves, valid: no check (~80 ns a call)
    else:
        tolerance = _kernel_tolerance(orthonormal_tolerance, non_orthonormal)
    single = single_sample(R, (3, 3))
    if single is not None:   # already in the canonical layout, as is its result
        out = new_array(out_trailing)
        if convention is None:
            bad = fused_kernel.call_unchecked(single, out, tolerance)
        else:
            bad = fused_kernel.call_unchecked(single, out, tolerance, convention)
        if bad == -1:
            return out   # else the general path raises or takes the eigenvector method
    a = float_array(R, 'R', (3, 3))
    m = kernel_layout(a, (3, 3))
    shape, batch = a.shape[:-2] + out_trailing, is_batch(a, (3, 3))
    out = np.empty(shape)
    flat_out = kernel_layout(out, out_trailing)
    if not batch:
        if convention is None:
            bad = fused_kernel(m, flat_out, tolerance)
        else:
            bad = fused_kernel(m, flat_out, tolerance, convention)
        if bad == -1:
            return out
        if bad >= 0:
            raise_sample_error(bad, ('R',), (a,), ((3, 3),))
    q = _flat_quaternions(a, m, tolerance)
    if quaternion_kernel is None:   # the quaternions are the result
        return q.reshape(shape)
    kernel_ = batch_kernel if batch_kernel is not None and batch else quaternion_kernel
    if convention is None:
        kernel_(q.reshape(-1), flat_out)
    else:
        kernel_(q.reshape(-1), flat_out, convention)
    return out


def _flat_quaternions(a, m, tolerance):
    """Quaternions (n, 4) of the matrices ``a`` (canonical layout ``m``), eigenvectors included."""
    q = np.empty((m.shape[0] // 3, 4))
    bad = quaternion_from_matrix_kernel(m, q.reshape(-1), tolerance)
    if bad >= 0:
        raise_sample_error(bad, ('R',), (a,), ((3, 3),))
    if bad < -1:
        rows = np.isnan(q[:, 3])
        q[rows] = nearest_rotation_quaternions(m.reshape(-1, 3, 3)[rows])
    return q


def quaternion_from_matrix(R: ArrayLike, *,
                           orthonormal_tolerance: float = DEFAULT_ORTHONORMAL_TOLERANCE,
                           non_orthonormal: str = DEFAULT_NON_ORTHONORMAL) -> FloatArray:
    """
    Quaternions of rotation matrices.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices mapping body to world coordinates; ``det(R) > 0``.
    orthonormal_tolerance : float, optional
        Largest absolute element of ``R^T R - I`` accepted (default 1e-6, which
        float32 round-off passes). Only used with ``non_orthonormal='raise'``.
    non_orthonormal : {'project', 'raise'}, optional
        What to do with a matrix beyond the tolerance: ``'project'`` (default)
        uses the nearest rotation in the Frobenius norm (the SVD / orthogonal
        Procrustes answer); ``'raise'`` raises ``ValueError``.

    Returns
    -------
    ndarray, shape (..., 4)
        Unit quaternions (x, y, z, w), canonical (``w >= 0``).

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf, ``det(R) <= 0`` (never a rotation), or a
        non-orthonormal matrix with ``non_orthonormal='raise'``.

    Notes
    -----
    The quaternion of the rotation nearest to ``R``, to rounding, for every accepted
    matrix: within 1e-15 of orthonormal, Markley's pivot as it is; else the nearest
    rotation first, by Newton-Schulz (Bjorck) iteration below a deviation of 0.5, else
    by Bar-Itzhack's eigenvector method.

    References
    ----------
    .. [1] F. L. Markley, "Unit Quaternion from Rotation Matrix", JGCD 31(2), 2008.
    .. [2] I. Y. Bar-Itzhack, "New Method for Extracting the Quaternion from a
       Rotation Matrix", JGCD 23(6), 2000.

    """
    return convert_matrices(R, orthonormal_tolerance, non_orthonormal, (4,),
                            quaternion_from_matrix_kernel, None)
