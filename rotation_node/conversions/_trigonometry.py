"""
``sin`` and ``cos`` of one angle together, in compiled code that vectorises.

numba calls the C library's scalar ``sin`` and ``cos`` (PyPI's llvmlite has no
SVML), ~15 ns each here, and a call inside a loop stops LLVM from vectorising
it. Every conversion that builds a rotation from an angle needs both, so this
module evaluates them the way fdlibm does, with arithmetic only:

- Cody-Waite reduction ``r = a - n pi/2`` with pi/2 split in two (33 + 53
  bits, so ``n * PIO2_HI`` is exact for ``|n| < 2^20``), keeping the rounding
  error of ``r`` as a tail (fdlibm ``__ieee754_rem_pio2``, medium case);
- fdlibm's ``__kernel_sin`` and ``__kernel_cos`` minimax polynomials on
  ``|r| <= pi/4``;
- the quadrant ``n mod 4`` chosen by selects, not branches.

Accuracy against 300-bit mpmath: within 0.7 ulp of the result, except within
a few ulps of a zero of sin or cos (``a`` at a multiple of pi/2), where the
absolute error stays below 4e-21 (fdlibm spends extra reduction steps there to
keep the relative error small too; a rotation only needs the absolute one).

Round-to-nearest uses the ``1.5 * 2^52`` trick, which is exact under numba's
default strict floating point. Beyond ``|a| = REDUCTION_LIMIT`` the reduction
would lose accuracy, and :func:`sin_cos` falls back to the C library (no
rotation in practice: 5e5 rad is 80000 turns).
"""
import math

from ._runtime import jit

# fdlibm k_sin.c and k_cos.c.
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
# fdlibm e_rem_pio2.c: 2/pi, and pi/2 as its first 33 bits plus the rest.
_INVPIO2 = 6.36619772367581382433e-01
_PIO2_HI = 1.57079632673412561417e+00
_PIO2_LO = 6.07710050650619224932e-11
# Adding and subtracting 1.5 * 2^52 rounds a double below 2^51 to the nearest integer.
_ROUND = 6755399441055744.0

#: Largest ``|angle|`` that :func:`reduced_sin_cos` handles to < 1 ulp (|n| < 2^19).
REDUCTION_LIMIT = 2.0 ** 19


@jit
def reduced_sin_cos(a):
    """
    ``(sin a, cos a)`` for ``|a| <= REDUCTION_LIMIT``, without calls or branches.

    Accurate as the module says; larger ``|a|`` give wrong values: use :func:`sin_cos`.
    """
    n = (a * _INVPIO2 + _ROUND) - _ROUND
    head = a - n * _PIO2_HI                   # exact
    r = head - n * _PIO2_LO
    tail = (head - r) - n * _PIO2_LO           # r + tail = a - n pi/2 to ~2^-85 n
    quadrant = n - 4.0 * ((0.25 * n - 0.375 + _ROUND) - _ROUND)   # n mod 4, in {0, 1, 2, 3}
    z = r * r
    v = z * r
    sin_poly = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    s = r - ((z * (0.5 * tail - v * sin_poly) - tail) - v * _S1)
    cos_poly = _C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6))))
    half_z = 0.5 * z
    one_minus = 1.0 - half_z
    c = one_minus + (((1.0 - one_minus) - half_z) + (z * z * cos_poly - r * tail))
    odd = quadrant == 1.0 or quadrant == 3.0
    sin_a = c if odd else s
    cos_a = s if odd else c
    sin_a = -sin_a if quadrant >= 2.0 else sin_a
    cos_a = -cos_a if quadrant == 1.0 or quadrant == 2.0 else cos_a
    return sin_a, cos_a


@jit
def sin_cos(a):
    """``(sin a, cos a)`` of any finite ``a`` (accuracy: see the module)."""
    if abs(a) <= REDUCTION_LIMIT:
        return reduced_sin_cos(a)
    return math.sin(a), math.cos(a)


@jit
def sin_cos_in_place_kernel(a, cos_out):
    """
    ``a <- sin(a)``, ``cos_out <- cos(a)`` for 1-d float64 arrays of finite angles.

    The batch form of :func:`sin_cos`, same results: one vectorised loop
    (no calls, no branches) unless some ``|a| > REDUCTION_LIMIT``.
    """
    big = False
    for i in range(a.shape[0]):
        big |= abs(a[i]) > REDUCTION_LIMIT
    if big:
        for i in range(a.shape[0]):
            a[i], cos_out[i] = sin_cos(a[i])
    else:
        for i in range(a.shape[0]):
            a[i], cos_out[i] = reduced_sin_cos(a[i])
