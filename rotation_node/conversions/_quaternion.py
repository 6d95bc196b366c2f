"""
Quaternion algebra: the scalar formulas every other module builds on, and their kernels.

Any non-zero scale of a quaternion is the same rotation: every formula works on ratios
or rescales by an exact power of two first, so norms of 1e+-160 neither under- nor
overflow. The scalar helpers (tuples in, tuples out) assume finite, non-zero input; the
kernels check it first (:func:`quaternion_defect`).
"""
from __future__ import annotations

import math
from typing import Any, Callable, TYPE_CHECKING

import numpy as np

from ._runtime import (
    call_binary, call_unary, compiled_form, first_status, FLAT_IN, FLAT_OUT, jit, kernel, samples,
    status)
from ._validation import NON_FINITE, OK, ZERO_NORM

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray, FloatArrayOrScalar, Quaternion4, Vector3


@jit
def quaternion_defect(x: float, y: float, z: float, w: float) -> int:
    """Defect code of a quaternion: OK, NON_FINITE or ZERO_NORM."""
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and math.isfinite(w)):
        return NON_FINITE
    if x == 0.0 and y == 0.0 and z == 0.0 and w == 0.0:
        return ZERO_NORM
    return OK


@jit
def vector_defect(x: float, y: float, z: float) -> int:
    """Defect code of a 3-vector: OK or NON_FINITE."""
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return NON_FINITE
    return OK


# Magnitudes whose squares and sums of squares are normal, finite doubles.
_SAFE_LOW = 2.0 ** -500
_SAFE_HIGH = 2.0 ** 500


@jit
def binary_exponent(m: float) -> int:
    """``e`` with ``m = f 2**e``, f in [0.5, 1): scaling by ``2**-e`` is exact."""
    return math.frexp(m)[1]


@jit
def scaled_quaternion(x: float, y: float, z: float, w: float) -> Quaternion4:
    """Return ``q`` unchanged within [2^-500, 2^500], else scaled exactly to a max in [0.5, 1)."""
    m = max(abs(x), abs(y), abs(z), abs(w))
    if _SAFE_LOW < m < _SAFE_HIGH:
        return x, y, z, w
    e = -binary_exponent(m)
    return math.ldexp(x, e), math.ldexp(y, e), math.ldexp(z, e), math.ldexp(w, e)


@jit
def vector_norm(x: float, y: float, z: float) -> float:
    """Euclidean norm of a 3-vector without under- or overflow."""
    m = max(abs(x), abs(y), abs(z))
    if _SAFE_LOW < m < _SAFE_HIGH:
        return math.sqrt(x * x + y * y + z * z)
    if m == 0.0:
        return 0.0
    e = binary_exponent(m)
    x, y, z = math.ldexp(x, -e), math.ldexp(y, -e), math.ldexp(z, -e)
    return math.ldexp(math.sqrt(x * x + y * y + z * z), e)


@jit
def needs_sign_flip(x: float, y: float, z: float, w: float) -> bool:
    """Whether ``-q`` is canonical: w > 0, or w == 0 and the first non-zero of x, y, z > 0."""
    return w < 0.0 or (w == 0.0 and (
        x < 0.0 or (x == 0.0 and (y < 0.0 or (y == 0.0 and z < 0.0)))))


def _divided_by_norm(x: float, y: float, z: float, w: float) -> Quaternion4:
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return x / n, y / n, z / n, w / n


def _over_zero(a: float) -> float:
    """Return ``a / +0.0`` as IEEE division gives it (Python raises): +-inf, or NaN for ``a`` 0."""
    return math.copysign(math.inf, a) if a != 0.0 else math.nan


def divided_by_norm(x: float, y: float, z: float, w: float) -> Quaternion4:
    """
    ``q / |q|`` for a quaternion that needs no rescaling (:func:`scaled_quaternion`).

    Interpreted, a zero norm (which a branch-free loop divides by before it checks) gives
    what IEEE division gives compiled, where Python's raises ``ZeroDivisionError``.
    """
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n == 0.0:
        return _over_zero(x), _over_zero(y), _over_zero(z), _over_zero(w)
    return x / n, y / n, z / n, w / n


@compiled_form(divided_by_norm)
def _compiled_divided_by_norm() -> Callable[..., Any]:
    from numba import njit
    return njit(nogil=True, error_model='numpy', inline='always')(_divided_by_norm)


@jit
def unit_quaternion(x: float, y: float, z: float, w: float) -> Quaternion4:
    """``q / |q|`` with its sign kept; any non-zero norm (exact power-of-two rescaling first)."""
    x, y, z, w = scaled_quaternion(x, y, z, w)
    return divided_by_norm(x, y, z, w)


@jit
def with_canonical_sign(x: float, y: float, z: float, w: float) -> Quaternion4:
    """``q`` or ``-q``, whichever has the canonical sign (:func:`needs_sign_flip`); no branch."""
    flip = needs_sign_flip(x, y, z, w)
    # + 0.0 turns w = -0.0 into 0.0
    return -x if flip else x, -y if flip else y, -z if flip else z, (-w if flip else w) + 0.0


@jit
def canonical_unit_quaternion(x: float, y: float, z: float, w: float) -> Quaternion4:
    """Return the unit quaternion with the canonical sign (see :func:`needs_sign_flip`)."""
    x, y, z, w = unit_quaternion(x, y, z, w)
    return with_canonical_sign(x, y, z, w)


@jit
def product(px: float, py: float, pz: float, pw: float,
            qx: float, qy: float, qz: float, qw: float) -> Quaternion4:
    """Hamilton product ``p (x) q``."""
    return (pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz)


@jit
def conjugate_product(px: float, py: float, pz: float, pw: float,
                      qx: float, qy: float, qz: float, qw: float) -> Quaternion4:
    """``p* (x) q`` with each cancelling pair grouped: exactly zero vector part for ``q = +-p``."""
    return ((pw * qx - px * qw) - (py * qz - pz * qy),
            (pw * qy - py * qw) - (pz * qx - px * qz),
            (pw * qz - pz * qw) - (px * qy - py * qx),
            pw * qw + px * qx + py * qy + pz * qz)


@jit
def rotated_by_unit(x: float, y: float, z: float, w: float,
                    vx: float, vy: float, vz: float) -> Vector3:
    """``R(q) v`` for a unit quaternion: ``v + w t + u x t`` with ``t = 2 u x v`` (|v| < 2^500)."""
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx))


@jit
def rotated_vector(x: float, y: float, z: float, w: float,
                   vx: float, vy: float, vz: float) -> Vector3:
    """``R(q) v`` for a unit quaternion, any finite ``v`` (beyond 2^500 rescaled exactly)."""
    m = max(abs(vx), abs(vy), abs(vz))
    e = binary_exponent(m) if m > _SAFE_HIGH else 0
    vx, vy, vz = math.ldexp(vx, -e), math.ldexp(vy, -e), math.ldexp(vz, -e)
    rx, ry, rz = rotated_by_unit(x, y, z, w, vx, vy, vz)
    return math.ldexp(rx, e), math.ldexp(ry, e), math.ldexp(rz, e)


@jit
def half_angle_atan2(vector_norm_value: float, scalar: float) -> float:
    """Rotation angle ``2 atan2(|q_v|, |q_s|)`` in [0, pi]: ~1 ulp for every angle."""
    return 2.0 * math.atan2(vector_norm_value, abs(scalar))


@jit
def quaternion_status(fq: FloatArray, s: int, argument: int) -> int:
    """Status of sample ``s`` of the flat quaternions ``fq`` (-1 when fine)."""
    code = quaternion_defect(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1 if code == OK else status(s, argument, code)


@jit
def vector_status(fv: FloatArray, s: int, argument: int) -> int:
    """Status of sample ``s`` of the flat 3-vectors ``fv`` (-1 when fine)."""
    code = vector_defect(fv[s, 0], fv[s, 1], fv[s, 2])
    return -1 if code == OK else status(s, argument, code)


# Sums of absolute values within these bounds need no rescaling (a sum above _PLAIN_LOW has
# a component above a quarter of it, above _SAFE_LOW).
_PLAIN_LOW = 4.0 * _SAFE_LOW
_PLAIN_HIGH = _SAFE_HIGH


@jit
def is_plain_quaternion(x: float, y: float, z: float, w: float) -> bool:
    """Whether ``q`` is finite, non-zero and needs no rescaling (sufficient, not necessary)."""
    m = abs(x) + abs(y) + abs(z) + abs(w)
    return (m > _PLAIN_LOW) & (m < _PLAIN_HIGH)


@jit
def is_plain_vector(x: float, y: float, z: float) -> bool:
    """Whether a 3-vector is finite and needs no rescaling (:func:`rotated_vector`), no branch."""
    return abs(x) + abs(y) + abs(z) < _PLAIN_HIGH


# ----------------------------------------------------------------- kernels
# The product and the rotation run chunk by chunk: a loop without branches (LLVM vectorises
# it) computes every sample with the formulas for plain inputs and counts the plain ones;
# only a chunk holding another sample is checked for its first bad one and computed again
# with the rescaling formulas. The results are those of the per-sample formulas, bit for bit.

# Samples per chunk: its inputs stay in the L1 cache for the second loop.
PLAIN_CHUNK = 256


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT)
def _product_kernel(p, q, out):
    fp, fq, fo = samples(p, 4), samples(q, 4), samples(out, 4)
    n = fp.shape[0]
    for start in range(0, n, PLAIN_CHUNK):
        stop = min(n, start + PLAIN_CHUNK)
        plain = 0
        for i in range(start, stop):   # no branch: a SIMD loop
            s = np.uintp(i)   # an unsigned index: no wraparound test for negative ones
            px, py, pz, pw = fp[s, 0], fp[s, 1], fp[s, 2], fp[s, 3]
            qx, qy, qz, qw = fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3]
            plain += is_plain_quaternion(px, py, pz, pw) & is_plain_quaternion(qx, qy, qz, qw)
            fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = product(px, py, pz, pw, qx, qy, qz, qw)
        if plain < stop - start:   # a bad sample, or only a huge one: find out which
            for k in range(start, stop):
                bad = first_status(quaternion_status(fp, k, 0), quaternion_status(fq, k, 1))
                if bad >= 0:
                    return bad
    return -1


@kernel(FLAT_IN, FLAT_OUT)
def _conjugate_kernel(q, out):
    fq, fo = samples(q, 4), samples(out, 4)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = -fq[s, 0], -fq[s, 1], -fq[s, 2], fq[s, 3]
    return -1


@kernel(FLAT_IN, FLAT_OUT)
def canonical_kernel(q: FloatArray, out: FloatArray) -> int:
    """Canonical unit quaternions of ``q`` into ``out``."""
    fq, fo = samples(q, 4), samples(out, 4)
    for s in range(fq.shape[0]):
        bad = quaternion_status(fq, s, 0)
        if bad >= 0:
            return bad
        fo[s, 0], fo[s, 1], fo[s, 2], fo[s, 3] = canonical_unit_quaternion(
            fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
    return -1


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT)
def _distance_kernel(p, q, out):
    fp, fq, fo = samples(p, 4), samples(q, 4), samples(out, 0)
    for s in range(fp.shape[0]):
        bad = first_status(quaternion_status(fp, s, 0), quaternion_status(fq, s, 1))
        if bad >= 0:
            return bad
        px, py, pz, pw = scaled_quaternion(fp[s, 0], fp[s, 1], fp[s, 2], fp[s, 3])
        qx, qy, qz, qw = scaled_quaternion(fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3])
        ex, ey, ez, ew = conjugate_product(px, py, pz, pw, qx, qy, qz, qw)
        fo[s] = half_angle_atan2(vector_norm(ex, ey, ez), ew)
    return -1


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT)
def _rotate_kernel(q, v, out):
    fq, fv, fo = samples(q, 4), samples(v, 3), samples(out, 3)
    n = fq.shape[0]
    for start in range(0, n, PLAIN_CHUNK):
        stop = min(n, start + PLAIN_CHUNK)
        plain = 0
        for i in range(start, stop):   # no branch: a SIMD loop
            s = np.uintp(i)   # an unsigned index: no wraparound test for negative ones
            x, y, z, w = fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3]
            vx, vy, vz = fv[s, 0], fv[s, 1], fv[s, 2]
            plain += is_plain_quaternion(x, y, z, w) & is_plain_vector(vx, vy, vz)
            # canonical_unit_quaternion and rotated_vector where neither rescales
            x, y, z, w = divided_by_norm(x, y, z, w)
            x, y, z, w = with_canonical_sign(x, y, z, w)
            fo[s, 0], fo[s, 1], fo[s, 2] = rotated_by_unit(x, y, z, w, vx, vy, vz)
        if plain < stop - start:   # redo the chunk with the rescaling formulas
            for k in range(start, stop):
                bad = first_status(quaternion_status(fq, k, 0), vector_status(fv, k, 1))
                if bad >= 0:
                    return bad
                x, y, z, w = canonical_unit_quaternion(fq[k, 0], fq[k, 1], fq[k, 2], fq[k, 3])
                fo[k, 0], fo[k, 1], fo[k, 2] = rotated_vector(x, y, z, w,
                                                              fv[k, 0], fv[k, 1], fv[k, 2])
    return -1


# ------------------------------------------------------------ public API

def quaternion_product(p: ArrayLike, q: ArrayLike) -> FloatArray:
    """
    Hamilton product of two quaternions.

    Parameters
    ----------
    p, q : array_like, shape (..., 4)
        Quaternions (x, y, z, w); leading dimensions broadcast.

    Returns
    -------
    ndarray, shape (..., 4)
        ``p (x) q``: the rotation ``q`` followed by ``p`` (``R(p) R(q)``). Not normalised,
        so that the product of unit quaternions stays exact to rounding.

    Raises
    ------
    ValueError
        Wrong shape, a NaN/Inf component, or a zero quaternion.

    """
    return call_binary(_product_kernel, p, q, ('p', 'q'), ((4,), (4,)), (4,))


def quaternion_conjugate(q: ArrayLike) -> FloatArray:
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
    return call_unary(_conjugate_kernel, q, 'q', (4,), (4,))


def canonical_quaternion(q: ArrayLike) -> FloatArray:
    """
    Return the unit quaternion with ``w >= 0`` representing the same rotation.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (x, y, z, w), any non-zero norm (1e-160 to 1e+160 are fine).

    Returns
    -------
    ndarray, shape (..., 4)
        ``q / |q|`` with the sign chosen so that ``w > 0``; where ``w == 0`` the first
        non-zero of x, y, z is positive. ``q`` and ``-q`` give the same result.

    """
    return call_unary(canonical_kernel, q, 'q', (4,), (4,))


def quaternion_distance(p: ArrayLike, q: ArrayLike) -> FloatArrayOrScalar:
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
    return call_binary(_distance_kernel, p, q, ('p', 'q'), ((4,), (4,)), ())


def rotate_vector(q: ArrayLike, v: ArrayLike) -> FloatArray:
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
    return call_binary(_rotate_kernel, q, v, ('q', 'v'), ((4,), (3,)), (3,))
