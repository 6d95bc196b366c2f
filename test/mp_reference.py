"""
High-precision references (mpmath, 40 digits) for measuring errors in units of eps.

Inputs are taken as exact binary values; the truth is computed with 40
significant digits (``rotation_dev.study.reference``, which the accuracy study
uses too), so the errors measured are the package's own. Quaternions are
(x, y, z, w).
"""
import mpmath as mp
import numpy as np
from rotation_dev.study.reference import (
    DIGITS, distance, EPS, exact, nearest_rotation_quaternion, normalized, quaternion_from_euler,
    quaternion_from_rotation_vector)

mp.mp.dps = DIGITS
mpf_vector = exact

__all__ = ['EPS', 'distance', 'error_in_eps', 'is_canonical', 'mpf_vector',
           'nearest_rotation_quaternion', 'quaternion_from_axis_angle', 'quaternion_from_euler',
           'quaternion_from_rotation_vector', 'rotation_distance']


def quaternion_from_axis_angle(axis, angle):
    """Exact quaternion of a rotation by ``angle`` about ``axis`` (any non-zero length)."""
    a = normalized(exact(axis) + [mp.mpf(0)])[:3]
    half = mp.mpf(float(angle)) / 2
    return [c * mp.sin(half) for c in a] + [mp.cos(half)]


def error_in_eps(p, q):
    """Geodesic distance between two rotations (mp quaternions or float arrays), in eps."""
    p = p if isinstance(p[0], mp.mpf) else exact(p)
    q = q if isinstance(q[0], mp.mpf) else exact(q)
    return float(distance(p, q)) / EPS


def rotation_distance(p, q):
    """
    Angle (rad) between the rotations of unit float quaternions ``(..., 4)``, in numpy.

    ``4 atan2(|p - s q|, |p + s q|)`` with ``s`` the sign of ``p . q``: exact to
    a few ulps from 0 up (no ``acos``), independent of the package's formulas.
    """
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    s = np.where(np.sum(p * q, axis=-1) < 0.0, -1.0, 1.0)[..., None]
    return 4.0 * np.arctan2(np.linalg.norm(p - s * q, axis=-1), np.linalg.norm(p + s * q, axis=-1))


def is_canonical(q):
    """
    Whether every quaternion of ``q`` (..., 4) has the documented sign.

    That is w > 0, or w == 0 and the first non-zero of x, y, z > 0.
    """
    for x in np.asarray(q, dtype=float).reshape(-1, 4):
        first = next((c for c in x if c != 0.0), 0.0)
        if not (x[3] > 0.0 or (x[3] == 0.0 and first > 0.0)):
            return False
    return True
