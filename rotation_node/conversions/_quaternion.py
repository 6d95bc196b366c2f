"""
Quaternion algebra: the scalar formulas every other module builds on.

Convention: ``q = (x, y, z, w)``, scalar last, Hamilton product, active
rotation mapping body coordinates to world coordinates. Any non-zero scale of a
quaternion represents the same rotation; every formula here either works on
ratios or rescales by a power of two first (exact), so quaternions scaled by
1e-160 or 1e+160 are handled without under- or overflow.

The ``_``-prefixed scalar functions are compiled with numba and called from the
loop kernels; they assume finite, non-zero input (the kernels check with
:func:`quaternion_defect` first).
"""
import math

import numpy as np
from numba import njit

from ._validation import NON_FINITE, OK, ZERO_NORM, broadcast_flat, flat_array, raise_sample_error

jit = njit(cache=True, nogil=True, error_model='numpy')


@jit
def quaternion_defect(x, y, z, w):
    """Defect code of a quaternion: OK, NON_FINITE or ZERO_NORM."""
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and math.isfinite(w)):
        return NON_FINITE
    if x == 0.0 and y == 0.0 and z == 0.0 and w == 0.0:
        return ZERO_NORM
    return OK


@jit
def vector_defect(x, y, z):
    """Defect code of a 3-vector: OK or NON_FINITE."""
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return NON_FINITE
    return OK


@jit
def power_of_two_scale(m):
    """Return ``2**-e`` with ``m * 2**-e`` in [0.5, 1): an exact rescaling factor."""
    return math.ldexp(1.0, -math.frexp(m)[1])


@jit
def scaled_quaternion(x, y, z, w):
    """Scale by a power of two so the largest component is in [0.5, 1) (exact)."""
    s = power_of_two_scale(max(abs(x), abs(y), abs(z), abs(w)))
    return x * s, y * s, z * s, w * s


@jit
def vector_norm(x, y, z):
    """Euclidean norm of a 3-vector without under- or overflow."""
    m = max(abs(x), abs(y), abs(z))
    if m == 0.0:
        return 0.0
    s = power_of_two_scale(m)
    x, y, z = x * s, y * s, z * s
    return math.sqrt(x * x + y * y + z * z) / s


@jit
def canonical_unit_quaternion(x, y, z, w):
    """
    Unit quaternion with w > 0, or w == 0 and the first non-zero of x, y, z > 0.

    The rule makes the output unique: q and -q map to the same result.
    """
    x, y, z, w = scaled_quaternion(x, y, z, w)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0 or (w == 0.0 and (x < 0.0 or (x == 0.0 and (y < 0.0 or (y == 0.0 and z < 0.0))))):
        n = -n
    return x / n, y / n, z / n, w / n + 0.0  # + 0.0 turns w = -0.0 into 0.0


@jit
def product(px, py, pz, pw, qx, qy, qz, qw):
    """Hamilton product ``p (x) q``."""
    return (pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz)


@jit
def rotated_vector(x, y, z, w, vx, vy, vz):
    """``R(q) v`` for a unit quaternion: ``v + w t + u x t`` with ``t = 2 u x v``."""
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx))


@jit
def half_angle_atan2(vector_norm_value, scalar):
    """Rotation angle ``2 atan2(|q_v|, |q_s|)`` in [0, pi]: ~1 ulp for every angle."""
    return 2.0 * math.atan2(vector_norm_value, abs(scalar))


# ----------------------------------------------------------------- kernels

@jit
def _product_kernel(p, q):
    n = p.shape[0]
    out = np.empty((n, 4))
    for s in range(n):
        code = quaternion_defect(p[s, 0], p[s, 1], p[s, 2], p[s, 3])
        if code != OK:
            return out, s, code, 0
        code = quaternion_defect(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        if code != OK:
            return out, s, code, 1
        out[s, 0], out[s, 1], out[s, 2], out[s, 3] = product(
            p[s, 0], p[s, 1], p[s, 2], p[s, 3], q[s, 0], q[s, 1], q[s, 2], q[s, 3])
    return out, -1, OK, 0


@jit
def _conjugate_kernel(q):
    n = q.shape[0]
    out = np.empty((n, 4))
    for s in range(n):
        code = quaternion_defect(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        if code != OK:
            return out, s, code
        out[s, 0], out[s, 1], out[s, 2], out[s, 3] = -q[s, 0], -q[s, 1], -q[s, 2], q[s, 3]
    return out, -1, OK


@jit
def canonical_kernel(q):
    n = q.shape[0]
    out = np.empty((n, 4))
    for s in range(n):
        code = quaternion_defect(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        if code != OK:
            return out, s, code
        out[s, 0], out[s, 1], out[s, 2], out[s, 3] = canonical_unit_quaternion(
            q[s, 0], q[s, 1], q[s, 2], q[s, 3])
    return out, -1, OK


@jit
def _distance_kernel(p, q):
    n = p.shape[0]
    out = np.empty(n)
    for s in range(n):
        code = quaternion_defect(p[s, 0], p[s, 1], p[s, 2], p[s, 3])
        if code != OK:
            return out, s, code, 0
        code = quaternion_defect(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        if code != OK:
            return out, s, code, 1
        px, py, pz, pw = scaled_quaternion(p[s, 0], p[s, 1], p[s, 2], p[s, 3])
        qx, qy, qz, qw = scaled_quaternion(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        ex, ey, ez, ew = product(-px, -py, -pz, pw, qx, qy, qz, qw)
        out[s] = half_angle_atan2(vector_norm(ex, ey, ez), ew)
    return out, -1, OK, 0


@jit
def _rotate_kernel(q, v):
    n = q.shape[0]
    out = np.empty((n, 3))
    for s in range(n):
        code = quaternion_defect(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        if code != OK:
            return out, s, code, 0
        code = vector_defect(v[s, 0], v[s, 1], v[s, 2])
        if code != OK:
            return out, s, code, 1
        x, y, z, w = canonical_unit_quaternion(q[s, 0], q[s, 1], q[s, 2], q[s, 3])
        out[s, 0], out[s, 1], out[s, 2] = rotated_vector(x, y, z, w, v[s, 0], v[s, 1], v[s, 2])
    return out, -1, OK, 0


# ------------------------------------------------------------ public API

def _binary(kernel, a, b, names, trailing_a, trailing_b, trailing_out):
    fa, la = flat_array(a, names[0], trailing_a)
    fb, lb = flat_array(b, names[1], trailing_b)
    (fa, fb), lead = broadcast_flat((fa, fb), (la, lb))
    out, bad, code, which = kernel(fa, fb)
    if bad >= 0:
        raise_sample_error(names[which], bad, code, lead)
    return out.reshape(lead + trailing_out)


def _unary_quaternion(kernel, q, name='q'):
    fq, lead = flat_array(q, name, (4,))
    out, bad, code = kernel(fq)
    if bad >= 0:
        raise_sample_error(name, bad, code, lead)
    return out.reshape(lead + (4,))


def quaternion_product(p, q):
    """
    Hamilton product of two quaternions.

    Parameters
    ----------
    p, q : array_like, shape (..., 4)
        Quaternions (x, y, z, w); leading dimensions broadcast.

    Returns
    -------
    ndarray, shape (..., 4)
        ``p (x) q``: the rotation ``q`` followed by ``p`` (``R(p) R(q)``). Not
        normalised, so that the product of unit quaternions stays exact to
        rounding.

    Raises
    ------
    ValueError
        Wrong shape, a NaN/Inf component, or a zero quaternion.
    """
    return _binary(_product_kernel, p, q, ('p', 'q'), (4,), (4,), (4,))


def quaternion_conjugate(q):
    """
    Conjugate ``(-x, -y, -z, w)``: the inverse rotation.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w).

    Returns
    -------
    ndarray, shape (..., 4)
        The conjugates (same norm as ``q``).
    """
    return _unary_quaternion(_conjugate_kernel, q)


def canonical_quaternion(q):
    """
    Unit quaternion with ``w >= 0`` representing the same rotation.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm (1e-160 to 1e+160 are fine).

    Returns
    -------
    ndarray, shape (..., 4)
        ``q / |q|`` with the sign chosen so that ``w > 0``; where ``w == 0``
        the first non-zero of x, y, z is positive. ``q`` and ``-q`` give the
        same result.
    """
    return _unary_quaternion(canonical_kernel, q)


def quaternion_distance(p, q):
    """
    Geodesic angle between the rotations of two quaternions.

    Parameters
    ----------
    p, q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm; leading dimensions broadcast.

    Returns
    -------
    ndarray, shape (...)
        ``2 atan2(|vec(p* q)|, |scalar(p* q)|)`` in [0, pi]: the angle of the
        rotation that takes ``p`` to ``q``. Accurate to ~1 ulp down to 0 (an
        ``acos`` form floors at ~1e-8). ``p`` and ``-p`` are the same rotation.
    """
    return _binary(_distance_kernel, p, q, ('p', 'q'), (4,), (4,), ())


def rotate_vector(q, v):
    """
    Rotate vectors by quaternions: ``R(q) v``.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), normalised internally.
    v : array_like, shape (..., 3)
        Vectors; leading dimensions broadcast with ``q``'s.

    Returns
    -------
    ndarray, shape (..., 3)
        The rotated vectors. With ``q`` body-to-world, this maps body
        coordinates to world coordinates (e.g. ``w_world = R w_body``).
    """
    return _binary(_rotate_kernel, q, v, ('q', 'v'), (4,), (3,), (3,))
