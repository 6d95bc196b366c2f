"""
Axis-angle and rotation vectors: the exponential and logarithm maps.

A rotation by ``angle`` about the unit ``axis`` n is the quaternion
``(n sin(angle/2), cos(angle/2))`` and the rotation vector ``angle * n``.

The seed's ``theta = 2 acos(q_s)`` and ``n = q_v / sqrt(1 - q_s^2)`` lose half
the digits near 0 (and all of them below ~2e-8 rad) and break for a quaternion
slightly off unit length; here the angle is ``2 atan2(|q_v|, |q_s|)`` and the
axis ``q_v / |q_v|``, exact to ~1 ulp for every angle and every norm. Matrix
forms go through the quaternion (never ``acos`` of the trace, which is
useless near pi).
"""
import math

import numpy as np

from ._matrix import (DEFAULT_ORTHONORMAL_TOLERANCE, flat_quaternions_from_matrices,
                      matrix_from_unit_direction)
from ._quaternion import (canonical_unit_quaternion, half_angle_atan2, jit, quaternion_defect,
                          scaled_quaternion, vector_defect, vector_norm)
from ._validation import (NON_FINITE, OK, ZERO_NORM, broadcast_flat, flat_array,
                          raise_sample_error)


@jit
def quaternion_from_rotation_vector_scalar(vx, vy, vz):
    """Exponential map: unit canonical quaternion of the rotation vector ``v``."""
    theta = vector_norm(vx, vy, vz)
    half = 0.5 * theta
    # sin(h)/h rounds to 1 below h ~ 2.6e-8; the guard also covers theta = 0.
    k = 0.5 if half < 1e-8 else 0.5 * math.sin(half) / half
    return canonical_unit_quaternion(k * vx, k * vy, k * vz, math.cos(half))


@jit
def axis_angle_from_quaternion_scalar(x, y, z, w):
    """Unit axis and angle in [0, pi]; the identity gives axis (1, 0, 0), angle 0."""
    x, y, z, w = scaled_quaternion(x, y, z, w)
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    n = vector_norm(x, y, z)
    if n == 0.0:
        return 1.0, 0.0, 0.0, 0.0
    return x / n, y / n, z / n, half_angle_atan2(n, w)


@jit
def rotation_vector_from_quaternion_scalar(x, y, z, w):
    """Logarithm map: rotation vector with norm in [0, pi]."""
    ax, ay, az, angle = axis_angle_from_quaternion_scalar(x, y, z, w)
    return ax * angle, ay * angle, az * angle


@jit
def quaternion_from_axis_angle_scalar(ax, ay, az, angle):
    """Unit canonical quaternion of a rotation by ``angle`` about a non-zero axis."""
    n = vector_norm(ax, ay, az)
    s = math.sin(0.5 * angle) / n
    return canonical_unit_quaternion(ax * s, ay * s, az * s, math.cos(0.5 * angle))


# ----------------------------------------------------------------- kernels

@jit
def _quaternion_from_axis_angle_kernel(axis, angle):
    n = axis.shape[0]
    out = np.empty((n, 4))
    for s in range(n):
        code = vector_defect(axis[s, 0], axis[s, 1], axis[s, 2])
        if code != OK:
            return out, s, code, 0
        if axis[s, 0] == 0.0 and axis[s, 1] == 0.0 and axis[s, 2] == 0.0:
            return out, s, ZERO_NORM, 0
        if not math.isfinite(angle[s]):
            return out, s, NON_FINITE, 1
        out[s, 0], out[s, 1], out[s, 2], out[s, 3] = quaternion_from_axis_angle_scalar(
            axis[s, 0], axis[s, 1], axis[s, 2], angle[s])
    return out, -1, OK, 0


@jit
def _matrix_from_axis_angle_kernel(axis, angle):
    q, bad, code, which = _quaternion_from_axis_angle_kernel(axis, angle)
    out = np.empty((axis.shape[0], 3, 3))
    if bad < 0:
        for s in range(axis.shape[0]):
            matrix_from_unit_direction(q[s, 0], q[s, 1], q[s, 2], q[s, 3], out[s])
    return out, bad, code, which


@jit
def _axis_angle_from_quaternion_kernel(q):
    n = q.shape[0]
    axis = np.empty((n, 3))
    angle = np.empty(n)
    for s in range(n):
        code = quaternion_defect(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        if code != OK:
            return axis, angle, s, code
        axis[s, 0], axis[s, 1], axis[s, 2], angle[s] = axis_angle_from_quaternion_scalar(
            q[s, 0], q[s, 1], q[s, 2], q[s, 3])
    return axis, angle, -1, OK


@jit
def _quaternion_from_rotation_vector_kernel(v):
    n = v.shape[0]
    out = np.empty((n, 4))
    for s in range(n):
        code = vector_defect(v[s, 0], v[s, 1], v[s, 2])
        if code != OK:
            return out, s, code
        out[s, 0], out[s, 1], out[s, 2], out[s, 3] = quaternion_from_rotation_vector_scalar(
            v[s, 0], v[s, 1], v[s, 2])
    return out, -1, OK


@jit
def _matrix_from_rotation_vector_kernel(v):
    n = v.shape[0]
    out = np.empty((n, 3, 3))
    for s in range(n):
        code = vector_defect(v[s, 0], v[s, 1], v[s, 2])
        if code != OK:
            return out, s, code
        x, y, z, w = quaternion_from_rotation_vector_scalar(v[s, 0], v[s, 1], v[s, 2])
        matrix_from_unit_direction(x, y, z, w, out[s])
    return out, -1, OK


@jit
def _rotation_vector_from_quaternion_kernel(q):
    n = q.shape[0]
    out = np.empty((n, 3))
    for s in range(n):
        code = quaternion_defect(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        if code != OK:
            return out, s, code
        out[s, 0], out[s, 1], out[s, 2] = rotation_vector_from_quaternion_scalar(
            q[s, 0], q[s, 1], q[s, 2], q[s, 3])
    return out, -1, OK


# ------------------------------------------------------------ public API

def _flat_axis_angle(axis, angle):
    fa, la = flat_array(axis, 'axis', (3,))
    ft, lt = flat_array(angle, 'angle', ())
    (fa, ft), lead = broadcast_flat((fa, ft), (la, lt))
    return fa, ft, lead


def quaternion_from_axis_angle(axis, angle):
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
    fa, ft, lead = _flat_axis_angle(axis, angle)
    out, bad, code, which = _quaternion_from_axis_angle_kernel(fa, ft)
    if bad >= 0:
        raise_sample_error(('axis', 'angle')[which], bad, code, lead)
    return out.reshape(lead + (4,))


def matrix_from_axis_angle(axis, angle):
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
    fa, ft, lead = _flat_axis_angle(axis, angle)
    out, bad, code, which = _matrix_from_axis_angle_kernel(fa, ft)
    if bad >= 0:
        raise_sample_error(('axis', 'angle')[which], bad, code, lead)
    return out.reshape(lead + (3, 3))


def axis_angle_from_quaternion(q):
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
    fq, lead = flat_array(q, 'q', (4,))
    axis, angle, bad, code = _axis_angle_from_quaternion_kernel(fq)
    if bad >= 0:
        raise_sample_error('q', bad, code, lead)
    return axis.reshape(lead + (3,)), angle.reshape(lead)


def axis_angle_from_matrix(R, *, orthonormal_tolerance=DEFAULT_ORTHONORMAL_TOLERANCE,
                           non_orthonormal='project'):
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
    q, lead = flat_quaternions_from_matrices(R, 'R', orthonormal_tolerance, non_orthonormal)
    axis, angle, _, _ = _axis_angle_from_quaternion_kernel(q)
    return axis.reshape(lead + (3,)), angle.reshape(lead)


def quaternion_from_rotation_vector(v):
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
    fv, lead = flat_array(v, 'v', (3,))
    out, bad, code = _quaternion_from_rotation_vector_kernel(fv)
    if bad >= 0:
        raise_sample_error('v', bad, code, lead)
    return out.reshape(lead + (4,))


def matrix_from_rotation_vector(v):
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
    fv, lead = flat_array(v, 'v', (3,))
    out, bad, code = _matrix_from_rotation_vector_kernel(fv)
    if bad >= 0:
        raise_sample_error('v', bad, code, lead)
    return out.reshape(lead + (3, 3))


def rotation_vector_from_quaternion(q):
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
    fq, lead = flat_array(q, 'q', (4,))
    out, bad, code = _rotation_vector_from_quaternion_kernel(fq)
    if bad >= 0:
        raise_sample_error('q', bad, code, lead)
    return out.reshape(lead + (3,))


def rotation_vector_from_matrix(R, *, orthonormal_tolerance=DEFAULT_ORTHONORMAL_TOLERANCE,
                                non_orthonormal='project'):
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
    q, lead = flat_quaternions_from_matrices(R, 'R', orthonormal_tolerance, non_orthonormal)
    out, _, _ = _rotation_vector_from_quaternion_kernel(q)
    return out.reshape(lead + (3,))

