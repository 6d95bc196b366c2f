"""
Angular velocity <-> time derivative of a quaternion or of a rotation matrix.

Conventions as in the package docstring. Expanded, ``dq_v/dt = 1/2 (q_s w_b + q_v x w_b)``
(body) or ``1/2 (q_s w_w - q_v x w_w)`` (world), and ``dq_s/dt = -1/2 q_v . w`` in both.
The inverses ``w_b = 2 vec(q* (x) qdot)`` and ``w_b = vee(skew(R^T Rdot))`` drop the part of
the derivative a rotation cannot have (``q . qdot``, the symmetric part of ``R^T Rdot``), so
they are the least-squares angular velocity of a noisy derivative.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ._validation import is_world_frame
from ..conversions.kernels import (
    BOOL, call_binary, first_status, FLAT_IN, FLAT_OUT, jit, kernel, matrix_at, matrix_defect,
    matrix_samples, NON_FINITE, OK, product, quaternion_status, ROWS_IN, ROWS_OUT, samples, status,
    unit_quaternion, vector_status)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray

# Kernels as in conversions: validated inputs, a preallocated output, the status of the first
# bad sample returned (-1 when all are fine).


@jit
def _matrix_status(fm, s, argument):
    """Status of the matrix ``fm[s]``: NaN/Inf or ``det <= 0`` (-1 when fine)."""
    code = matrix_defect(matrix_at(fm, s))
    return -1 if code == OK else status(s, argument, code)


@jit
def _finite_status(fa, s, argument):
    """Status of ``fa[s]`` (any shape; zero allowed, as for a derivative): NaN/Inf only."""
    for v in fa[s].flat:
        if not math.isfinite(v):
            return status(s, argument, NON_FINITE)
    return -1


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT, BOOL)
def _quaternion_derivative_kernel(q, omega, out, world):
    fq, fw, fo = samples(q, 4), samples(omega, 3), samples(out, 4)
    for s in range(fq.shape[0]):
        bad = first_status(quaternion_status(fq, s, 0), vector_status(fw, s, 1))
        if bad >= 0:
            return bad
        x, y, z, w = unit_quaternion(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
        if world:  # 1/2 (w_w, 0) (x) q
            dx, dy, dz, dw = product(fw[s, 0], fw[s, 1], fw[s, 2], 0.0, x, y, z, w)
        else:  # 1/2 q (x) (w_b, 0)
            dx, dy, dz, dw = product(x, y, z, w, fw[s, 0], fw[s, 1], fw[s, 2], 0.0)
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = 0.5 * dx, 0.5 * dy, 0.5 * dz, 0.5 * dw
    return -1


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT, BOOL)
def _angular_velocity_from_quaternion_derivative_kernel(q, q_dot, out, world):
    fq, fd, fo = samples(q, 4), samples(q_dot, 4), samples(out, 3)
    for s in range(fq.shape[0]):
        bad = first_status(quaternion_status(fq, s, 0), _finite_status(fd, s, 1))
        if bad >= 0:
            return bad
        x, y, z, w = unit_quaternion(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
        if world:  # 2 qdot (x) q*
            vx, vy, vz, _ = product(fd[s, 0], fd[s, 1], fd[s, 2], fd[s, 3], -x, -y, -z, w)
        else:  # 2 q* (x) qdot
            vx, vy, vz, _ = product(-x, -y, -z, w, fd[s, 0], fd[s, 1], fd[s, 2], fd[s, 3])
        fo[s, 0], fo[s, 1], fo[s, 2] = 2.0 * vx, 2.0 * vy, 2.0 * vz
    return -1


@kernel(ROWS_IN, FLAT_IN, ROWS_OUT, BOOL)
def _matrix_derivative_kernel(R, omega, out, world):
    fm, fw, fo = matrix_samples(R), samples(omega, 3), matrix_samples(out)
    for s in range(fm.shape[0]):
        bad = first_status(_matrix_status(fm, s, 0), vector_status(fw, s, 1))
        if bad >= 0:
            return bad
        wx, wy, wz = fw[s, 0], fw[s, 1], fw[s, 2]
        m, d = fm[s], fo[s]
        if world:  # [w]x R: column c is w x R[:, c]
            for c in range(3):
                d[0, c] = wy * m[2, c] - wz * m[1, c]
                d[1, c] = wz * m[0, c] - wx * m[2, c]
                d[2, c] = wx * m[1, c] - wy * m[0, c]
        else:  # R [w]x: column c is R (w x e_c)
            for r in range(3):
                d[r, 0] = wz * m[r, 1] - wy * m[r, 2]
                d[r, 1] = wx * m[r, 2] - wz * m[r, 0]
                d[r, 2] = wy * m[r, 0] - wx * m[r, 1]
    return -1


@kernel(ROWS_IN, ROWS_IN, FLAT_OUT, BOOL)
def _angular_velocity_from_matrix_derivative_kernel(R, R_dot, out, world):
    fm, fd, fo = matrix_samples(R), matrix_samples(R_dot), samples(out, 3)
    for s in range(fm.shape[0]):
        bad = first_status(_matrix_status(fm, s, 0), _finite_status(fd, s, 1))
        if bad >= 0:
            return bad
        m, d = fm[s], fd[s]
        if world:  # A = Rdot R^T: A[a, b] = Rdot[a, :] . R[b, :]
            a, b = d, m
        else:  # A = R^T Rdot: A[a, b] = R[:, a] . Rdot[:, b] = (R^T)[a, :] . (Rdot^T)[b, :]
            a, b = m.T, d.T
        a21 = a[2, 0] * b[1, 0] + a[2, 1] * b[1, 1] + a[2, 2] * b[1, 2]
        a12 = a[1, 0] * b[2, 0] + a[1, 1] * b[2, 1] + a[1, 2] * b[2, 2]
        a02 = a[0, 0] * b[2, 0] + a[0, 1] * b[2, 1] + a[0, 2] * b[2, 2]
        a20 = a[2, 0] * b[0, 0] + a[2, 1] * b[0, 1] + a[2, 2] * b[0, 2]
        a10 = a[1, 0] * b[0, 0] + a[1, 1] * b[0, 1] + a[1, 2] * b[0, 2]
        a01 = a[0, 0] * b[1, 0] + a[0, 1] * b[1, 1] + a[0, 2] * b[1, 2]
        # vee of the skew-symmetric part of A
        fo[s, 0] = 0.5 * (a21 - a12)
        fo[s, 1] = 0.5 * (a02 - a20)
        fo[s, 2] = 0.5 * (a10 - a01)
    return -1


def quaternion_derivative(q: ArrayLike, omega: ArrayLike, frame: str = 'body') -> FloatArray:
    """
    Time derivative of a unit quaternion rotating with angular velocity ``omega``.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Orientations (x, y, z, w), body-to-world, any non-zero norm (normalised first, sign
        kept: ``-q`` gives ``-qdot``).
    omega : array_like, shape (..., 3)
        Angular velocities (rad/s) in ``frame``; broadcast with ``q``.
    frame : {'body', 'world'}, optional
        ``'body'``: ``qdot = 1/2 q (x) (w_b, 0)``. ``'world'``: ``qdot = 1/2 (w_w, 0) (x) q``,
        the textbook formula that labels its vector "omega_Body".

    Returns
    -------
    ndarray, shape (..., 4)
        ``qdot`` (1/s) of the unit quaternion ``q / |q|``; orthogonal to it.

    Raises
    ------
    ValueError
        Bad ``frame``; wrong shape, NaN/Inf or a zero quaternion, naming the argument and the
        sample.

    """
    return call_binary(_quaternion_derivative_kernel, q, omega, ('q', 'omega'), ((4,), (3,)), (4,),
                       is_world_frame(frame))


def angular_velocity_from_quaternion_derivative(q: ArrayLike, q_dot: ArrayLike,
                                                frame: str = 'body') -> FloatArray:
    """
    Angular velocity of a quaternion and its time derivative.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Orientations (x, y, z, w), body-to-world, any non-zero norm (normalised, sign kept).
    q_dot : array_like, shape (..., 4)
        Time derivative (1/s) of the unit quaternion ``q / |q|``; broadcast with ``q``.
    frame : {'body', 'world'}, optional
        ``'body'``: ``w_b = 2 vec(q* (x) qdot)``; ``'world'``: ``w_w = 2 vec(qdot (x) q*)``.

    Returns
    -------
    ndarray, shape (..., 3)
        Angular velocity (rad/s) in ``frame``. The component of ``q_dot`` along ``q`` is
        ignored (least squares for a noisy ``q_dot``); inverts :func:`quaternion_derivative`
        to rounding.

    Raises
    ------
    ValueError
        Bad ``frame``; wrong shape, NaN/Inf or a zero ``q``.

    """
    return call_binary(_angular_velocity_from_quaternion_derivative_kernel, q, q_dot,
                       ('q', 'q_dot'), ((4,), (4,)), (3,), is_world_frame(frame))


def matrix_derivative(R: ArrayLike, omega: ArrayLike, frame: str = 'body') -> FloatArray:
    """
    Time derivative of a rotation matrix rotating with angular velocity ``omega``.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices, body-to-world, used as given (not re-orthonormalised).
    omega : array_like, shape (..., 3)
        Angular velocities (rad/s) in ``frame``; broadcast with ``R``.
    frame : {'body', 'world'}, optional
        ``'body'``: ``Rdot = R [w_b]x``; ``'world'``: ``Rdot = [w_w]x R``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``Rdot`` (1/s).

    Raises
    ------
    ValueError
        Bad ``frame``; wrong shape, NaN/Inf or ``det(R) <= 0``.

    """
    return call_binary(_matrix_derivative_kernel, R, omega, ('R', 'omega'), ((3, 3), (3,)), (3, 3),
                       is_world_frame(frame))


def angular_velocity_from_matrix_derivative(R: ArrayLike, R_dot: ArrayLike,
                                            frame: str = 'body') -> FloatArray:
    """
    Angular velocity of a rotation matrix and its time derivative.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices, body-to-world, used as given.
    R_dot : array_like, shape (..., 3, 3)
        Their time derivatives (1/s); broadcast with ``R``.
    frame : {'body', 'world'}, optional
        ``'body'``: ``[w_b]x = R^T Rdot``; ``'world'``: ``[w_w]x = Rdot R^T`` (the textbook
        ``Omega``).

    Returns
    -------
    ndarray, shape (..., 3)
        Angular velocity (rad/s) in ``frame``: the vee of the skew-symmetric part of
        ``R^T Rdot`` (``Rdot R^T``); the symmetric part is ignored (least squares for a noisy
        ``R_dot``).

    Raises
    ------
    ValueError
        Bad ``frame``; wrong shape, NaN/Inf or ``det(R) <= 0``.

    """
    return call_binary(_angular_velocity_from_matrix_derivative_kernel, R, R_dot,
                       ('R', 'R_dot'), ((3, 3), (3, 3)), (3,), is_world_frame(frame))
