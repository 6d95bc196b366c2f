"""
Exact references for the accuracy study: rotations computed with 40 significant digits.

Every input float is taken as the exact binary number it is, and the rotation it
stands for is computed with mpmath at :data:`DIGITS` significant digits, so a
measured error is the method's own, not the reference's (whose rounding is
~1e-40). Quaternions are (x, y, z, w), scalar last, Hamilton product, active,
body-to-world; a reference quaternion is a tuple of four ``mpmath.mpf``, unit.

Errors are geodesic angles between rotations,
``2 atan2(|vec(p* q)|, |scalar(p* q)|)`` (docs/numerics.md; never ``acos``, which
floors at ~1e-8), reported in units of :data:`EPS`.

The study and the tests use this module (mpmath is a study and test
dependency, never a runtime one): the per-sample functions (``product``,
``quaternion_from_rotation_vector``, ``quaternion_from_euler``,
``nearest_rotation_quaternion``, ``distance``) expect to run at
:data:`DIGITS` digits (``mpmath.workdps``), the batch functions set it.
"""
import math

import mpmath
import numpy as np

#: Significant digits of the references.
DIGITS = 40
#: float64 machine epsilon, 2**-52: the unit errors are reported in.
EPS = float(np.finfo(np.float64).eps)
#: float32 machine epsilon, 2**-23.
EPS32 = float(np.finfo(np.float32).eps)

_mpf = mpmath.mpf


def product(p, q):
    """Hamilton product ``p (x) q`` of two mp quaternions (x, y, z, w)."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return (pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz)


def normalized(q):
    """Return the unit quaternion ``q / |q|`` (mp)."""
    norm = mpmath.sqrt(sum(c * c for c in q))
    return tuple(c / norm for c in q)


def exact(values):
    """Return the values (any float dtype) as exact mp numbers."""
    return [_mpf(float(v)) for v in values]


def _reference(rows, build):
    """Return ``build(row)`` for each row at :data:`DIGITS` digits; None for rows with NaN/Inf."""
    rows = np.asarray(rows)
    finite = np.isfinite(rows.reshape(len(rows), -1)).all(axis=1)
    with mpmath.workdps(DIGITS):
        return [build(row) if ok else None for row, ok in zip(rows, finite)]


def quaternion_from_rotation_vector(v):
    """Exact quaternion of one rotation vector (exponential map)."""
    vector = exact(v)
    angle = mpmath.sqrt(sum(c * c for c in vector))
    if not angle:
        return (_mpf(0), _mpf(0), _mpf(0), _mpf(1))
    k = mpmath.sin(angle / 2) / angle
    return tuple(c * k for c in vector) + (mpmath.cos(angle / 2),)


def quaternion_from_euler(angles, seq):
    """Exact quaternion of one triple of Euler angles of ``seq``."""
    factors = []
    for axis, angle in zip(seq.lower(), exact(angles)):
        factor = [_mpf(0), _mpf(0), _mpf(0), mpmath.cos(angle / 2)]
        factor['xyz'.index(axis)] = mpmath.sin(angle / 2)
        factors.append(factor)
    if seq.islower():
        factors.reverse()
    return product(product(factors[0], factors[1]), factors[2])


def nearest_rotation_quaternion(matrix):
    """Exact quaternion of the rotation nearest to one 3x3 float matrix (det > 0)."""
    return _quaternion_from_orthonormal(_nearest_rotation([exact(row) for row in matrix]))


def distance(p, q):
    """Geodesic angle between two mp quaternions of any norm; None if one is zero."""
    e = product((-p[0], -p[1], -p[2], p[3]), q)
    vector = mpmath.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2)
    if not (vector or e[3]):
        return None
    return 2 * mpmath.atan2(vector, abs(e[3]))


def quaternions(q):
    """
    Exact rotations of float quaternions of any non-zero norm.

    Parameters
    ----------
    q : array_like, shape (n, 4)
        Quaternions (x, y, z, w); the rotation of ``q / |q|``, computed exactly.

    Returns
    -------
    list of tuple of mpmath.mpf
        Unit quaternions; None where ``q`` has a NaN or Inf (or is zero).

    """
    def build(row):
        values = exact(row)
        return normalized(values) if any(values) else None
    return _reference(q, build)


def quaternions_from_rotation_vectors(v):
    """
    Exact rotations of rotation vectors ``angle * axis`` (the exponential map).

    Parameters
    ----------
    v : array_like, shape (n, 3)
        Rotation vectors (rad).

    Returns
    -------
    list of tuple of mpmath.mpf
        Unit quaternions; None for rows with a NaN or Inf.

    """
    return _reference(v, quaternion_from_rotation_vector)


def quaternions_from_euler(angles, seq):
    """
    Exact rotations of Euler angles.

    Parameters
    ----------
    angles : array_like, shape (n, 3)
        Radians, in the order of ``seq``.
    seq : str
        Three of x, y, z; upper case intrinsic (``R = R1 R2 R3``), lower case
        extrinsic (``R = R3 R2 R1``).

    Returns
    -------
    list of tuple of mpmath.mpf
        Unit quaternions; None for rows with a NaN or Inf.

    """
    return _reference(angles, lambda row: quaternion_from_euler(row, seq))


def _nearest_rotation(m):
    """
    Orthogonal polar factor of an mp 3x3 matrix (list of rows) with det > 0.

    Newton-Schulz (Bjorck-Bowie) iteration ``X <- X (3 I - X^T X) / 2``: it
    converges quadratically for deviations from orthonormality below 1, which
    covers every matrix of the study (noise up to sigma = 0.1).
    """
    tolerance = _mpf(10) ** (2 - DIGITS)
    x = m
    for _ in range(100):
        gram = [[sum(x[r][a] * x[r][b] for r in range(3)) for b in range(3)] for a in range(3)]
        deviation = max(abs(gram[a][b] - (1 if a == b else 0)) for a in range(3) for b in range(3))
        if deviation < tolerance:
            return x
        w = [[((3 if a == b else 0) - gram[a][b]) / 2 for b in range(3)] for a in range(3)]
        x = [[sum(x[r][k] * w[k][c] for k in range(3)) for c in range(3)] for r in range(3)]
    raise ArithmeticError('nearest rotation: Newton-Schulz did not converge '
                          f'(deviation {float(deviation):.1e})')


def _quaternion_from_orthonormal(x):
    """Markley's quaternion of an mp rotation matrix (pivot on the largest diagonal term)."""
    trace = x[0][0] + x[1][1] + x[2][2]
    if trace >= max(x[0][0], x[1][1], x[2][2]):
        q = (x[2][1] - x[1][2], x[0][2] - x[2][0], x[1][0] - x[0][1], 1 + trace)
    elif x[0][0] >= x[1][1] and x[0][0] >= x[2][2]:
        q = (1 + x[0][0] - x[1][1] - x[2][2], x[0][1] + x[1][0], x[0][2] + x[2][0],
             x[2][1] - x[1][2])
    elif x[1][1] >= x[2][2]:
        q = (x[0][1] + x[1][0], 1 + x[1][1] - x[0][0] - x[2][2], x[1][2] + x[2][1],
             x[0][2] - x[2][0])
    else:
        q = (x[0][2] + x[2][0], x[1][2] + x[2][1], 1 + x[2][2] - x[0][0] - x[1][1],
             x[1][0] - x[0][1])
    return normalized(q)


def quaternions_from_nearest_rotation(m):
    """
    Exact quaternions of the rotations nearest (Frobenius norm) to 3x3 matrices.

    For a matrix that is a rotation to rounding this is the rotation the
    float matrix stands for; for a noisy one, the orthogonal Procrustes answer.

    Parameters
    ----------
    m : array_like, shape (n, 3, 3)
        Matrices with positive determinant.

    Returns
    -------
    list of tuple of mpmath.mpf
        Unit quaternions; None for matrices with a NaN or Inf.

    """
    return _reference(m, nearest_rotation_quaternion)


def errors_in_eps(estimates, truths):
    """
    Geodesic angles between estimated and true rotations, in units of :data:`EPS`.

    Parameters
    ----------
    estimates, truths : sequence of tuple of mpmath.mpf or None
        Quaternions as returned by this module's functions (any norm); None
        marks a failed estimate (a NaN/Inf output or an exception).

    Returns
    -------
    ndarray, shape (n,)
        Errors in eps; NaN where the estimate failed.

    """
    errors = np.full(len(truths), math.nan)
    with mpmath.workdps(DIGITS):
        for index, (p, q) in enumerate(zip(estimates, truths)):
            if p is None:
                continue
            angle = distance(p, q)
            if angle is not None:
                errors[index] = float(angle) / EPS
    return errors
