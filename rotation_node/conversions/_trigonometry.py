"""
``sin`` and ``cos`` of one angle together, and ``atan2``, in compiled code that vectorises.

The C library's scalar functions stop LLVM from vectorising a loop; these are fdlibm's
polynomials with arithmetic and selects only (no calls, no branches): ``sin``/``cos``
within 0.7 ulp (absolute error < 4e-21 next to their zeros), ``atan2`` within 0.8 ulp,
signed zeros as C's, finite arguments. The method: docs/numerics.md. Round-to-nearest
uses the ``1.5 * 2^52`` trick, exact under numba's default strict floating point.
"""
from __future__ import annotations

import math
from typing import Any, Callable, TYPE_CHECKING

from ._runtime import compiled_form, jit

if TYPE_CHECKING:
    from ..type_aliases import FloatArray

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
def reduced_sin_cos(a: float) -> tuple[float, float]:
    """``(sin a, cos a)`` for ``|a| <= REDUCTION_LIMIT`` (larger: wrong; use :func:`sin_cos`)."""
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
def sin_cos(a: float) -> tuple[float, float]:
    """``(sin a, cos a)`` of any finite ``a`` (accuracy: see the module)."""
    if abs(a) <= REDUCTION_LIMIT:
        return reduced_sin_cos(a)
    return math.sin(a), math.cos(a)


@jit
def sin_cos_in_place_kernel(a: FloatArray, cos_out: FloatArray) -> None:
    """Compute ``a <- sin(a)``, ``cos_out <- cos(a)``: :func:`sin_cos` in one vectorised loop."""
    big = False
    for i in range(a.shape[0]):
        big |= abs(a[i]) > REDUCTION_LIMIT
    if big:
        for i in range(a.shape[0]):
            a[i], cos_out[i] = sin_cos(a[i])
    else:
        for i in range(a.shape[0]):
            a[i], cos_out[i] = reduced_sin_cos(a[i])


def fused_multiply_add(a: float, b: float, c: float) -> float:
    """Return ``a * b + c`` rounded once: LLVM's ``fma`` compiled, exact rationals interpreted."""
    if a == 0.0 or b == 0.0 or not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        return a * b + c    # the product is exact (or not finite): one rounding
    from fractions import Fraction   # (and decimal): here only, microseconds beside its use
    return float(Fraction(a) * Fraction(b) + Fraction(c))


@compiled_form(fused_multiply_add)
def _compiled_fused_multiply_add() -> Callable[..., Any]:
    from numba import types
    from numba.extending import intrinsic

    @intrinsic
    def fma(typingctx: Any, a: Any, b: Any, c: Any) -> tuple[Any, Callable[..., Any]]:
        signature = types.float64(types.float64, types.float64, types.float64)

        def codegen(context, builder, signature, args):
            return builder.fma(*args)

        return signature, codegen

    return fma


# fdlibm s_atan.c: atan(r) = r - r^3 (T0 + T1 r^2 + ... + T10 r^20) on |r| <= 7/16.
_T0 = 3.33333333333329318027e-01
_T1 = -1.99999999998764832476e-01
_T2 = 1.42857142725034663711e-01
_T3 = -1.11111104054623557880e-01
_T4 = 9.09088713343650656196e-02
_T5 = -7.69187620504482999495e-02
_T6 = 6.66107313738753120669e-02
_T7 = -5.83357013379057348645e-02
_T8 = 4.97687799461593236017e-02
_T9 = -3.65315727442169155270e-02
_T10 = 1.62858201153657823623e-02
# atan(c) (x >= 0) and pi - atan(c) (x < 0) as hi + lo, for c = 0, 1/2, 1, 3/2, inf
# (300-bit mpmath, rounded to nearest; the x >= 0 values are fdlibm's atanhi/atanlo).
_ATAN_0, _ATAN_0_LO = 0.0, 0.0
_ATAN_HALF, _ATAN_HALF_LO = 0.4636476090008061, 2.2698777452961687e-17
_ATAN_1, _ATAN_1_LO = 0.7853981633974483, 3.061616997868383e-17
_ATAN_3HALVES, _ATAN_3HALVES_LO = 0.982793723247329, 1.3903311031230998e-17
_ATAN_INF, _ATAN_INF_LO = 1.5707963267948966, 6.123233995736766e-17
_PI_MINUS_ATAN_0, _PI_MINUS_ATAN_0_LO = 3.141592653589793, 1.2246467991473532e-16
_PI_MINUS_ATAN_HALF, _PI_MINUS_ATAN_HALF_LO = 2.677945044588987, 1.5527705369303147e-16
_PI_MINUS_ATAN_1, _PI_MINUS_ATAN_1_LO = 2.356194490192345, 9.184850993605148e-17
_PI_MINUS_ATAN_3HALVES, _PI_MINUS_ATAN_3HALVES_LO = 2.158798930342464, 2.1958367134601997e-16
# Arguments scaled (by a power of two) into [2^-900, 2^1000]: the sums below
# cannot overflow and the fused multiply-add's residual cannot underflow.
_TINY, _SCALE_UP = 2.0 ** -900, 2.0 ** 600
_HUGE, _SCALE_DOWN = 2.0 ** 1000, 2.0 ** -8


@jit
def _reduced_atan_argument(ax, ay):
    """
    ``|y| / |x|`` reduced about ``c``: ``(num, num_lo, den, den_lo)`` and the interval flags.

    ``(num + num_lo) / (den + den_lo)`` is exactly ``(t - c) / (1 + c t)``, ``t = ay / ax``,
    ``c`` the first flag set of ``(inf, 3/2, 1, 1/2)``, else 0.
    """
    beyond_2, beyond_1, beyond_half, beyond_0 = (ay > 2.4375 * ax, ay > 1.1875 * ax,
                                                 ay > 0.6875 * ax, ay > 0.4375 * ax)
    two_ax, two_ay = ax + ax, ay + ay
    # c = 3/2: (2ay - 3ax) / (2ax + 3ay), 3ax and 3ay by Fast2Sum, 2ay - 3ax exact (Sterbenz).
    three_ax = two_ax + ax
    three_ax_lo = ax - (three_ax - two_ax)
    three_ay = two_ay + ay
    three_ay_lo = ay - (three_ay - two_ay)
    den_3halves = three_ay + two_ax
    den_3halves_lo = (two_ax - (den_3halves - three_ay)) + three_ay_lo
    # c = 1: (ay - ax) / (ay + ax), the difference exact (Sterbenz), the sum by Fast2Sum.
    den_1 = ay + ax
    den_1_lo = min(ax, ay) - (den_1 - max(ax, ay))
    # c = 1/2: (2ay - ax) / (2ax + ay), the difference exact, the sum by Fast2Sum.
    den_half = two_ax + ay
    den_half_lo = ay - (den_half - two_ax)
    if beyond_2:       # c = inf: -ax / ay
        return -ax, 0.0, ay, 0.0, beyond_2, beyond_1, beyond_half, beyond_0
    if beyond_1:
        return (two_ay - three_ax, -three_ax_lo, den_3halves, den_3halves_lo,
                beyond_2, beyond_1, beyond_half, beyond_0)
    if beyond_half:
        return ay - ax, 0.0, den_1, den_1_lo, beyond_2, beyond_1, beyond_half, beyond_0
    if beyond_0:
        return two_ay - ax, 0.0, den_half, den_half_lo, beyond_2, beyond_1, beyond_half, beyond_0
    return ay, 0.0, ax, 0.0, beyond_2, beyond_1, beyond_half, beyond_0


@jit
def atan2(y: float, x: float) -> float:
    """Return the arc tangent of finite ``y / x`` in the quadrant of ``(x, y)`` (C's ``atan2``)."""
    ax, ay = abs(x), abs(y)
    largest = max(ax, ay)
    scale = _SCALE_UP if largest < _TINY else (_SCALE_DOWN if largest > _HUGE else 1.0)
    ax, ay = ax * scale, ay * scale
    num, num_lo, den, den_lo, c_inf, c_3halves, c_1, c_half = _reduced_atan_argument(ax, ay)
    den = 1.0 if den == 0.0 else den     # x = y = 0: r = 0
    negative_x = math.copysign(1.0, x) < 0.0
    if negative_x:
        hi = (_ATAN_INF if c_inf else _PI_MINUS_ATAN_3HALVES if c_3halves else
              _PI_MINUS_ATAN_1 if c_1 else _PI_MINUS_ATAN_HALF if c_half else _PI_MINUS_ATAN_0)
        lo = (_ATAN_INF_LO if c_inf else _PI_MINUS_ATAN_3HALVES_LO if c_3halves else
              _PI_MINUS_ATAN_1_LO if c_1 else _PI_MINUS_ATAN_HALF_LO if c_half else
              _PI_MINUS_ATAN_0_LO)
    else:
        hi = (_ATAN_INF if c_inf else _ATAN_3HALVES if c_3halves else
              _ATAN_1 if c_1 else _ATAN_HALF if c_half else _ATAN_0)
        lo = (_ATAN_INF_LO if c_inf else _ATAN_3HALVES_LO if c_3halves else
              _ATAN_1_LO if c_1 else _ATAN_HALF_LO if c_half else _ATAN_0_LO)
    inverse = 1.0 / den
    r = num * inverse
    # The exact quotient is r + r_lo: the residual num - r den is exact (fma).
    r_lo = (fused_multiply_add(-r, den, num) + num_lo - r * den_lo) * inverse
    r = -r if negative_x else r       # pi - atan(c) - atan(r)
    r_lo = -r_lo if negative_x else r_lo
    z = r * r
    w = z * z
    odd = z * (_T0 + w * (_T2 + w * (_T4 + w * (_T6 + w * (_T8 + w * _T10)))))
    even = w * (_T1 + w * (_T3 + w * (_T5 + w * (_T7 + w * _T9))))
    return math.copysign(hi - ((r * (odd + even) - (lo + r_lo)) - r), y)


@jit
def atan2_in_place_kernel(y: FloatArray, x: FloatArray) -> None:
    """``y <- atan2(y, x)`` for 1-d float64 arrays of finite values: one vectorised loop."""
    for i in range(y.shape[0]):
        y[i] = atan2(y[i], x[i])
