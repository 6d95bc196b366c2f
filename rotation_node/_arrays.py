"""Argument checks shared by :mod:`rotation_node.covariance` and :mod:`rotation_node.frames`."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .conversions._validation import float_array

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from .type_aliases import FloatArray


def finite_array(x: ArrayLike, name: str, trailing: tuple[int, ...]) -> FloatArray:
    """
    Return ``x`` as a float64 array whose shape ends in ``trailing``, every element finite.

    The conversions' shape check, plus the finiteness check they make inside their kernels;
    a ValueError naming ``name`` otherwise.
    """
    a = float_array(x, name, trailing)
    finite = np.isfinite(a)
    if not finite.all():
        k = len(trailing)
        bad = np.argwhere(~finite)[0][:a.ndim - k]
        where = f' at index {tuple(int(i) for i in bad)}' if a.ndim > k else ''
        raise ValueError(f'`{name}`{where} has a NaN or Inf component.')
    return a
