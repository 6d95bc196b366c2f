"""
Argument checks at the public boundary of :mod:`rotation_node.conversions`.

Arguments become C-contiguous, aligned, writable float64 arrays of the right trailing
shape here; per-sample checks run inside the kernels, which report the first bad sample
as ``(flat_index << 4) | (argument << 3) | defect`` (-1: none), and
:func:`raise_sample_error` names the argument, the sample and what was wrong.
"""
from __future__ import annotations

from typing import Any, NamedTuple, NoReturn, Sequence, TYPE_CHECKING

import numpy as np

from ._messages import message_values, QUATERNION_FIELDS, refusal

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from ..type_aliases import FloatArray


# Defect codes returned by the kernels.
OK = 0
NON_FINITE = 1
ZERO_NORM = 2
NOT_ROTATION = 3
NOT_ORTHONORMAL = 4

_DEFECT_TEXT = {
    NON_FINITE: 'has a NaN or Inf component',
    ZERO_NORM: 'has zero norm (a zero quaternion or axis is not a rotation)',
    NOT_ROTATION: 'has det <= 0 (not a rotation matrix)',
    NOT_ORTHONORMAL: 'is not orthonormal within `orthonormal_tolerance`',
}

_SHAPE_TEXT = {(): '(...)', (3,): '(..., 3)', (4,): '(..., 4)', (3, 3): '(..., 3, 3)',
               (4, 4): '(..., 4, 4)'}


def float_array(x: ArrayLike, name: str, trailing: tuple[int, ...]) -> FloatArray:
    """
    Return ``x`` as a C-contiguous, aligned, writable float64 array ending in ``trailing``.

    A copy only where needed; ``ValueError`` naming ``name`` for a non-numeric ``x`` or
    another shape.
    """
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:   # Overflow: an int beyond float64
        a = _message_array(x, name, trailing, exc)
    k = len(trailing)
    if a.shape[a.ndim - k:] != trailing or a.ndim < k:
        raise ValueError(
            f'Expected `{name}` to have shape {_SHAPE_TEXT[trailing]}, got {a.shape}.')
    return kernel_ready(a)


def _message_array(x: Any, name: str, trailing: tuple[int, ...],
                   refused: Exception) -> NDArray[Any]:
    """
    Return ``x``, which numpy refused, as an array of its messages' values, or raise ValueError.

    The error names the first object lacking an attribute, else numpy's reason.
    """
    values, found = message_values(x, trailing)
    why: object = refused
    if found:
        try:
            return np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError, OverflowError) as exc:
            why = exc
    lacking = refusal(x, trailing)   # an object without the attributes: named first
    objects = (f' or objects with attributes {", ".join(QUATERNION_FIELDS[:trailing[0]])}'
               if found or lacking else '')
    raise ValueError(f'Expected `{name}` to be an array of numbers with shape '
                     f'{_SHAPE_TEXT[trailing]}{objects}, got {type(x).__name__}: '
                     f'{lacking or why}') from None


def kernel_ready(a: NDArray[Any]) -> FloatArray:
    """Return ``a`` if C-contiguous, aligned and writable (as kernels take it), else a copy."""
    return a if a.flags.carray else np.array(a, order='C')


def broadcast_pair(a: FloatArray, b: FloatArray, trailing_a: tuple[int, ...],
                   trailing_b: tuple[int, ...]) -> tuple[FloatArray, FloatArray]:
    """Broadcast two arrays from :func:`float_array` to a common leading shape."""
    lead_a = a.shape[:a.ndim - len(trailing_a)]
    lead_b = b.shape[:b.ndim - len(trailing_b)]
    if lead_a == lead_b:
        return a, b
    try:
        lead = np.broadcast_shapes(lead_a, lead_b)
    except ValueError:
        raise ValueError(
            f'Leading shapes of the arguments do not broadcast: {lead_a} and {lead_b}.') from None
    return (kernel_ready(np.broadcast_to(a, lead + trailing_a)),
            kernel_ready(np.broadcast_to(b, lead + trailing_b)))


def raise_sample_error(status: int, names: Sequence[str], arrays: Sequence[NDArray[Any]],
                       trailings: Sequence[tuple[int, ...]]) -> NoReturn:
    """Raise the ``ValueError`` for the bad sample that a kernel's ``status`` reports."""
    flat_index, argument, code = status >> 4, (status >> 3) & 1, status & 7
    array, trailing = arrays[argument], trailings[argument]
    lead = array.shape[:array.ndim - len(trailing)]
    index = tuple(int(i) for i in np.unravel_index(flat_index, lead)) if lead else ()
    where = f' at index {index}' if lead else ''
    raise ValueError(f'`{names[argument]}`{where} {_DEFECT_TEXT[code]}.')


class EulerSequence(NamedTuple):
    """
    A validated Euler axis sequence.

    Attributes
    ----------
    name : str
        The sequence as given, e.g. ``'xyz'`` (extrinsic) or ``'ZYX'`` (intrinsic).
    axes : tuple of int
        Axis indices (0 = x, 1 = y, 2 = z) in the order the angles are given.
    intrinsic : bool
        True for upper case (rotations about the moving body axes).
    proper : bool
        True for proper Euler sequences (first axis == third axis, e.g. ``'ZXZ'``),
        False for Tait-Bryan sequences (three different axes, e.g. ``'xyz'``).

    """

    name: str
    axes: tuple[int, int, int]
    intrinsic: bool
    proper: bool


_LOWER = ('xyz', 'xzy', 'yxz', 'yzx', 'zxy', 'zyx', 'xyx', 'xzx', 'yxy', 'yzy', 'zxz', 'zyz')
#: The 24 conventions: 12 extrinsic (lower case) and 12 intrinsic (upper case).
SEQUENCES = _LOWER + tuple(s.upper() for s in _LOWER)


def _parsed(name: str) -> EulerSequence:
    a, b, c = ('xyz'.index(axis) for axis in name.lower())
    return EulerSequence(name, (a, b, c), name.isupper(), a == c)


#: The 24 conventions by name.
SEQUENCE_TABLE = {name: _parsed(name) for name in SEQUENCES}


def parse_sequence(seq: object) -> EulerSequence:
    """
    Validate an Euler axis sequence.

    Parameters
    ----------
    seq : str
        Three letters from x, y, z with no two consecutive alike. Upper case is
        intrinsic (body axes, ``R = R1 R2 R3``), lower case extrinsic (fixed
        axes, ``R = R3 R2 R1``). ROS roll-pitch-yaw (REP 103) is ``'xyz'``.

    Returns
    -------
    EulerSequence
        The parsed sequence; one of the 24 conventions.

    Raises
    ------
    ValueError
        If ``seq`` is not one of the 24 conventions; the message says why.

    """
    parsed = SEQUENCE_TABLE.get(seq) if isinstance(seq, str) else None
    if parsed is not None:
        return parsed
    if not isinstance(seq, str):
        why = f'got {type(seq).__name__}'
    elif len(seq) != 3:
        why = f'got {seq!r} with {len(seq)} characters'
    elif set(seq.lower()) - set('xyz'):
        why = f'got {seq!r}: only the letters x, y, z are axes'
    elif not (seq.islower() or seq.isupper()):
        why = f'got {seq!r}: mixed case (all upper = intrinsic, all lower = extrinsic)'
    else:
        why = f'got {seq!r}: two consecutive axes are the same'
    raise ValueError(
        f'Expected `seq` to be three of x, y, z with no two consecutive alike, '
        f'all upper case (intrinsic) or all lower case (extrinsic); {why}.')
