"""
The argument checks only kinematics needs: the frame of an angular velocity, sample times.

Arrays are checked with :mod:`rotation_node.conversions.kernels`, the package's one contract.
"""
from __future__ import annotations

import math
from typing import Optional, TYPE_CHECKING

import numpy as np

from ..conversions.kernels import FLAT_IN, FLAT_OUT, kernel, kernel_ready

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray


def is_world_frame(frame: object) -> bool:
    """Return True for ``frame == 'world'`` (``w_w = R w_b``), False for ``'body'``, else raise."""
    if frame == 'body':
        return False
    if frame == 'world':
        return True
    raise ValueError(f"Expected `frame` to be 'body' or 'world', got {frame!r}.")


def sample_times(t: ArrayLike, n_samples: Optional[int] = None,
                 series_name: str = 't') -> tuple[FloatArray, FloatArray]:
    """
    Return the validated times ``t`` (float64) and their steps ``t[1:] - t[:-1]``, all > 0.

    ``n_samples``: the time axis length of the series argument ``series_name`` (default ``t``'s).
    """
    try:
        t = np.asarray(t, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'Expected `t` to be an array of numbers, got {type(t).__name__}: {exc}'
                         ) from None
    if n_samples is None:
        if t.ndim != 1:
            raise ValueError(f'Expected `t` to have shape (N,), got {t.shape}.')
        n_samples = t.shape[0]
    if n_samples < 2:
        raise ValueError(f'Expected `{series_name}` to hold a time series of N >= 2 samples, '
                         f'got N = {n_samples}.')
    if t.shape != (n_samples,):
        raise ValueError(f'Expected `t` to have shape ({n_samples},) to match `{series_name}`, '
                         f'got {t.shape}.')
    h = np.empty(n_samples - 1)
    t = kernel_ready(t)
    bad = _steps_kernel(t, h)
    if bad >= 0 and not math.isfinite(t[bad]):
        raise ValueError(f'`t` at index {bad} is {float(t[bad])!r}: times must be finite.')
    if bad >= 0:
        raise ValueError(f'Expected `t` to be strictly increasing, got '
                         f't[{bad}] = {float(t[bad])!r} <= t[{bad - 1}] = {float(t[bad - 1])!r}.')
    return t, h


@kernel(FLAT_IN, FLAT_OUT)
def _steps_kernel(t, h):
    """Fill ``h`` with the steps; return the first bad (NaN/Inf, not increasing) index or -1."""
    if not math.isfinite(t[0]):
        return 0
    for k in range(1, t.shape[0]):
        if not math.isfinite(t[k]):
            return k
        h[k - 1] = t[k] - t[k - 1]
        if not h[k - 1] > 0.0:
            return k
    return -1
