"""
The checks of node parameters and scene files: dataclass fields of a kind of value.

A dataclass made of :func:`checked_field` fields says, per field, its kind of
value (:class:`Boolean`, :class:`Integer`, :class:`Real`, :class:`Text`,
:class:`Choice`, :class:`ChoiceList`, :class:`Vector`, :class:`Reals`; for
scenes also a dataclass: :class:`DataclassByTag`, :class:`DataclassesByName`,
:class:`NestedDataclass`) and, where the domain asks for more (a unit
quaternion, a frame name without a leading /), a further check.
:func:`checked_arguments` checks a mapping (a parsed YAML file, ROS parameters)
against those fields: unknown keys first, with the nearest valid name
(``difflib``), then missing required keys, then each value by its kind, so a
misspelt key reads as what it is.

Each problem raises the error type of a :class:`KeyPath`, and its message
starts with the value's path as the :class:`KeyPath` names it
(``motion.half_angle``, ``parameter 'qos.depth'``). Values are shown by type
and a bounded repr: a megabyte-long string is not copied into a log line.
"""
from __future__ import annotations

from collections.abc import Mapping
import dataclasses
import math
import re
from typing import Any, Callable, Iterable, Optional

_MAX_REPR = 80
_FIELD_SPEC = 'rotation_node.validation'   # the dataclass field metadata key


# --- wording ------------------------------------------------------------------

def short_repr(value: Any) -> str:
    """
    Return the repr of a value, cut to a readable length.

    Examples
    --------
    >>> short_repr('x' * 100)[:10]
    "'xxxxxxxxx"

    """
    text = repr(value) if not isinstance(value, (list, dict, tuple)) or len(value) < 100 \
        else f'<{len(value)} items>'
    if len(text) > _MAX_REPR:
        text = f'{text[:_MAX_REPR - 20]}...{text[-12:]} ({len(text)} characters)'
    return text


def type_and_repr(value: Any) -> str:
    """
    Return ``'<type> <repr>'`` of a value, the repr cut to a readable length.

    Examples
    --------
    >>> type_and_repr('x' * 100)[:12]
    "str 'xxxxxxx"

    """
    return f'{type(value).__name__} {short_repr(value)}'


def nearest_name(name: Any, names: Iterable[str]) -> str:
    """Return the valid name nearest to ``name`` (``difflib``), or '' if none is near."""
    import difflib   # (and heapq): only for a name that is not valid
    matches = difflib.get_close_matches(str(name), list(names), n=1, cutoff=0.6)
    return matches[0] if matches else ''


def did_you_mean(name: Any, names: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the nearest valid name, or ''."""
    nearest = nearest_name(name, names)
    return f' (did you mean {nearest!r}?)' if nearest else ''


@dataclasses.dataclass(frozen=True)
class KeyPath:
    """
    The path of a value in its document, and the errors that name it.

    Attributes
    ----------
    path : str
        Keys from the top of the document: ``'motion.orientation[2]'``; ``''``
        is the top.
    error_type : type of ValueError
        The error :meth:`error` returns.
    template : str
        How a message names the path: ``'{}'`` gives ``motion.half_angle:
        ...``, ``"parameter '{}'"`` gives ``parameter 'qos.depth': ...``.

    """

    path: str = ''
    error_type: type[ValueError] = ValueError
    template: str = '{}'

    def key(self, key: Any) -> 'KeyPath':
        """Return the path of the value of ``key`` of this mapping."""
        return dataclasses.replace(self, path=f'{self.path}.{key}' if self.path else str(key))

    def index(self, index: int) -> 'KeyPath':
        """Return the path of the item ``index`` of this list."""
        return dataclasses.replace(self, path=f'{self.path}[{index}]')

    def error(self, problem: str) -> ValueError:
        """Return the error ``'<path as the template names it>: <problem>'`` (to raise)."""
        return self.error_type(f'{self.template.format(self.path)}: {problem}')

    def type_error(self, expected: str, value: Any) -> ValueError:
        """Return the error ``'<path>: expected <expected>, got <type> <repr>'``."""
        return self.error(f'expected {expected}, got {type_and_repr(value)}')


# --- kinds of value -----------------------------------------------------------

class ValueKind:
    """
    A kind of value: :meth:`checked` returns a value of it in its stored form.

    ``constraints`` says the allowed values in words (for the parameter table);
    a number kind has ``bounds``, a string kind ``choices`` (what a ROS
    parameter descriptor carries).
    """

    constraints = ''

    def checked(self, value: Any, where: KeyPath) -> Any:
        """Return ``value`` in its stored form, or raise ``where``'s error naming the problem."""
        raise NotImplementedError


@dataclasses.dataclass(frozen=True)
class Boolean(ValueKind):
    """``true`` or ``false``; no number or string stands for one."""

    def checked(self, value: Any, where: KeyPath) -> bool:
        """Return ``value`` if it is a bool."""
        if not isinstance(value, bool):
            raise where.type_error('a boolean', value)
        return value


@dataclasses.dataclass(frozen=True)
class _Range(ValueKind):
    """A number in ``[minimum, maximum]`` (either bound optional), or > 0 with ``positive``."""

    minimum: Optional[float] = None
    maximum: Optional[float] = None
    positive: bool = dataclasses.field(default=False, kw_only=True)

    @property
    def bounds(self) -> Optional[tuple]:
        """Return ``(minimum, maximum)`` when both are set, else None."""
        return None if self.minimum is None or self.maximum is None \
            else (self.minimum, self.maximum)

    @property
    def constraints(self) -> str:  # type: ignore[override]
        """Return the range in words."""
        low, high = self.minimum, self.maximum
        if self.positive:
            return '> 0'
        if low is not None and high is not None:
            return f'from {low:g} to {high:g}'
        if low is not None:
            return f'>= {low:g}'
        return '' if high is None else f'<= {high:g}'

    def _in_range(self, number: Any, where: KeyPath) -> Any:
        if (self.positive and not number > 0
                or self.minimum is not None and number < self.minimum
                or self.maximum is not None and number > self.maximum):
            raise where.error(f'must be {self.constraints}, got {short_repr(number)}')
        return number


@dataclasses.dataclass(frozen=True)
class Integer(_Range):
    """An integer in ``[minimum, maximum]``; ``3.0`` and ``true`` are not integers."""

    def checked(self, value: Any, where: KeyPath) -> int:
        """Return ``value`` if it is an int within the bounds."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise where.type_error('an integer', value)
        return self._in_range(value, where)


@dataclasses.dataclass(frozen=True)
class Real(_Range):
    """
    A finite real number in ``[minimum, maximum]``, stored as float.

    ``integers``: an integer stands for the real number (``rate: 100``), as in
    scene files. A ROS double parameter takes no integer (``0`` is refused
    where ``0.0`` is meant): ``integers=False``. A bool is never a number.
    """

    integers: bool = dataclasses.field(default=True, kw_only=True)

    def checked(self, value: Any, where: KeyPath) -> float:
        """Return ``value`` as a float if it is a finite number within the bounds."""
        if isinstance(value, bool) or not isinstance(
                value, (int, float) if self.integers else float):
            raise where.type_error('a number' if self.integers else
                                   'a floating-point number (write 0.0, not 0)', value)
        try:
            number = float(value)
        except OverflowError:   # an integer beyond the float range
            number = math.inf
        if not math.isfinite(number):
            raise where.error(f'must be finite, got {short_repr(value)}')
        return self._in_range(number, where)


@dataclasses.dataclass(frozen=True)
class Text(ValueKind):
    """
    A string: any, one matching ``pattern``, or one ``parser`` accepts.

    ``noun`` says what the string is in messages (``'an absolute topic name
    such as /imu'``); ``parser(value)`` raises ValueError, saying why, for a
    string that is not valid (e.g. :func:`rotation_node.conversions.parse_sequence`).
    """

    noun: str = 'a string'
    pattern: Optional[re.Pattern] = None
    parser: Optional[Callable[[str], Any]] = None

    def checked(self, value: Any, where: KeyPath) -> str:
        """Return ``value`` if it is a string that matches and parses."""
        if not isinstance(value, str) or self.pattern and not self.pattern.fullmatch(value):
            raise where.type_error(self.noun, value)
        if self.parser is not None:
            try:
                self.parser(value)
            except ValueError as exc:
                raise where.error(f'{short_repr(value)} is not {self.noun} ({exc})') from None
        return value


def _not_allowed(item: Any, choices: tuple, words: str, where: KeyPath) -> ValueError:
    return where.error(f'{short_repr(item)} is not allowed{did_you_mean(item, choices)}; {words}')


@dataclasses.dataclass(frozen=True)
class Choice(ValueKind):
    """One string of ``choices``."""

    choices: tuple = ()

    @property
    def constraints(self) -> str:  # type: ignore[override]
        """Return ``'one of: a, b'``."""
        return f'one of: {", ".join(self.choices)}'

    def checked(self, value: Any, where: KeyPath) -> str:
        """Return ``value`` if it is one of the choices."""
        if not isinstance(value, str):
            raise where.type_error('a string', value)
        if value not in self.choices:
            raise _not_allowed(value, self.choices, self.constraints, where)
        return value


@dataclasses.dataclass(frozen=True)
class ChoiceList(ValueKind):
    """
    A non-empty list of distinct strings of ``choices``, stored as a tuple in the given order.

    ``item`` names an entry in messages (``'list at least one output'``). A
    missing value (``None``) is an empty list: ROS gives ``outputs: []`` of a
    parameters file as no value.
    """

    choices: tuple = ()
    item: str = 'entry'

    @property
    def constraints(self) -> str:  # type: ignore[override]
        """Return ``'each one of: a, b'``."""
        return f'each one of: {", ".join(self.choices)}'

    def checked(self, value: Any, where: KeyPath) -> tuple:
        """Return ``value`` as a tuple if it is a list of distinct choices."""
        if value is None:
            value = ()
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise where.type_error('a list of strings', value)
        if not value:
            raise where.error(f'list at least one {self.item}; '
                              f'choose from {", ".join(self.choices)}')
        for item in value:
            if item not in self.choices:
                raise _not_allowed(item, self.choices, self.constraints, where)
        repeated = sorted({item for item in value if value.count(item) > 1})
        if repeated:
            raise where.error(f'{", ".join(repeated)} listed twice')
        return tuple(value)


_NUMBER = Real()


@dataclasses.dataclass(frozen=True)
class Vector(ValueKind):
    """A list of ``size`` finite numbers (integers allowed), stored as a tuple of float."""

    size: int

    def checked(self, value: Any, where: KeyPath) -> tuple:
        """Return ``value`` as a tuple of float if it is a list of ``size`` finite numbers."""
        if not isinstance(value, (list, tuple)) or len(value) != self.size:
            raise where.type_error(f'a list of {self.size} numbers', value)
        return tuple(_NUMBER.checked(x, where.index(i)) for i, x in enumerate(value))


@dataclasses.dataclass(frozen=True)
class Reals(ValueKind):
    """
    A ROS double array: floats, as many as one of ``sizes``, stored as a tuple.

    Any sequence but a string or a mapping (rclpy gives an ``array.array``).
    """

    sizes: tuple = (3,)

    def checked(self, value: Any, where: KeyPath) -> tuple:
        """Return ``value`` as a tuple of float if it is a list of finite floats of a size."""
        number = Real(integers=False)
        expected = f'a list of {" or ".join(map(str, self.sizes))} numbers'
        if isinstance(value, (str, bytes, dict)) or not isinstance(value, Iterable):
            raise where.type_error(expected, value)
        items = list(value)
        if len(items) not in self.sizes:
            raise where.error(f'expected {expected}, got {len(items)}')
        return tuple(number.checked(x, where.index(i)) for i, x in enumerate(items))


@dataclasses.dataclass(frozen=True)
class DataclassByTag(ValueKind):
    """
    A mapping that is one of several dataclasses, chosen by the value of its key ``type``.

    ``classes`` maps each ``type`` value to its dataclass; ``noun`` names them
    in messages (``unknown motion 'wobble'``).
    """

    classes: Mapping[str, type]
    noun: str

    def checked(self, value: Any, where: KeyPath) -> Any:
        """Return the dataclass the mapping ``value`` describes."""
        if not isinstance(value, dict):
            raise where.type_error('a mapping with a type', value)
        expected = f'expected one of {", ".join(self.classes)}'
        if 'type' not in value:
            raise where.key('type').error(f'missing; {expected}')
        name = value['type']
        if not isinstance(name, str) or name not in self.classes:
            raise where.key('type').error(
                f'unknown {self.noun} {short_repr(name)}{did_you_mean(name, self.classes)}; '
                f'{expected}')
        return dataclass_from_mapping(self.classes[name], value, where, skip=('type',))


@dataclasses.dataclass(frozen=True)
class DataclassesByName(ValueKind):
    """
    A mapping of names of ``classes`` to mappings of their dataclass; stored as a dict.

    A missing value (``None``) is no entry; ``noun`` names an entry in
    messages (``unknown effect``).
    """

    classes: Mapping[str, type]
    noun: str

    def checked(self, value: Any, where: KeyPath) -> dict:
        """Return ``{name: dataclass}`` for the mapping ``value``."""
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise where.type_error(f'a mapping of {self.noun} names', value)
        for name in value:
            if name not in self.classes:
                raise where.key(name).error(
                    f'unknown {self.noun}{did_you_mean(name, self.classes)}; '
                    f'expected one of {", ".join(self.classes)}')
        return {name: dataclass_from_mapping(self.classes[name], fields, where.key(name))
                for name, fields in value.items()}


@dataclasses.dataclass(frozen=True)
class NestedDataclass(ValueKind):
    """A mapping that is the dataclass ``cls`` (:func:`dataclass_from_mapping`)."""

    cls: type

    def checked(self, value: Any, where: KeyPath) -> Any:
        """Return the dataclass the mapping ``value`` describes."""
        if not isinstance(value, dict):
            raise where.type_error('a mapping', value)
        return dataclass_from_mapping(self.cls, value, where)


# --- checked fields -----------------------------------------------------------

@dataclasses.dataclass(frozen=True, kw_only=True)
class FieldSpec:
    """
    What a dataclass field accepts: its kind of value and a further check.

    Attributes
    ----------
    kind : ValueKind
        The kind of value.
    check : callable, optional
        ``check(value, where)`` of a value of the right kind: returns the value
        to store, or raises ``where.error(...)``; for what the domain adds (a
        unit quaternion, a frame name without a leading /).
    name : str
        The field's key in a mapping; the attribute name unless set.
    attribute : str
        The dataclass attribute (set by :func:`field_specs`).
    required : bool
        The field has no default (set by :func:`field_specs`).

    """

    kind: ValueKind
    check: Optional[Callable[[Any, KeyPath], Any]] = None
    name: str = ''
    attribute: str = ''
    required: bool = False

    def checked(self, value: Any, where: KeyPath) -> Any:
        """Return the value to store, checked by the kind and then by ``check``."""
        value = self.kind.checked(value, where)
        return value if self.check is None else self.check(value, where)

    def field(self, default: Any = dataclasses.MISSING,
              default_factory: Any = dataclasses.MISSING) -> Any:
        """Return the ``dataclasses.field`` that carries this spec."""
        return dataclasses.field(default=default, default_factory=default_factory,
                                 metadata={_FIELD_SPEC: self})


def checked_field(kind: ValueKind, default: Any = dataclasses.MISSING, *,
                  check: Optional[Callable[[Any, KeyPath], Any]] = None,
                  default_factory: Any = dataclasses.MISSING) -> Any:
    """
    Return a dataclass field of ``kind``; required unless it has a default.

    Examples
    --------
    >>> @dataclasses.dataclass(frozen=True)
    ... class Noise:
    ...     std: float = checked_field(Real(0.0))
    >>> dataclass_from_mapping(Noise, {'std': 1}, KeyPath())
    Noise(std=1.0)

    """
    return FieldSpec(kind=kind, check=check).field(default, default_factory)


_FIELD_SPECS: dict[type, tuple[FieldSpec, ...]] = {}


def field_specs(cls: type) -> tuple[FieldSpec, ...]:
    """Return the specs of the dataclass ``cls``'s checked fields, in field order."""
    found = _FIELD_SPECS.get(cls)
    if found is None:
        found = _FIELD_SPECS[cls] = tuple(
            dataclasses.replace(
                f.metadata[_FIELD_SPEC], attribute=f.name,
                name=f.metadata[_FIELD_SPEC].name or f.name,
                required=f.default is dataclasses.MISSING
                and f.default_factory is dataclasses.MISSING)
            for f in dataclasses.fields(cls) if _FIELD_SPEC in f.metadata)
    return found


def checked_arguments(cls: type, data: Any, where: KeyPath, *, skip: Iterable[str] = (),
                      unknown: Optional[Callable[[str], Exception]] = None) -> dict[str, Any]:
    """
    Return ``{attribute: value}`` of the checked fields of ``cls`` found in the mapping ``data``.

    Parameters
    ----------
    cls : type
        A dataclass with fields made by :func:`checked_field`.
    data : Mapping or None
        The mapping (None: an empty one).
    where : KeyPath
        Where ``data`` sits.
    skip : iterable of str, optional
        Keys of ``data`` that are the caller's (a tag), neither checked nor unknown.
    unknown : callable, optional
        ``unknown(key)`` returns the error for a key no field has; by default
        ``'<path>.<key>: unknown key (did you mean ...); expected ...'``.

    Raises
    ------
    ValueError
        Of ``where``'s error type: for the first unknown key, else the first
        missing required key, else the first invalid value, in field order.
        Absent optional keys are left out (the dataclass has their defaults).

    """
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise where.type_error('a mapping', data)
    skip = tuple(skip)
    fields = {spec.name: spec for spec in field_specs(cls)}
    for key in data:
        if key not in fields and key not in skip:
            if unknown is not None:
                raise unknown(key)
            expected = [*skip, *fields]
            raise where.key(key).error(f'unknown key{did_you_mean(key, expected)}; '
                                       f'expected {", ".join(expected) or "no keys"}')
    for name, spec in fields.items():
        if spec.required and name not in data:
            raise where.key(name).error('missing')
    return {spec.attribute: spec.checked(data[name], where.key(name))
            for name, spec in fields.items() if name in data}


def dataclass_from_mapping(cls: type, data: Any, where: KeyPath, *,
                           skip: Iterable[str] = ()) -> Any:
    """Return the dataclass ``cls`` made from the mapping ``data`` (:func:`checked_arguments`)."""
    return cls(**checked_arguments(cls, data, where, skip=skip))


def check_fields_in_place(instance: Any, where: KeyPath) -> None:
    """
    Check every checked field of a frozen dataclass, storing the value in its stored form.

    For ``__post_init__`` of a dataclass that is valid by construction.
    """
    for spec in field_specs(type(instance)):
        value = getattr(instance, spec.attribute)
        object.__setattr__(instance, spec.attribute, spec.checked(value, where.key(spec.name)))
