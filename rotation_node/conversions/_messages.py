"""
Samples given as objects with attributes: ROS message fields, by duck typing.

The rule, defined here once: an object with attributes x, y, z and w *is* the tuple
``(x, y, z, w)`` (``geometry_msgs/Quaternion``), one with x, y, z and no w the tuple
``(x, y, z)`` (``Vector3``, ``Point``), taken as any tuple is; a wrong kind is refused
naming what it lacks or has (:func:`refusal`). Nothing of ROS is imported; sequences,
arrays and numbers are never read by attribute. How a type is read is decided once
(:data:`message_readers`); a rosidl class, whose field ``x`` is a property returning the
slot ``_x`` (checked on its code), is read from its slots (~0.15 us less a quaternion).
"""
from __future__ import annotations

from inspect import getattr_static
from types import MemberDescriptorType
from typing import Any, Callable, Optional

QUATERNION_FIELDS = ('x', 'y', 'z', 'w')
VECTOR_FIELDS = ('x', 'y', 'z')
_QUATERNION, _VECTOR = (4,), (3,)
_NOT_SAMPLES = ('__len__', '__iter__', '__array__', '__float__', '__index__')


# Readers of a type's objects: attributes, or for rosidl classes their slots.
# Plain functions, not operator.attrgetter: measured 5-8 % faster per single-sample call on
# message objects (bench_conversions.py --single, message/ndarray 0.96-1.02 against 1.01-1.10).
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


#: ``message_readers[type(x)](x)``: x's tuple, or None (no x, y, z; a sequence or number).
#: A new type raises KeyError (:func:`message_sample` adds it), a slot never set
#: AttributeError. Looked up inline by the single-sample path (~100 ns less than a call).
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
    """Return ``x`` with each message in (nested) lists as its tuple, and whether any was."""
    kind = type(x)
    if kind is list or kind is tuple:
        items = [message_values(item, trailing) for item in x]
        return [item for item, _ in items], any(found for _, found in items)
    sample = message_sample(x, kind) if trailing in (_QUATERNION, _VECTOR) else None
    return (x, False) if sample is None or len(sample) != trailing[0] else (sample, True)


def refusal(x: Any, trailing: tuple[int, ...]) -> str:
    """
    Return why ``x`` (a message or nested sequences of them) gives no samples, or ''.

    The first object (depth first) lacking an attribute, or with a ``w`` where a 3-vector
    is needed, with its index; '' where every object or none has its attributes.
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
