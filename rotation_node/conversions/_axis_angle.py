"""
Axis-angle and rotation vectors: the exponential and logarithm maps.

A rotation by ``angle`` about the unit axis ``n`` is the quaternion
``(n sin(angle/2), cos(angle/2))`` and the rotation vector ``angle * n``. The angle is
``2 atan2(|q_v|, |q_s|)`` and the axis ``q_v / |q_v|`` (~1 ulp for every angle and norm,
where ``2 acos(q_s)`` fails below ~2e-8 rad); matrices go through the quaternion.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ._matrix import (
    convert_matrices, DEFAULT_NON_ORTHONORMAL, DEFAULT_ORTHONORMAL_TOLERANCE, EIGENVECTOR_PENDING,
    quaternion_of_matrix, store_rotation)
from ._quaternion import (
    half_angle_atan2, needs_sign_flip, quaternion_status, scaled_quaternion, vector_defect,
    vector_norm, vector_status)
from ._runtime import (
    call_binary, call_unary, FLAT_IN, FLAT_OUT, FLOAT, jit, kernel, matrix_samples, ROWS_IN,
    ROWS_OUT, samples, STAGE_CHUNK, status)
from ._trigonometry import sin_cos, sin_cos_in_place_kernel
from ._validation import NON_FINITE, OK, ZERO_NORM

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray, FloatArrayOrScalar, Quaternion4, Vector3


@jit
def rotation_quaternion(ux: float, uy: float, uz: float, k: float,
                        half_angle_cos: float) -> Quaternion4:
    """``(k u, cos(a/2))`` with the canonical sign."""
    x, y, z, w = k * ux, k * uy, k * uz, half_angle_cos
    if needs_sign_flip(x, y, z, w):
        return -x, -y, -z, -w
    return x, y, z, w + 0.0


@jit
def rotation_vector_quaternion(vx: float, vy: float, vz: float, theta: float,
                               half_angle_sin: float, half_angle_cos: float) -> Quaternion4:
    """Exponential map from ``sin``, ``cos`` of ``|v| / 2`` (``sin(t/2) / t``: 1/2 below 2e-8)."""
    k = 0.5 if theta < 2e-8 else half_angle_sin / theta
    return rotation_quaternion(vx, vy, vz, k, half_angle_cos)


@jit
def axis_angle_quaternion(ax: float, ay: float, az: float, half_angle_sin: float,
                          half_angle_cos: float) -> Quaternion4:
    """Quaternion of a rotation about the non-zero axis ``a``, from sin/cos of half the angle."""
    n = vector_norm(ax, ay, az)
    return rotation_quaternion(ax / n, ay / n, az / n, half_angle_sin, half_angle_cos)


@jit
def quaternion_from_rotation_vector_scalar(vx: float, vy: float, vz: float) -> Quaternion4:
    """Exponential map: unit canonical quaternion of the rotation vector ``v``."""
    theta = vector_norm(vx, vy, vz)
    half_sin, half_cos = sin_cos(0.5 * theta)
    return rotation_vector_quaternion(vx, vy, vz, theta, half_sin, half_cos)


@jit
def quaternion_from_axis_angle_scalar(ax: float, ay: float, az: float,
                                      angle: float) -> Quaternion4:
    """Return the unit canonical quaternion of a rotation by ``angle`` about a non-zero axis."""
    half_sin, half_cos = sin_cos(0.5 * angle)
    return axis_angle_quaternion(ax, ay, az, half_sin, half_cos)


@jit
def axis_angle_from_quaternion_scalar(x: float, y: float, z: float,
                                      w: float) -> Quaternion4:
    """Return the unit axis and angle in [0, pi]; the identity gives axis (1, 0, 0), angle 0."""
    x, y, z, w = scaled_quaternion(x, y, z, w)
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    n = vector_norm(x, y, z)
    if n == 0.0:
        return 1.0, 0.0, 0.0, 0.0
    return x / n, y / n, z / n, half_angle_atan2(n, w)


@jit
def rotation_vector_from_quaternion_scalar(x: float, y: float, z: float, w: float) -> Vector3:
    """Logarithm map: rotation vector with norm in [0, pi]."""
    ax, ay, az, angle = axis_angle_from_quaternion_scalar(x, y, z, w)
    return ax * angle, ay * angle, az * angle


# ----------------------------------------------------------------- kernels
# The exponential maps have two schedules, the same formulas: one fused loop, and for
# batches a staged one taking a chunk's sines and cosines in one vectorised loop.

@jit
def _axis_angle_status(ax, ay, az, angle, s):
    """Status of sample ``s``: axis (argument 0) finite and non-zero, angle (1) finite."""
    code = vector_defect(ax, ay, az)
    if code == OK and ax == 0.0 and ay == 0.0 and az == 0.0:
        code = ZERO_NORM
    if code != OK:
        return status(s, 0, code)
    return -1 if math.isfinite(angle) else status(s, 1, NON_FINITE)


@jit
def _rotations_from_axis_angle(fa, ft, angle, fo):
    """Rotations about axes ``fa`` (n, 3) by ``ft`` (n,), or by ``angle`` if ``ft`` is empty."""
    for s in range(fa.shape[0]):
        t = ft[s] if ft.shape[0] else angle
        bad = _axis_angle_status(fa[s, 0], fa[s, 1], fa[s, 2], t, s)
        if bad >= 0:
            return bad
        x, y, z, w = quaternion_from_axis_angle_scalar(fa[s, 0], fa[s, 1], fa[s, 2], t)
        store_rotation(fo, s, x, y, z, w)
    return -1


@jit
def _rotations_from_axis_angle_staged(fa, ft, fo):
    """Return the batch schedule of :func:`_rotations_from_axis_angle`."""
    n = fa.shape[0]
    half_sin, half_cos = np.empty(min(n, STAGE_CHUNK)), np.empty(min(n, STAGE_CHUNK))
    for start in range(0, n, STAGE_CHUNK):
        stop = min(n, start + STAGE_CHUNK)
        for s in range(start, stop):
            bad = _axis_angle_status(fa[s, 0], fa[s, 1], fa[s, 2], ft[s], s)
            if bad >= 0:
                return bad
            half_sin[s - start] = 0.5 * ft[s]
        sin_cos_in_place_kernel(half_sin[:stop - start], half_cos[:stop - start])
        for s in range(start, stop):
            x, y, z, w = axis_angle_quaternion(fa[s, 0], fa[s, 1], fa[s, 2],
                                               half_sin[s - start], half_cos[s - start])
            store_rotation(fo, s, x, y, z, w)
    return -1


# One kernel per output layout (one signature each); ``angle``: one sample's (``angles`` empty).

@kernel(FLAT_IN, FLAT_IN, FLAT_OUT, FLOAT)
def _quaternion_from_axis_angle_kernel(axis, angles, out, angle):
    return _rotations_from_axis_angle(samples(axis, 3), samples(angles, 0), angle, samples(out, 4))


@kernel(FLAT_IN, FLAT_IN, ROWS_OUT, FLOAT)
def _matrix_from_axis_angle_kernel(axis, angles, out, angle):
    return _rotations_from_axis_angle(samples(axis, 3), samples(angles, 0), angle, samples(out, 9))


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT, FLOAT)
def _quaternion_from_axis_angle_batch_kernel(axis, angles, out, angle):
    return _rotations_from_axis_angle_staged(samples(axis, 3), samples(angles, 0), samples(out, 4))


@kernel(FLAT_IN, FLAT_IN, ROWS_OUT, FLOAT)
def _matrix_from_axis_angle_batch_kernel(axis, angles, out, angle):
    return _rotations_from_axis_angle_staged(samples(axis, 3), samples(angles, 0), samples(out, 9))


@jit
def _rotations_from_rotation_vectors(fv, fo):
    """Rotations (quaternions or matrices, as ``fo`` is (n, 4) or (n, 9)) of rotation vectors."""
    for s in range(fv.shape[0]):
        bad = vector_status(fv, s, 0)
        if bad >= 0:
            return bad
        x, y, z, w = quaternion_from_rotation_vector_scalar(fv[s, 0], fv[s, 1], fv[s, 2])
        store_rotation(fo, s, x, y, z, w)
    return -1


@jit
def _rotations_from_rotation_vectors_staged(fv, fo):
    """Return the batch schedule of :func:`_rotations_from_rotation_vectors`."""
    n = fv.shape[0]
    half_sin, half_cos = np.empty(min(n, STAGE_CHUNK)), np.empty(min(n, STAGE_CHUNK))
    for start in range(0, n, STAGE_CHUNK):
        stop = min(n, start + STAGE_CHUNK)
        for s in range(start, stop):
            bad = vector_status(fv, s, 0)
            if bad >= 0:
                return bad
            half_sin[s - start] = 0.5 * vector_norm(fv[s, 0], fv[s, 1], fv[s, 2])
        sin_cos_in_place_kernel(half_sin[:stop - start], half_cos[:stop - start])
        for s in range(start, stop):
            vx, vy, vz = fv[s, 0], fv[s, 1], fv[s, 2]
            x, y, z, w = rotation_vector_quaternion(vx, vy, vz, vector_norm(vx, vy, vz),
                                                    half_sin[s - start], half_cos[s - start])
            store_rotation(fo, s, x, y, z, w)
    return -1


@kernel(FLAT_IN, FLAT_OUT)
def _quaternion_from_rotation_vector_kernel(v, out):
    return _rotations_from_rotation_vectors(samples(v, 3), samples(out, 4))


@kernel(FLAT_IN, ROWS_OUT)
def _matrix_from_rotation_vector_kernel(v, out):
    return _rotations_from_rotation_vectors(samples(v, 3), samples(out, 9))


@kernel(FLAT_IN, FLAT_OUT)
def _quaternion_from_rotation_vector_batch_kernel(v, out):
    return _rotations_from_rotation_vectors_staged(samples(v, 3), samples(out, 4))


@kernel(FLAT_IN, ROWS_OUT)
def _matrix_from_rotation_vector_batch_kernel(v, out):
    return _rotations_from_rotation_vectors_staged(samples(v, 3), samples(out, 9))


@kernel(FLAT_IN, FLAT_OUT)
def axis_angle_kernel(q: FloatArray, out: FloatArray) -> int:
    """``(x, y, z, angle)`` of quaternions into ``out`` (4 n)."""
    fq, fo = samples(q, 4), samples(out, 4)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = axis_angle_from_quaternion_scalar(
            fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1


@kernel(FLAT_IN, FLAT_OUT)
def rotation_vector_kernel(q: FloatArray, out: FloatArray) -> int:
    """Rotation vectors of quaternions into ``out`` (3 n)."""
    fq, fo = samples(q, 4), samples(out, 3)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        fo[s, 0], fo[s, 1], fo[s, 2] = rotation_vector_from_quaternion_scalar(
            fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1


@kernel(ROWS_IN, FLAT_OUT, FLOAT)
def _axis_angle_from_matrix_kernel(m, out, tolerance):
    """Axis-angle of matrices, one loop (the fused kernel of ``convert_matrices``)."""
    fm, fo = matrix_samples(m), samples(out, 4)
    pending = 0
    for s in range(fm.shape[0]):
        bad, x, y, z, w = quaternion_of_matrix(fm, s, tolerance)
        if bad >= 0:
            return bad
        pending += bad == EIGENVECTOR_PENDING
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = axis_angle_from_quaternion_scalar(x, y, z, w)
    return -1 - pending


@kernel(ROWS_IN, FLAT_OUT, FLOAT)
def _rotation_vector_from_matrix_kernel(m, out, tolerance):
    """Rotation vectors of matrices, one loop (the fused kernel of ``convert_matrices``)."""
    fm, fo = matrix_samples(m), samples(out, 3)
    pending = 0
    for s in range(fm.shape[0]):
        bad, x, y, z, w = quaternion_of_matrix(fm, s, tolerance)
        if bad >= 0:
            return bad
        pending += bad == EIGENVECTOR_PENDING
        fo[s, 0], fo[s, 1], fo[s, 2] = rotation_vector_from_quaternion_scalar(x, y, z, w)
    return -1 - pending


# ------------------------------------------------------------ public API

def _split_axis_angle(packed: FloatArray) -> tuple[FloatArray, FloatArrayOrScalar]:
    """Split ``(..., 4)`` rows ``(x, y, z, angle)`` into ``(axis, angle)`` (one sample: scalar)."""
    if packed.ndim == 1:
        return packed[:3], packed[3]
    return packed[..., :3], packed[..., 3]


def quaternion_from_axis_angle(axis: ArrayLike, angle: ArrayLike) -> FloatArray:
    """
    Quaternions of rotations by ``angle`` about ``axis``.

    Parameters
    ----------
    axis : array_like, shape (..., 3)
        Rotation axes, any non-zero length (normalised here).
    angle : array_like, shape (...)
        Angles in radians (right-hand rule); broadcasts with ``axis``.

    Returns
    -------
    ndarray, shape (..., 4)
        Unit quaternions (x, y, z, w), canonical (``w >= 0``).

    Raises
    ------
    ValueError
        Wrong shape, NaN/Inf, or a zero axis.

    """
    return call_binary(_quaternion_from_axis_angle_kernel, axis, angle, ('axis', 'angle'),
                       ((3,), ()), (4,), batch_kernel=_quaternion_from_axis_angle_batch_kernel)


def matrix_from_axis_angle(axis: ArrayLike, angle: ArrayLike) -> FloatArray:
    """
    Rotation matrices of rotations by ``angle`` about ``axis``.

    Parameters
    ----------
    axis : array_like, shape (..., 3)
        Rotation axes, any non-zero length.
    angle : array_like, shape (...)
        Angles in radians; broadcasts with ``axis``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Body-to-world rotation matrices.

    """
    return call_binary(_matrix_from_axis_angle_kernel, axis, angle, ('axis', 'angle'),
                       ((3,), ()), (3, 3), batch_kernel=_matrix_from_axis_angle_batch_kernel)


def axis_angle_from_quaternion(q: ArrayLike) -> tuple[FloatArray, FloatArrayOrScalar]:
    """
    Axis and angle of quaternions.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm.

    Returns
    -------
    axis : ndarray, shape (..., 3)
        Unit rotation axes; ``(1, 0, 0)`` for the identity.
    angle : ndarray, shape (...)
        Angles in [0, pi], ``2 atan2(|q_v|, |q_s|)``: ~1 ulp for every angle.

    """
    packed = call_unary(axis_angle_kernel, q, 'q', (4,), (4,))
    return _split_axis_angle(packed)


def axis_angle_from_matrix(R: ArrayLike, *,
                           orthonormal_tolerance: float = DEFAULT_ORTHONORMAL_TOLERANCE,
                           non_orthonormal: str = DEFAULT_NON_ORTHONORMAL,
                           ) -> tuple[FloatArray, FloatArrayOrScalar]:
    """
    Axis and angle of rotation matrices (through the quaternion, exact near pi).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices, ``det(R) > 0``.
    orthonormal_tolerance, non_orthonormal
        As in :func:`quaternion_from_matrix`: by default every matrix is
        replaced by its nearest rotation.

    Returns
    -------
    axis : ndarray, shape (..., 3)
        Unit axes; ``(1, 0, 0)`` for the identity.
    angle : ndarray, shape (...)
        Angles in [0, pi].

    """
    packed = convert_matrices(R, orthonormal_tolerance, non_orthonormal, (4,),
                              _axis_angle_from_matrix_kernel, axis_angle_kernel)
    return _split_axis_angle(packed)


def quaternion_from_rotation_vector(v: ArrayLike) -> FloatArray:
    """
    Exponential map: quaternions of rotation vectors.

    Parameters
    ----------
    v : array_like, shape (..., 3)
        Rotation vectors ``angle * axis`` (radians), any length.

    Returns
    -------
    ndarray, shape (..., 4)
        Unit quaternions (x, y, z, w), canonical; exact to ~1 ulp from
        ``|v| = 0`` (identity) up.

    """
    return call_unary(_quaternion_from_rotation_vector_kernel, v, 'v', (3,), (4,),
                      batch_kernel=_quaternion_from_rotation_vector_batch_kernel)


def matrix_from_rotation_vector(v: ArrayLike) -> FloatArray:
    """
    Exponential map: rotation matrices of rotation vectors (Rodrigues).

    Parameters
    ----------
    v : array_like, shape (..., 3)
        Rotation vectors (radians).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Body-to-world rotation matrices. Computed through the quaternion, so
        no ``(1 - cos t) / t^2`` cancellation.

    """
    return call_unary(_matrix_from_rotation_vector_kernel, v, 'v', (3,), (3, 3),
                      batch_kernel=_matrix_from_rotation_vector_batch_kernel)


def rotation_vector_from_quaternion(q: ArrayLike) -> FloatArray:
    """
    Logarithm map: rotation vectors of quaternions.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm.

    Returns
    -------
    ndarray, shape (..., 3)
        Rotation vectors with norm in [0, pi] (the shorter way round).

    """
    return call_unary(rotation_vector_kernel, q, 'q', (4,), (3,))


def rotation_vector_from_matrix(R: ArrayLike, *,
                                orthonormal_tolerance: float = DEFAULT_ORTHONORMAL_TOLERANCE,
                                non_orthonormal: str = DEFAULT_NON_ORTHONORMAL) -> FloatArray:
    """
    Logarithm map: rotation vectors of rotation matrices.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices, ``det(R) > 0``.
    orthonormal_tolerance, non_orthonormal
        As in :func:`quaternion_from_matrix`: by default every matrix is
        replaced by its nearest rotation.

    Returns
    -------
    ndarray, shape (..., 3)
        Rotation vectors with norm in [0, pi]; exact near pi, where ``acos``
        of the trace loses everything.

    """
    return convert_matrices(R, orthonormal_tolerance, non_orthonormal, (3,),
                            _rotation_vector_from_matrix_kernel, rotation_vector_kernel)
