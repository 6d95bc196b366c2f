"""
High-precision references (mpmath, 40 digits) for measuring errors in units of eps.

Inputs are taken as exact binary values; the truth is computed with 40
significant digits, so the errors measured are the package's own, not the
reference's rounding. Quaternions are (x, y, z, w).
"""
import mpmath as mp
import numpy as np

mp.mp.dps = 40
EPS = np.finfo(float).eps


def mpf_vector(v):
    return [mp.mpf(float(c)) for c in v]


def normalized(q):
    n = mp.sqrt(sum(c * c for c in q))
    return [c / n for c in q]


def product(p, q):
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return [pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz]


def distance(p, q):
    """Geodesic angle between two mp quaternions (any norms)."""
    p, q = normalized(p), normalized(q)
    e = product([-p[0], -p[1], -p[2], p[3]], q)
    return 2 * mp.atan2(mp.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2), abs(e[3]))


def quaternion_from_rotation_vector(v):
    v = mpf_vector(v)
    theta = mp.sqrt(sum(c * c for c in v))
    if theta == 0:
        return [mp.mpf(0), mp.mpf(0), mp.mpf(0), mp.mpf(1)]
    k = mp.sin(theta / 2) / theta
    return [c * k for c in v] + [mp.cos(theta / 2)]


def quaternion_from_axis_angle(axis, angle):
    a = mpf_vector(axis)
    n = mp.sqrt(sum(c * c for c in a))
    half = mp.mpf(float(angle)) / 2
    return [c / n * mp.sin(half) for c in a] + [mp.cos(half)]


def quaternion_from_euler(angles, seq):
    """Quaternion of Euler angles; upper case intrinsic, lower case extrinsic."""
    elementary = []
    for axis, angle in zip(seq.lower(), angles):
        half = mp.mpf(float(angle)) / 2
        e = [mp.mpf(0)] * 3 + [mp.cos(half)]
        e['xyz'.index(axis)] = mp.sin(half)
        elementary.append(e)
    if seq.islower():
        elementary.reverse()
    return product(product(elementary[0], elementary[1]), elementary[2])


def nearest_rotation_quaternion(m):
    """Quaternion of the rotation nearest to the 3x3 matrix ``m`` (Newton-Schulz in mp)."""
    x = mp.matrix([[mp.mpf(float(m[r][c])) for c in range(3)] for r in range(3)])
    for _ in range(60):
        if mp.mnorm(x.T * x - mp.eye(3), 1) < mp.mpf('1e-36'):
            break
        x = x * (3 * mp.eye(3) - x.T * x) / 2
    return quaternion_from_orthonormal(x)


def quaternion_from_orthonormal(x):
    """Markley's quaternion of an (mp) orthonormal matrix."""
    t = x[0, 0] + x[1, 1] + x[2, 2]
    if t >= max(x[0, 0], x[1, 1], x[2, 2]):
        q = [x[2, 1] - x[1, 2], x[0, 2] - x[2, 0], x[1, 0] - x[0, 1], 1 + t]
    elif x[0, 0] >= x[1, 1] and x[0, 0] >= x[2, 2]:
        q = [1 + x[0, 0] - x[1, 1] - x[2, 2], x[0, 1] + x[1, 0], x[0, 2] + x[2, 0], x[2, 1] - x[1, 2]]
    elif x[1, 1] >= x[2, 2]:
        q = [x[0, 1] + x[1, 0], 1 + x[1, 1] - x[0, 0] - x[2, 2], x[1, 2] + x[2, 1], x[0, 2] - x[2, 0]]
    else:
        q = [x[0, 2] + x[2, 0], x[1, 2] + x[2, 1], 1 + x[2, 2] - x[0, 0] - x[1, 1], x[1, 0] - x[0, 1]]
    return normalized(q)


def error_in_eps(p, q):
    """Geodesic distance between two rotations (mp quaternions or float arrays), in eps."""
    p = p if isinstance(p[0], mp.mpf) else mpf_vector(p)
    q = q if isinstance(q[0], mp.mpf) else mpf_vector(q)
    return float(distance(p, q)) / EPS
