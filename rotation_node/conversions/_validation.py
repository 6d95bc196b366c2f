"""
Argument checks at the public boundary of :mod:`rotation_node.conversions`.

Public functions validate once, here: they turn array_like arguments into
C-contiguous float64 arrays flattened to ``(n, *trailing)`` and remember the
leading shape. Per-sample checks (finiteness, zero norm, determinant) run
inside the compiled kernels, which report the first bad sample as
``(flat_index, defect_code)``; :func:`raise_sample_error` turns that into a
``ValueError`` that names the argument, the sample and what was wrong.
"""
from collections import namedtuple

import numpy as np

# Defect codes returned by the kernels (0 = sample is fine).
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

_SHAPE_TEXT = {(): '(...)', (3,): '(..., 3)', (4,): '(..., 4)', (3, 3): '(..., 3, 3)'}


def flat_array(x, name, trailing):
    """
    Return ``x`` as a C-contiguous float64 array of shape ``(n, *trailing)``.

    Parameters
    ----------
    x : array_like
        The argument as the caller gave it (never modified).
    name : str
        The argument's name, for error messages.
    trailing : tuple of int
        The required trailing shape, e.g. ``(4,)`` or ``(3, 3)``.

    Returns
    -------
    flat : ndarray, shape (n, *trailing)
        The values; a copy only where a conversion or reordering was needed.
    lead : tuple of int
        The leading shape of ``x`` (``x.shape`` without ``trailing``).

    Raises
    ------
    ValueError
        If ``x`` is not numeric or its shape does not end in ``trailing``.
    """
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f'Expected `{name}` to be an array of numbers with shape '
            f'{_SHAPE_TEXT[trailing]}, got {type(x).__name__}: {exc}') from None
    k = len(trailing)
    if a.ndim < k or a.shape[a.ndim - k:] != trailing:
        raise ValueError(
            f'Expected `{name}` to have shape {_SHAPE_TEXT[trailing]}, got {a.shape}.')
    lead = a.shape[:a.ndim - k]
    return np.ascontiguousarray(a).reshape((-1,) + trailing), lead


def broadcast_flat(args, lead_shapes):
    """
    Broadcast flattened arguments against each other's leading shapes.

    Parameters
    ----------
    args : sequence of ndarray
        Arrays from :func:`flat_array`, each ``(n_i, *trailing_i)``.
    lead_shapes : sequence of tuple
        Their leading shapes.

    Returns
    -------
    flats : list of ndarray
        C-contiguous arrays with a common first dimension.
    lead : tuple of int
        The broadcast leading shape.
    """
    if all(s == lead_shapes[0] for s in lead_shapes):
        return list(args), lead_shapes[0]
    try:
        lead = np.broadcast_shapes(*lead_shapes)
    except ValueError:
        raise ValueError(
            'Leading shapes of the arguments do not broadcast: '
            + ', '.join(str(s) for s in lead_shapes)) from None
    out = []
    for a, s in zip(args, lead_shapes):
        full = np.broadcast_to(a.reshape(s + a.shape[1:]), lead + a.shape[1:])
        out.append(np.ascontiguousarray(full).reshape((-1,) + a.shape[1:]))
    return out, lead


def raise_sample_error(name, flat_index, code, lead):
    """Raise the ``ValueError`` for a bad sample reported by a kernel."""
    where = '' if lead == () else f' at index {tuple(int(i) for i in np.unravel_index(flat_index, lead))}'
    raise ValueError(f'`{name}`{where} {_DEFECT_TEXT[code]}.')


EulerSequence = namedtuple('EulerSequence', 'name axes intrinsic proper')
EulerSequence.__doc__ = """\
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


def _all_sequences():
    table = {}
    for a in range(3):
        for b in range(3):
            for c in range(3):
                if a == b or b == c:
                    continue
                lower = ''.join('xyz'[i] for i in (a, b, c))
                for name, intrinsic in ((lower, False), (lower.upper(), True)):
                    table[name] = EulerSequence(name, (a, b, c), intrinsic, a == c)
    return table


_SEQUENCES = _all_sequences()


def parse_sequence(seq):
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
    parsed = _SEQUENCES.get(seq) if isinstance(seq, str) else None
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
