"""
Euler-angle rates <-> angular velocity, for all 24 conventions and both frames.

For an intrinsic sequence with axes ``e1, e2, e3`` and angles ``(b1, b2, b3)``
(``R = R1 R2 R3``) the body angular velocity is (``docs/numerics.md``)

    w_b = R3^T R2^T e1 b1' + R3^T e2 b2' + e3 b3' = J(b2, b3) b'.

Every other case reduces to this ``J``: extrinsic ``'ijk'`` with ``(a1, a2, a3)`` is intrinsic
``'KJI'`` with ``(a3, a2, a1)``; in the world frame, ``R^T`` is the intrinsic sequence
``(e3, e2, e1)`` at ``(-b3, -b2, -b1)`` with body angular velocity ``-w_w``. So a convention
and frame select three axis indices, whether the angle order is reversed and whether the
angles are negated; one kernel each way does the rest. It writes ``w = J r`` along
``(e_i, e_j, e_n)``, the axes of ``e1``, ``e2`` and the remaining one, with ``p = +1`` if
``(i, j, n)`` is cyclic, else ``-1``; ``c2, s2, c3, s3`` are the cosine and sine of the middle
and last angle. Tait-Bryan (``e3 = e_n``) inverses divide by ``c2``, proper Euler
(``e3 = e_i``) ones by ``s2``, nothing else: singular exactly at gimbal lock.

References
----------
.. [1] J. Diebel, "Representing Attitude: Euler Angles, Unit Quaternions, and
   Rotation Vectors", Stanford University, 2006.

"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING
import warnings

import numpy as np

from ._validation import is_world_frame
from ..conversions import parse_sequence
from ..conversions.kernels import (
    array_type, BOOL, call_binary, first_status, FLAT_IN, FLAT_OUT, FLOAT, INT, jit, kernel,
    samples, vector_status)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray

#: Default ``singularity_threshold`` (rad), ~sqrt(eps): closer to gimbal lock
#: the rates exceed 6.7e7 |omega| and a one-ulp change of the middle angle
#: changes them by more than 1e-8 relative.
DEFAULT_SINGULARITY_THRESHOLD = 1.5e-8

_RADIANS_PER_DEGREE = math.pi / 180.0


class EulerSingularityWarning(RuntimeWarning):
    """
    Euler rates were requested at (or within ``singularity_threshold`` of) gimbal lock.

    The affected samples are NaN (all three rates; mask ``np.isnan(rates[..., 0])``). Silence
    it with ``warnings.simplefilter('ignore', EulerSingularityWarning)`` when counting them.
    """


def _jacobian_axes(seq, frame):
    """Return ``(i, j, n, parity, proper, reverse, world)`` for a convention and frame."""
    spec = parse_sequence(seq)
    world = is_world_frame(frame)
    reverse = spec.intrinsic == world  # extrinsic body or intrinsic world
    a, j, c = spec.axes
    i = c if reverse else a
    n = 3 - i - j
    parity = 1.0 if (j - i) % 3 == 1 else -1.0
    return i, j, n, parity, spec.proper, reverse, world


@jit
def _jacobian_angles(angles, scale, reverse, world):
    """Cosine and sine of the middle and last angle (radians) of the reduced sequence."""
    middle = angles[1] * scale
    last = (angles[0] if reverse else angles[2]) * scale
    if world:
        middle, last = -middle, -last
    return math.cos(middle), math.sin(middle), math.cos(last), math.sin(last)


# The arguments after ``out``: the axes and flags of :func:`_jacobian_axes`, then the angle unit.
_JACOBIAN = (INT, INT, INT, FLOAT, BOOL, BOOL, BOOL, FLOAT)


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT, *_JACOBIAN)
def _angular_velocity_kernel(angles, rates, out, i, j, n, parity, proper, reverse, world, scale):
    fa, fr, fo = samples(angles, 3), samples(rates, 3), samples(out, 3)
    for s in range(fa.shape[0]):
        bad = first_status(vector_status(fa, s, 0), vector_status(fr, s, 1))
        if bad >= 0:
            return bad
        c2, s2, c3, s3 = _jacobian_angles(fa[s], scale, reverse, world)
        r1, r2, r3 = fr[s, 0] * scale, fr[s, 1] * scale, fr[s, 2] * scale
        if reverse:
            r1, r3 = r3, r1
        if proper:
            fo[s, i] = c2 * r1 + r3
            fo[s, j] = s2 * s3 * r1 + c3 * r2
            fo[s, n] = parity * (s2 * c3 * r1 - s3 * r2)
        else:
            fo[s, i] = c2 * c3 * r1 + parity * s3 * r2
            fo[s, j] = c3 * r2 - parity * c2 * s3 * r1
            fo[s, n] = r3 + parity * s2 * r1
    return -1


@kernel(FLAT_IN, FLAT_IN, FLAT_OUT, *_JACOBIAN, FLOAT, array_type(1, INT))
def _euler_rates_kernel(angles, omega, out, i, j, n, parity, proper, reverse, world, scale,
                        sin_threshold, singular):
    """Fill ``out``, count the near-singular samples into ``singular[0]``; return the status."""
    fa, fw, fo = samples(angles, 3), samples(omega, 3), samples(out, 3)
    for s in range(fa.shape[0]):
        bad = first_status(vector_status(fa, s, 0), vector_status(fw, s, 1))
        if bad >= 0:
            return bad
        c2, s2, c3, s3 = _jacobian_angles(fa[s], scale, reverse, world)
        if abs(s2 if proper else c2) <= sin_threshold:
            fo[s, 0] = fo[s, 1] = fo[s, 2] = np.nan
            singular[0] += 1
            continue
        wi, wj, wn = fw[s, i], fw[s, j], fw[s, n]
        if proper:
            r1 = (s3 * wj + parity * c3 * wn) / s2
            r2 = c3 * wj - parity * s3 * wn
            r3 = wi - c2 * r1
        else:
            r1 = (c3 * wi - parity * s3 * wj) / c2
            r2 = parity * s3 * wi + c3 * wj
            r3 = wn - parity * s2 * r1
        if reverse:
            r1, r3 = r3, r1
        fo[s, 0], fo[s, 1], fo[s, 2] = r1 / scale, r2 / scale, r3 / scale
    return -1


def angular_velocity_from_euler_rates(angles: ArrayLike, rates: ArrayLike, seq: str,
                                      frame: str = 'body', degrees: bool = False) -> FloatArray:
    """
    Angular velocity of Euler angles changing at the given rates.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        Euler angles (first, second, third of ``seq``), radians unless ``degrees``.
    rates : array_like, shape (..., 3)
        Their time derivatives, rad/s (deg/s if ``degrees``); broadcast with ``angles``.
    seq : str
        One of the 24 conventions: three of x, y, z, no two consecutive alike; upper case
        intrinsic (``R = R1 R2 R3``), lower case extrinsic (``R = R3 R2 R1``). ROS
        roll-pitch-yaw is ``'xyz'``.
    frame : {'body', 'world'}, optional
        Frame of the result: ``w_b``, or ``w_w = R w_b`` with ``R`` body-to-world.
    degrees : bool, optional
        Angles in degrees and rates in deg/s. The angular velocity is always rad/s.

    Returns
    -------
    ndarray, shape (..., 3)
        Angular velocity (rad/s) in ``frame``; defined everywhere, gimbal lock included.

    Raises
    ------
    ValueError
        Bad ``seq`` or ``frame``; wrong shape or NaN/Inf, naming the argument.

    """
    return call_binary(_angular_velocity_kernel, angles, rates, ('angles', 'rates'), ((3,), (3,)),
                       (3,), *_jacobian_axes(seq, frame),
                       _RADIANS_PER_DEGREE if degrees else 1.0)


def euler_rates_from_angular_velocity(
        angles: ArrayLike, omega: ArrayLike, seq: str, frame: str = 'body',
        degrees: bool = False, *,
        singularity_threshold: float = DEFAULT_SINGULARITY_THRESHOLD) -> FloatArray:
    """
    Euler-angle rates of an orientation turning with angular velocity ``omega``.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        Euler angles (first, second, third of ``seq``), radians unless ``degrees``.
    omega : array_like, shape (..., 3)
        Angular velocity (rad/s) in ``frame``; broadcast with ``angles``.
    seq : str
        One of the 24 conventions, as in :func:`angular_velocity_from_euler_rates`.
    frame : {'body', 'world'}, optional
        Frame of ``omega``: ``w_b``, or ``w_w = R w_b`` with ``R`` body-to-world.
    degrees : bool, optional
        Angles in degrees and the returned rates in deg/s. ``omega`` is always rad/s.
    singularity_threshold : float, optional
        Radians whatever ``degrees``, in [0, pi/2]: samples whose middle angle is this close
        to its singular value (+-pi/2 Tait-Bryan, 0 or pi proper Euler) get NaN rates.

    Returns
    -------
    ndarray, shape (..., 3)
        Rates of the three angles, rad/s (deg/s if ``degrees``): NaN for the near-singular
        samples, elsewhere finite even if large (they grow as ``|omega| / margin``).

    Warns
    -----
    EulerSingularityWarning
        Once per call if any sample was near-singular, with their count (mask:
        ``np.isnan(rates[..., 0])``).

    Raises
    ------
    ValueError
        Bad ``seq`` or ``frame``, ``singularity_threshold`` outside [0, pi/2]; wrong shape or
        NaN/Inf, naming the argument.

    """
    axes = _jacobian_axes(seq, frame)
    try:
        threshold = float(singularity_threshold)
    except (TypeError, ValueError):
        threshold = math.nan
    if not 0.0 <= threshold <= 0.5 * math.pi:
        raise ValueError('Expected `singularity_threshold` in [0, pi/2] rad, '
                         f'got {singularity_threshold!r}.')
    singular = np.zeros(1, dtype=np.int64)
    out = call_binary(_euler_rates_kernel, angles, omega, ('angles', 'omega'), ((3,), (3,)), (3,),
                      *axes, _RADIANS_PER_DEGREE if degrees else 1.0, math.sin(threshold),
                      singular)
    if singular[0]:
        warnings.warn(
            f'{singular[0]} of {out.size // 3} samples are within {threshold:g} rad of gimbal '
            f'lock in {seq!r}: their Euler rates are NaN.', EulerSingularityWarning, stacklevel=2)
    return out
