"""
Wording shared by the checks of parameters and of scene files.

Both name what was wrong the same way: a value by its type and a bounded
repr (a megabyte-long string is not copied into a log line), an unknown name
with the nearest valid one (``difflib``).
"""
import difflib
from typing import Any, Iterable

_MAX_REPR = 80


def describe_value(value: Any) -> str:
    """
    Return ``'<type> <repr>'`` of a value, the repr cut to a readable length.

    Examples
    --------
    >>> describe_value('x' * 100)[:12]
    "str 'xxxxxxx"

    """
    text = repr(value) if not isinstance(value, (list, dict, tuple)) or len(value) < 100 \
        else f'<{len(value)} items>'
    if len(text) > _MAX_REPR:
        text = f'{text[:_MAX_REPR - 20]}...{text[-12:]} ({len(text)} characters)'
    return f'{type(value).__name__} {text}'


def nearest_name(name: Any, names: Iterable[str]) -> str:
    """Return the valid name nearest to ``name`` (``difflib``), or '' if none is near."""
    matches = difflib.get_close_matches(str(name), list(names), n=1, cutoff=0.6)
    return matches[0] if matches else ''


def did_you_mean(name: Any, names: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the nearest valid name, or ''."""
    nearest = nearest_name(name, names)
    return f' (did you mean {nearest!r}?)' if nearest else ''
