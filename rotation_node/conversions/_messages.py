"""
Samples given as objects with attributes: ROS message fields, by duck typing.

The rule, defined here once: an object with attributes ``x``, ``y``, ``z``
and ``w`` *is* the tuple ``(x, y, z, w)`` (``geometry_msgs/Quaternion``: the
library's order), one with ``x``, ``y``, ``z`` and no ``w`` the tuple
``(x, y, z)`` (``Vector3``, ``Point``); the tuple is then taken as any tuple
is, its items as numpy's float64 conversion takes them. So a Vector3 where
a quaternion is needed, or a Quaternion where a 3-vector is (never cut
short), is a sample of the wrong shape, refused with a message naming what
it lacks or has (:func:`refusal`). Nothing of ROS is imported: the
attributes decide. Sequences, arrays and numbers are never read by
attribute (numpy's conversion decides), and only quaternion and 3-vector
arguments take such objects.

How objects of a type are read is decided once per type
(:data:`message_readers`): by the type where it decides (no instance
``__dict__``, no ``__getattr__``: the classes rosidl generates, whose fields
are slots), else object by object. For a rosidl class, whose field ``x`` is
a property returning the slot ``_x`` (checked on its code), the reader reads
the slots: a Python property call costs ~45 ns a field, a quaternion's four
~0.15 us of a ~1 us single-sample call (measured).
"""
from __future__ import annotations

from inspect import getattr_static
from types import MemberDescriptorType
from typing import Any, Callable, Optional

QUATERNION_FIELDS = ('x', 'y', 'z', 'w')
VECTOR_FIELDS = ('x', 'y', 'z')
_QUATERNION, _VECTOR = (4,), (3,)
_NOT_SAMPLES = ('__len__', '__iter__', '__array__', '__float__', '__index__')


def _slot_quaternion(m: Any) -> Any:
    return (m._x, m._y, m._z, m._w)


def _slot_vector(m: Any) -> Any:
    return (m._x, m._y, m._z)


def _quaternion(m: Any) -> Any:
    return (m.x, m.y, m.z, m.w)


def _vector(m: Any) -> Any:
    return (m.x, m.y, m.z)


def _returns_slot(self: Any) -> Any:
    return self._x   # the code of a rosidl field getter (any field name)


def _reads_slots(kind: type, fields: tuple[str, ...]) -> bool:
    """Whether each field of ``kind`` is a property returning the slot of its name with a '_'."""
    for field in fields:
        getter = getattr_static(kind, field, None)
        code = getattr(getattr(getter, 'fget', None), '__code__', None)
        slot = '_' + field
        if not (type(getter) is property and code is not None
                and code.co_code == _returns_slot.__code__.co_code
                and code.co_names == (slot,) and code.co_argcount == 1
                and type(getattr_static(kind, slot, None)) is MemberDescriptorType):
            return False
    return True


def _no_sample(x: Any) -> None:
    return None


def _has_field(kind: type, name: str) -> bool:
    return getattr_static(kind, name, None) is not None


def _each_object_decides(x: Any) -> Any:
    try:
        return _quaternion(x) if hasattr(x, 'w') else _vector(x)
    except AttributeError:
        return None


def _new_reader(kind: type) -> Callable[[Any], Any]:
    """Return the reader of objects of type ``kind`` (see :data:`message_readers`)."""
    if issubclass(kind, type) or any(hasattr(kind, name) for name in _NOT_SAMPLES):
        return _no_sample   # classes (a message class for its instance); sequences, arrays and
        # numbers: numpy's conversion decides
    if not (getattr(kind, '__dictoffset__', 1) == 0 and not hasattr(kind, '__getattr__')
            and kind.__getattribute__ is object.__getattribute__):
        return _each_object_decides   # instance attributes: each object has its own
    # No instance __dict__, no __getattr__: the type decides (the classes rosidl generates).
    if not all(_has_field(kind, name) for name in VECTOR_FIELDS):
        return _no_sample
    if _has_field(kind, 'w'):
        return _slot_quaternion if _reads_slots(kind, QUATERNION_FIELDS) else _quaternion
    return _slot_vector if _reads_slots(kind, VECTOR_FIELDS) else _vector


#: ``message_readers[type(x)](x)``: the tuple (x.x, x.y, x.z, x.w), or (x.x, x.y, x.z) for an
#: object without ``w``, or None for an object without x, y, z (or a sequence, array or number).
#: A type seen for the first time raises KeyError (:func:`message_sample` adds it); a reader
#: may raise AttributeError (a slot never set: no sample either). A plain dict, looked up
#: inline by the single-sample path: ~25 ns, where a call to message_sample costs ~100 ns more.
message_readers: dict[type, Callable[[Any], Any]] = {}


def message_sample(x: Any, kind: type) -> Any:
    """Return the tuple of ``x``'s attributes x, y, z(, w) (``x`` of type ``kind``), or None."""
    read = message_readers.get(kind)
    if read is None:
        if len(message_readers) >= 512:   # a program making classes on the fly: no growth
            message_readers.clear()
        read = message_readers[kind] = _new_reader(kind)
    try:
        return read(x)
    except AttributeError:
        return None


def message_values(x: Any, trailing: tuple[int, ...]) -> tuple[Any, bool]:
    """
    Return ``x`` with every object holding a sample replaced by its tuple, and whether any was.

    For the general path, after numpy's conversion refused ``x``: a (nested)
    list or tuple of messages becomes lists of tuples. Anything else is left
    as it is, for numpy to refuse with its reason.
    """
    kind = type(x)
    if kind is list or kind is tuple:
        items = [message_values(item, trailing) for item in x]
        return [item for item, _ in items], any(found for _, found in items)
    sample = message_sample(x, kind) if trailing in (_QUATERNION, _VECTOR) else None
    return (x, False) if sample is None or len(sample) != trailing[0] else (sample, True)


def refusal(x: Any, trailing: tuple[int, ...]) -> str:
    """
    Return why ``x`` (a message or a nested sequence of them) gives no samples, or ''.

    For the general path's error message, after numpy refused ``x`` and the
    tuples of its messages: the first object (depth first) lacking an
    attribute the sample needs, or with a ``w`` where a 3-vector is needed,
    with its index; '' where every object has its attributes (a value is what
    is wrong: numpy says which) or none has any.
    """
    found = _first_refused(x, trailing, ())
    if found is None:
        return ''
    index, kind, why = found
    if not index:
        return f'it {why}'
    return f'item {"".join(f"[{i}]" for i in index)}, a {kind.__name__}, {why}'


def _first_refused(x: Any, trailing: tuple[int, ...],
                   index: tuple[int, ...]) -> Optional[tuple[tuple[int, ...], type, str]]:
    """Return (index, type, why) of the first object of ``x`` refused as a sample, or None."""
    fields = (QUATERNION_FIELDS if trailing == _QUATERNION else
              VECTOR_FIELDS if trailing == _VECTOR else None)
    kind = type(x)
    if fields is None:
        return None
    if kind is list or kind is tuple:
        for i, item in enumerate(x):
            found = _first_refused(item, trailing, index + (i,))
            if found is not None:
                return found
        return None
    lacking = [name for name in fields if not hasattr(x, name)]
    sample = message_sample(x, kind)
    if len(lacking) == len(fields) or sample is not None and len(sample) == len(fields):
        return None   # no object of such attributes at all (a string, None), or a sample
    if lacking:
        what = 'a quaternion is x, y, z, w' if fields is QUATERNION_FIELDS else 'x, y, z'
        return index, kind, f'has no attribute {", ".join(lacking)} ({what})'
    if fields is VECTOR_FIELDS and hasattr(x, 'w'):
        return index, kind, 'has an attribute w: a quaternion where a 3-vector (x, y, z) is needed'
    return None
