"""
The checks of node parameters and scene files: dataclass fields of a kind of value.

A :func:`checked_field` has a kind (:class:`Real`, :class:`Choice`, a nested
dataclass...) and optionally a ``check(value, where)`` returning the value to
store. :func:`checked_arguments` checks a mapping: unknown keys first (with the
nearest valid name), then missing keys, then each value. Errors are the
:class:`KeyPath`'s type, naming the value's path and showing a bounded repr.
"""
from __future__ import annotations

from collections.abc import Mapping
import dataclasses
import math
import re
from typing import Any, Callable, Iterable, Optional

_MAX_REPR = 80
_FIELD_SPEC = 'rotation_node.validation'   # the dataclass field metadata key


def short_repr(value: Any) -> str:
    """Return the repr of a value, cut to a readable length (with the full length)."""
    text = repr(value) if not isinstance(value, (list, dict, tuple)) or len(value) < 100 \
        else f'<{len(value)} items>'
    if len(text) > _MAX_REPR:
        text = f'{text[:_MAX_REPR - 20]}...{text[-12:]} ({len(text)} characters)'
    return text


def type_and_repr(value: Any) -> str:
    """Return ``'<type> <repr>'`` of a value, the repr cut to a readable length."""
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
    The path of a value in its document (``'motion.orientation[2]'``), and the errors naming it.

    ``template`` names the path in messages (``"parameter '{}'"``).
    """

    path: str = ''
    error_type: type[ValueError] = ValueError
    template: str = '{}'

    def key(self, key: Any) -> KeyPath:
        """Return the path of the value of ``key`` of this mapping."""
        return dataclasses.replace(self, path=f'{self.path}.{key}' if self.path else str(key))

    def index(self, index: int) -> KeyPath:
        """Return the path of the item ``index`` of this list."""
        return dataclasses.replace(self, path=f'{self.path}[{index}]')

    def error(self, problem: str) -> ValueError:
        """Return the error ``'<path as the template names it>: <problem>'`` (to raise)."""
        return self.error_type(f'{self.template.format(self.path)}: {problem}')

    def type_error(self, expected: str, value: Any) -> ValueError:
        """Return the error ``'<path>: expected <expected>, got <type> <repr>'``."""
        return self.error(f'expected {expected}, got {type_and_repr(value)}')


# --- kinds of value: checked(value, where) returns the value in its stored form ------

class ValueKind:
    """A kind of value; ``constraints`` says its allowed values in words."""

    constraints = ''

    def checked(self, value: Any, where: KeyPath) -> Any:
        """Return ``value`` in its stored form, or raise ``where``'s error naming the problem."""
        raise NotImplementedError


@dataclasses.dataclass(frozen=True)
class Boolean(ValueKind):
    """``true`` or ``false``; no number or string stands for one."""

    def checked(self, value: Any, where: KeyPath) -> bool:
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
        """Return ``(minimum, maximum)`` if both are set (a ROS descriptor's range), else None."""
        return None if self.minimum is None or self.maximum is None \
            else (self.minimum, self.maximum)

    @property
    def constraints(self) -> str:  # type: ignore[override]
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
    """An integer within the bounds; ``3.0`` and ``true`` are not integers."""

    def checked(self, value: Any, where: KeyPath) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise where.type_error('an integer', value)
        return self._in_range(value, where)


@dataclasses.dataclass(frozen=True)
class Real(_Range):
    """
    A finite number within the bounds, stored as float; a bool is never a number.

    ``integers=False``: a ROS double, where ``0`` is refused (a scene takes ``100``).
    """

    integers: bool = dataclasses.field(default=True, kw_only=True)

    def checked(self, value: Any, where: KeyPath) -> float:
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
    A string: any, one matching ``pattern``, or one ``parser`` accepts (else ValueError).

    ``noun`` says what the string is in messages (``'an absolute topic name such as /imu'``).
    """

    noun: str = 'a string'
    pattern: Optional[re.Pattern] = None
    parser: Optional[Callable[[str], Any]] = None

    def checked(self, value: Any, where: KeyPath) -> str:
        if not isinstance(value, str) or self.pattern and not self.pattern.fullmatch(value):
            raise where.type_error(self.noun, value)
        if self.parser is not None:
            try:
                self.parser(value)
            except ValueError as exc:
                raise where.error(f'{short_repr(value)} is not {self.noun} ({exc})') from None
        return value


def _check_choice(item: Any, choices: tuple, words: str, where: KeyPath) -> None:
    if item not in choices:
        raise where.error(
            f'{short_repr(item)} is not allowed{did_you_mean(item, choices)}; {words}')


@dataclasses.dataclass(frozen=True)
class Choice(ValueKind):
    """One string of ``choices``."""

    choices: tuple = ()

    @property
    def constraints(self) -> str:  # type: ignore[override]
        return f'one of: {", ".join(self.choices)}'

    def checked(self, value: Any, where: KeyPath) -> str:
        if not isinstance(value, str):
            raise where.type_error('a string', value)
        _check_choice(value, self.choices, self.constraints, where)
        return value


@dataclasses.dataclass(frozen=True)
class ChoiceList(ValueKind):
    """
    A non-empty list of distinct strings of ``choices``, stored as a tuple in the given order.

    None is an empty list (ROS gives ``outputs: []`` as no value); ``item`` names an entry.
    """

    choices: tuple = ()
    item: str = 'entry'

    @property
    def constraints(self) -> str:  # type: ignore[override]
        return f'each one of: {", ".join(self.choices)}'

    def checked(self, value: Any, where: KeyPath) -> tuple:
        value = () if value is None else value
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise where.type_error('a list of strings', value)
        if not value:
            raise where.error(f'list at least one {self.item}; '
                              f'choose from {", ".join(self.choices)}')
        for item in value:
            _check_choice(item, self.choices, self.constraints, where)
        repeated = sorted({item for item in value if value.count(item) > 1})
        if repeated:
            raise where.error(f'{", ".join(repeated)} listed twice')
        return tuple(value)


@dataclasses.dataclass(frozen=True)
class Vector(ValueKind):
    """A list of ``size`` finite numbers (integers allowed), stored as a tuple of float."""

    size: int

    def checked(self, value: Any, where: KeyPath) -> tuple:
        if not isinstance(value, (list, tuple)) or len(value) != self.size:
            raise where.type_error(f'a list of {self.size} numbers', value)
        return tuple(Real().checked(x, where.index(i)) for i, x in enumerate(value))


@dataclasses.dataclass(frozen=True)
class Reals(ValueKind):
    """A ROS double array (any sequence but a string or mapping) of one of ``sizes``; a tuple."""

    sizes: tuple = (3,)

    def checked(self, value: Any, where: KeyPath) -> tuple:
        expected = f'a list of {" or ".join(map(str, self.sizes))} numbers'
        if isinstance(value, (str, bytes, dict)) or not isinstance(value, Iterable):
            raise where.type_error(expected, value)
        items = list(value)
        if len(items) not in self.sizes:
            raise where.error(f'expected {expected}, got {len(items)}')
        double = Real(integers=False)
        return tuple(double.checked(x, where.index(i)) for i, x in enumerate(items))


@dataclasses.dataclass(frozen=True)
class DataclassByTag(ValueKind):
    """A mapping that is the dataclass ``classes[value['type']]``; ``noun`` names the tags."""

    classes: Mapping[str, type]
    noun: str

    def checked(self, value: Any, where: KeyPath) -> Any:
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
    """A mapping of names of ``classes`` to mappings of their dataclass (None: none); a dict."""

    classes: Mapping[str, type]
    noun: str

    def checked(self, value: Any, where: KeyPath) -> dict:
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
    """A mapping that is the dataclass ``cls``."""

    cls: type

    def checked(self, value: Any, where: KeyPath) -> Any:
        if not isinstance(value, dict):
            raise where.type_error('a mapping', value)
        return dataclass_from_mapping(self.cls, value, where)


@dataclasses.dataclass(frozen=True, kw_only=True)
class FieldSpec:
    """
    What a dataclass field accepts: its ``kind`` of value and a further ``check``.

    ``name``: its key (the attribute's unless set); :func:`field_specs` sets the rest.
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
    """Return a dataclass field of ``kind``; required unless it has a default."""
    return FieldSpec(kind=kind, check=check).field(default, default_factory)


_FIELD_SPECS: dict[type, tuple[FieldSpec, ...]] = {}


def field_specs(cls: type) -> tuple[FieldSpec, ...]:
    """Return the specs of the dataclass ``cls``'s checked fields, in field order."""
    if cls not in _FIELD_SPECS:
        _FIELD_SPECS[cls] = tuple(
            dataclasses.replace(
                f.metadata[_FIELD_SPEC], attribute=f.name,
                name=f.metadata[_FIELD_SPEC].name or f.name,
                required=f.default is dataclasses.MISSING
                and f.default_factory is dataclasses.MISSING)
            for f in dataclasses.fields(cls) if _FIELD_SPEC in f.metadata)
    return _FIELD_SPECS[cls]


def checked_arguments(cls: type, data: Any, where: KeyPath, *, skip: Iterable[str] = (),
                      unknown: Optional[Callable[[str], Exception]] = None) -> dict[str, Any]:
    """
    Return ``{attribute: value}`` of the checked fields of ``cls`` found in the mapping ``data``.

    None is an empty mapping; keys in ``skip`` are the caller's (a tag). Raises for
    the first unknown key (``unknown(key)`` if given), missing key, or invalid value.
    """
    data = {} if data is None else data
    if not isinstance(data, Mapping):
        raise where.type_error('a mapping', data)
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
    """Check every checked field of a frozen dataclass (in ``__post_init__``); store its form."""
    for spec in field_specs(type(instance)):
        value = getattr(instance, spec.attribute)
        object.__setattr__(instance, spec.attribute, spec.checked(value, where.key(spec.name)))
