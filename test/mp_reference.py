"""
High-precision references (mpmath, 40 digits) for measuring errors in units of eps.

Inputs are taken as exact binary values; the truth is computed with 40
significant digits (``rotation_dev.study.reference``, which the accuracy study
uses too), so the errors measured are the package's own. Quaternions are
(x, y, z, w).
"""
import mpmath as mp

from rotation_dev.study.reference import (DIGITS, EPS, distance, exact, nearest_rotation_quaternion,
                                           normalized, quaternion_from_euler,
                                           quaternion_from_rotation_vector)

mp.mp.dps = DIGITS
mpf_vector = exact

__all__ = ['EPS', 'distance', 'error_in_eps', 'mpf_vector', 'nearest_rotation_quaternion',
           'quaternion_from_axis_angle', 'quaternion_from_euler', 'quaternion_from_rotation_vector']


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
