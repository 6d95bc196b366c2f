"""
Rotation matrices: quaternion <-> matrix and the nearest rotation of a noisy matrix.

``R`` maps body coordinates to world coordinates; ``R = matrix_from_quaternion(q)``
is the seed's ``(2 q_s^2 - 1) I + 2 q_s [q_v]x + 2 q_v q_v^T``.

Matrix to quaternion uses Markley's pivot (the largest of trace, R00, R11, R22
selects the best-conditioned column of the symmetric 4x4 matrix), exact to an
ulp or two everywhere, including rotations by pi, where the seed's trace
formula returns NaN. A matrix that is not orthonormal to rounding is replaced
by its nearest rotation (Frobenius norm): by Newton-Schulz iteration when it is
close, else as the dominant eigenvector of Bar-Itzhack's symmetric 4x4 matrix.

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
import math

import numpy as np

from ._quaternion import (call_unary, canonical_kernel, canonical_unit_quaternion, is_batch,
                          is_single_sample, jit, quaternion_status, scaled_quaternion, status)
from ._validation import (NON_FINITE, NOT_ORTHONORMAL, NOT_ROTATION, OK, float_array,
                          raise_sample_error)

DEFAULT_ORTHONORMAL_TOLERANCE = 1e-6


@jit
def matrix_entries(x, y, z, w):
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
def store_matrix(fo, s, x, y, z, w):
    """Write ``R(q)`` into row ``s`` of ``fo`` (shape (n, 9), row-major matrices)."""
    # One unpacking assignment: indexing the tuple in a loop would spill it
    # to the stack and cost ~2x the whole kernel.
    (fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3], fo[s, 4], fo[s, 5],
     fo[s, 6], fo[s, 7], fo[s, 8]) = matrix_entries(x, y, z, w)


@jit
def store_rotation(fo, s, x, y, z, w):
    """Write ``q`` into row ``s`` of ``fo``: as it is if ``fo`` is (n, 4), as ``R(q)`` if (n, 9)."""
    if fo.shape[1] == 9:
        store_matrix(fo, s, x, y, z, w)
    else:
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = x, y, z, w


# Deviation from orthonormality below which a matrix is used as it is: at this
# level Markley's quaternion is within rounding of the nearest rotation's.
EXACT_ORTHONORMAL = 1e-15
# Newton-Schulz converges for deviations below 1 (singular values in (0, sqrt 3));
# beyond this the eigenvector method is used instead.
NEWTON_SCHULZ_LIMIT = 0.5


@jit
def orthonormality_deviation(m):
    """Largest absolute element of ``m^T m - I``."""
    worst = 0.0
    for a in range(3):
        for b in range(a, 3):
            g = m[0, a] * m[0, b] + m[1, a] * m[1, b] + m[2, a] * m[2, b]
            if a == b:
                g -= 1.0
            worst = max(worst, abs(g))
    return worst


@jit
def matrix_defect(m):
    """Defect code of a 3x3 matrix: NON_FINITE, NOT_ROTATION (det <= 0) or OK."""
    for r in range(3):
        for c in range(3):
            if not math.isfinite(m[r, c]):
                return NON_FINITE
    det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
           - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
           + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
    if not det > 0.0:
        return NOT_ROTATION
    return OK


@jit
def newton_schulz_orthonormalize(x, work):
    """
    Replace ``x`` by its orthogonal polar factor (the nearest rotation when det > 0).

    Iterates ``X <- X (3 I - X^T X) / 2`` (Bjorck and Bowie 1971), which
    converges quadratically from any deviation below 1; returns whether the
    deviation fell to rounding level within the iteration budget.
    """
    for _ in range(12):
        deviation = orthonormality_deviation(x)
        if deviation <= EXACT_ORTHONORMAL:
            return True
        for a in range(3):
            for b in range(3):
                g = x[0, a] * x[0, b] + x[1, a] * x[1, b] + x[2, a] * x[2, b]
                work[a, b] = (1.5 if a == b else 0.0) - 0.5 * g
        for r in range(3):
            x0, x1, x2 = x[r, 0], x[r, 1], x[r, 2]
            for c in range(3):
                x[r, c] = x0 * work[0, c] + x1 * work[1, c] + x2 * work[2, c]
    return orthonormality_deviation(x) <= EXACT_ORTHONORMAL


@jit
def quaternion_from_orthonormal(m):
    """Markley's quaternion of a rotation matrix, unit and canonical."""
    m00, m11, m22 = m[0, 0], m[1, 1], m[2, 2]
    trace = m00 + m11 + m22
    if trace >= m00 and trace >= m11 and trace >= m22:
        x, y, z, w = m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1], 1.0 + trace
    elif m00 >= m11 and m00 >= m22:
        x, y, z, w = 1.0 + m00 - m11 - m22, m[0, 1] + m[1, 0], m[0, 2] + m[2, 0], m[2, 1] - m[1, 2]
    elif m11 >= m22:
        x, y, z, w = m[0, 1] + m[1, 0], 1.0 + m11 - m00 - m22, m[1, 2] + m[2, 1], m[0, 2] - m[2, 0]
    else:
        x, y, z, w = m[0, 2] + m[2, 0], m[1, 2] + m[2, 1], 1.0 + m22 - m00 - m11, m[1, 0] - m[0, 1]
    return canonical_unit_quaternion(x, y, z, w)


@jit
def _matrix_from_quaternion_kernel(q, out):
    fq, fo = q.reshape(-1, 4), out.reshape(-1, 9)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        store_matrix(fo, s, fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1


@jit
def quaternion_from_matrix_kernel(m, out, tolerance):
    """
    Quaternions of matrices (any leading shape) into ``out`` (same leading shape, 4).

    Returns the status of the first bad sample, or ``-1 - count`` where
    ``count`` rows of ``out`` are NaN: matrices too far from orthonormal for
    Newton-Schulz, left for the eigenvector method. A matrix deviating from
    orthonormality by more than ``tolerance`` is an error (``inf``: none is);
    every matrix deviating by more than rounding is replaced by its nearest
    rotation before Markley's formula is applied.
    """
    fm, fo = m.reshape(-1, 3, 3), out.reshape(-1, 4)
    count = 0
    scratch = np.empty((2, 3, 3))   # one allocation: this kernel also serves single matrices
    x, work = scratch[0], scratch[1]
    for s in range(fm.shape[0]):
        code = matrix_defect(fm[s])
        if code != OK:
            return status(s, 0, code)
        deviation = orthonormality_deviation(fm[s])
        if deviation > tolerance:
            return status(s, 0, NOT_ORTHONORMAL)
        if deviation <= EXACT_ORTHONORMAL:
            fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = quaternion_from_orthonormal(fm[s])
            continue
        x[:, :] = fm[s]
        if deviation < NEWTON_SCHULZ_LIMIT and newton_schulz_orthonormalize(x, work):
            fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = quaternion_from_orthonormal(x)
        else:
            fo[s, :] = np.nan
            count += 1
    return -1 - count


def nearest_rotation_quaternions(m):
    """
    Quaternions of the rotations nearest (Frobenius norm) to matrices with det > 0.

    The maximiser of ``trace(R(q)^T M)`` is the eigenvector of the largest
    eigenvalue of Bar-Itzhack's symmetric matrix ``K(M)`` [3]_: the same
    rotation as the orthogonal Procrustes (SVD) solution.

    Parameters
    ----------
    m : ndarray, shape (n, 3, 3)
        Finite matrices with positive determinant.

    Returns
    -------
    ndarray, shape (n, 4)
        Unit quaternions (x, y, z, w), canonical.
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
    canonical_kernel(np.ascontiguousarray(vectors[:, :, 3]), q)
    return q


# ------------------------------------------------------------ public API

def matrix_from_quaternion(q):
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
    """The kernels' ``tolerance``: the deviation beyond which a matrix is an error."""
    if type(non_orthonormal) is not str or non_orthonormal not in ('project', 'raise'):
        raise ValueError(
            f"Expected `non_orthonormal` to be 'project' or 'raise', got {non_orthonormal!r}.")
    if not orthonormal_tolerance >= 0.0:
        raise ValueError(
            f'Expected `orthonormal_tolerance` >= 0, got {orthonormal_tolerance!r}.')
    return math.inf if non_orthonormal == 'project' else float(orthonormal_tolerance)


def convert_matrices(R, orthonormal_tolerance, non_orthonormal, out_trailing,
                     fused_kernel, quaternion_kernel, *args, batch_kernel=None):
    """
    The body of every ``*_from_matrix`` conversion: a kernel on the quaternions of ``R``.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        The public argument.
    orthonormal_tolerance, non_orthonormal
        As in :func:`quaternion_from_matrix` (validated here).
    out_trailing : tuple of int
        Trailing shape of the output per matrix.
    fused_kernel : callable
        ``fused_kernel(m, out, tolerance, *args)``: both steps in one compiled
        call (``quaternion_from_matrix_kernel`` then ``quaternion_kernel``), for
        inputs below ``BATCH_SAMPLES`` matrices, such as a single matrix. Returns a
        status like ``quaternion_from_matrix_kernel``'s; below -1 (some matrix
        needs the eigenvector method) the two-step route takes over.
    quaternion_kernel : callable or None
        ``quaternion_kernel(q, out, *args)`` on the flat quaternions; None
        returns the quaternions.
    batch_kernel : callable, optional
        Used instead of ``quaternion_kernel`` for ``BATCH_SAMPLES`` matrices or more.

    Returns
    -------
    ndarray
        ``R``'s leading shape followed by ``out_trailing``.
    """
    tolerance = _kernel_tolerance(orthonormal_tolerance, non_orthonormal)
    if is_single_sample(R, (3, 3)):
        m, shape, batch = R, out_trailing, False
    else:
        m = float_array(R, 'R', (3, 3))
        shape, batch = m.shape[:-2] + out_trailing, is_batch(m, (3, 3))
    if not batch:
        out = np.empty(shape)
        bad = fused_kernel(m, out, tolerance, *args)
        if bad >= 0:
            raise_sample_error(bad, ('R',), (m,), ((3, 3),))
        if bad == -1:
            return out
    q = _flat_quaternions(m, tolerance)
    if quaternion_kernel is None:   # the quaternions are the result
        return q.reshape(shape)
    out = np.empty(shape)
    (batch_kernel if batch_kernel is not None and batch else quaternion_kernel)(q, out, *args)
    return out


def _flat_quaternions(m, tolerance):
    """Quaternions (n, 4) of the validated matrices ``m``, eigenvector method included."""
    q = np.empty((m.size // 9, 4))
    bad = quaternion_from_matrix_kernel(m, q, tolerance)
    if bad >= 0:
        raise_sample_error(bad, ('R',), (m,), ((3, 3),))
    if bad < -1:
        rows = np.isnan(q[:, 3])
        q[rows] = nearest_rotation_quaternions(m.reshape(-1, 3, 3)[rows])
    return q


def quaternion_from_matrix(R, *, orthonormal_tolerance=DEFAULT_ORTHONORMAL_TOLERANCE,
                           non_orthonormal='project'):
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

    Notes
    -----
    The result is the quaternion of the rotation nearest to ``R``, to
    rounding, for every accepted matrix: one that is orthonormal to within
    1e-15 is used as it is (Markley's pivot); any other is first replaced by
    its nearest rotation, by Newton-Schulz (Bjorck) iteration when it deviates
    by less than 0.5, else by Bar-Itzhack's eigenvector method.

    Returns
    -------
    ndarray, shape (..., 4)
        Unit quaternions (x, y, z, w), canonical (``w >= 0``).

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf, ``det(R) <= 0`` (never a rotation), or a
        non-orthonormal matrix with ``non_orthonormal='raise'``.

    References
    ----------
    .. [1] F. L. Markley, "Unit Quaternion from Rotation Matrix", JGCD 31(2), 2008.
    .. [2] I. Y. Bar-Itzhack, "New Method for Extracting the Quaternion from a
       Rotation Matrix", JGCD 23(6), 2000.
    """
    return convert_matrices(R, orthonormal_tolerance, non_orthonormal, (4,),
                            quaternion_from_matrix_kernel, None)


