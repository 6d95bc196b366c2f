"""
``scalar_first=True``: the public functions for (w, x, y, z) quaternions, from one adapter.

Quaternion arguments are reordered to (x, y, z, w) on the way in and a quaternion result
to (w, x, y, z) on the way out: the same numbers, bit for bit. Each adapted function is
written from the original's signature, so the default path costs one plain Python call.
"""
from __future__ import annotations

import functools
import inspect
from typing import Any, Callable, Sequence, TypeVar

import numpy as np

Result = TypeVar('Result')

_TO_SCALAR_LAST = [1, 2, 3, 0]
_TO_SCALAR_FIRST = [3, 0, 1, 2]


def scalar_last(q: Any) -> Any:
    """Reorder (w, x, y, z) to (x, y, z, w); anything else (messages name their fields) as is."""
    a = np.asarray(q)
    if a.ndim == 0 or a.shape[-1] != 4 or a.dtype == object:
        return q
    return a[..., _TO_SCALAR_LAST]


def scalar_first(q: Any) -> Any:
    """Reorder (x, y, z, w) to (w, x, y, z) in a result array."""
    return q[..., _TO_SCALAR_FIRST]


_NOTE = """
    With ``scalar_first=True`` the quaternions {what} are (w, x, y, z)
    instead of (x, y, z, w); the numbers are the same.
"""


def scalar_first_adapter(function: Callable[..., Result], quaternions: Sequence[str] = (),
                         returns_quaternion: bool = False) -> Callable[..., Result]:
    """Return ``function`` with the keyword ``scalar_first`` for its ``quaternions`` parameters."""
    signature = inspect.signature(function)
    parameters = [p.replace(annotation=inspect.Parameter.empty)
                  for p in signature.parameters.values()]
    parameters.append(inspect.Parameter('scalar_first', inspect.Parameter.KEYWORD_ONLY,
                                        default=False))
    text = str(inspect.Signature(parameters))
    call = ', '.join(p.name if p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
                     else f'{p.name}={p.name}' for p in parameters[:-1])
    reorder = ''.join(f'        {name} = _scalar_last({name})\n' for name in quaternions)
    result = '_scalar_first(result)' if returns_quaternion else 'result'
    source = (f'def {function.__name__}{text}:\n'
              f'    if scalar_first:\n{reorder}'
              f'        result = function({call})\n'
              f'        return {result}\n'
              f'    return function({call})\n')
    namespace = {'function': function, '_scalar_last': scalar_last, '_scalar_first': scalar_first}
    exec(compile(source, f'<scalar_first {function.__name__}>', 'exec'), namespace)  # noqa: S102
    adapted = functools.update_wrapper(namespace[function.__name__], function)
    del adapted.__wrapped__   # inspect.signature then shows the keyword
    what = ' and '.join(filter(None, [
        f'``{"``, ``".join(quaternions)}``' if quaternions else '',
        'returned' if returns_quaternion else '']))
    adapted.__doc__ = (function.__doc__ or '').rstrip() + '\n' + _NOTE.format(what=what)
    return adapted
