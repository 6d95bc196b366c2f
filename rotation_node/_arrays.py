"""Argument checks shared by :mod:`rotation_node.covariance` and :mod:`rotation_node.frames`."""
import numpy as np


def _shape_text(trailing: tuple) -> str:
    return '(..., ' + ', '.join(str(n) for n in trailing) + ')'


def finite_array(x, name: str, trailing: tuple) -> np.ndarray:
    """
    Return ``x`` as a float64 array whose shape ends in ``trailing``, every element finite.

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
    ndarray
        The values as float64 (a copy only where a conversion was needed).

    Raises
    ------
    ValueError
        If ``x`` is not numeric, its shape does not end in ``trailing`` or an
        element is NaN or infinite; the message names the argument.
    """
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'Expected `{name}` to be an array of numbers with shape '
                         f'{_shape_text(trailing)}, got {type(x).__name__}: {exc}') from None
    k = len(trailing)
    if a.ndim < k or a.shape[a.ndim - k:] != tuple(trailing):
        raise ValueError(f'Expected `{name}` to have shape {_shape_text(trailing)}, '
                         f'got {a.shape}.')
    if not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0][:a.ndim - k]
        where = f' at index {tuple(int(i) for i in bad)}' if a.ndim > k else ''
        raise ValueError(f'`{name}`{where} has a NaN or Inf component.')
    return a
