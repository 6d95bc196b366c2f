"""
The one validation helper of node parameters and scene files.

A dataclass declares each field with :func:`declare`: the field's :class:`Kind`
(a boolean, an integer or a real number within bounds, a string, one of some
choices, a list of choices, a fixed-size vector, one of several dataclasses
chosen by a tag, named sections...) and, where the domain asks for more (a
unit quaternion, a frame name without a leading /), a further check. :func:`checked_values`
then checks a mapping (a parsed YAML file, ROS parameters) against those
declarations: unknown keys first, with the nearest valid name (``difflib``),
then missing required keys, then each value by its kind, so a misspelt key
reads as what it is.

Each problem raises the error type of a :class:`Where`, and its message starts
with the value's path as the :class:`Where` names it (``motion.half_angle``,
``parameter 'qos.depth'``). Values are described by type and a bounded repr: a
megabyte-long string is not copied into a log line.
"""
from __future__ import annotations

from collections.abc import Mapping
import dataclasses
import difflib
import math
import re
from typing import Any, Callable, ClassVar, Iterable, Optional

_MAX_REPR = 80


# --- wording ------------------------------------------------------------------

def shown(value: Any) -> str:
    """
    Return the repr of a value, cut to a readable length.

    Examples
    --------
    >>> shown('x' * 100)[:10]
    "'xxxxxxxxx"

    """
    text = repr(value) if not isinstance(value, (list, dict, tuple)) or len(value) < 100 \
        else f'<{len(value)} items>'
    if len(text) > _MAX_REPR:
        text = f'{text[:_MAX_REPR - 20]}...{text[-12:]} ({len(text)} characters)'
    return text


def describe_value(value: Any) -> str:
    """
    Return ``'<type> <repr>'`` of a value, the repr cut to a readable length.

    Examples
    --------
    >>> describe_value('x' * 100)[:12]
    "str 'xxxxxxx"

    """
    return f'{type(value).__name__} {shown(value)}'


def nearest_name(name: Any, names: Iterable[str]) -> str:
    """Return the valid name nearest to ``name`` (``difflib``), or '' if none is near."""
    matches = difflib.get_close_matches(str(name), list(names), n=1, cutoff=0.6)
    return matches[0] if matches else ''


def did_you_mean(name: Any, names: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the nearest valid name, or ''."""
    nearest = nearest_name(name, names)
    return f' (did you mean {nearest!r}?)' if nearest else ''


@dataclasses.dataclass(frozen=True)
class Where:
    """
    Where a value sits: how error messages name it, and the error they raise.

    Attributes
    ----------
    path : str
        Key path from the top of the document: ``'motion.orientation[2]'``;
        ``''`` is the top.
    error_type : type of ValueError
        The error :meth:`error` returns.
    template : str
        How a message names the path: ``'{}'`` gives ``motion.half_angle:
        ...``, ``"parameter '{}'"`` gives ``parameter 'qos.depth': ...``.

    """

    path: str = ''
    error_type: type[ValueError] = ValueError
    template: str = '{}'

    @property
    def label(self) -> str:
        """Return the name of the value in messages."""
        return self.template.format(self.path)

    def key(self, key: Any) -> 'Where':
        """Return where the value of ``key`` of this mapping sits."""
        return dataclasses.replace(self, path=f'{self.path}.{key}' if self.path else str(key))

    def index(self, index: int) -> 'Where':
        """Return where the item ``index`` of this list sits."""
        return dataclasses.replace(self, path=f'{self.path}[{index}]')

    def error(self, problem: str) -> ValueError:
        """Return the error ``'<label>: <problem>'`` (to raise)."""
        return self.error_type(f'{self.label}: {problem}')

    def type_error(self, expected: str, value: Any) -> ValueError:
        """Return the error ``'<label>: expected <expected>, got <type> <repr>'``."""
        return self.error(f'expected {expected}, got {describe_value(value)}')


# --- kinds of value -----------------------------------------------------------

class Kind:
    """
    A kind of value: how a value of it is checked, and its constraints in words.

    Subclasses define :meth:`checked`. A kind with a range has ``bounds``,
    one of strings ``choices`` (what a ROS parameter descriptor can carry).
    """

    def checked(self, value: Any, where: Where) -> Any:
        """Return ``value`` in its stored form, or raise ``where``'s error naming the problem."""
        raise NotImplementedError

    @property
    def constraints(self) -> str:
        """Return the allowed values in words beyond the type ('' if the type says all)."""
        return ''


@dataclasses.dataclass(frozen=True)
class Boolean(Kind):
    """``true`` or ``false``; no number or string stands for one."""

    def checked(self, value: Any, where: Where) -> bool:
        """Return ``value`` if it is a bool."""
        if not isinstance(value, bool):
            raise where.type_error('a boolean', value)
        return value


def _range_words(minimum: Optional[float], maximum: Optional[float], positive: bool) -> str:
    if positive:
        return '> 0'
    if minimum is not None and maximum is not None:
        return f'from {minimum:g} to {maximum:g}'
    if minimum is not None:
        return f'>= {minimum:g}'
    return '' if maximum is None else f'<= {maximum:g}'


def _in_range(number: Any, minimum: Any, maximum: Any, positive: bool, where: Where) -> Any:
    """Return ``number`` if it is within the bounds, else raise ``where``'s error."""
    if (positive and not number > 0 or minimum is not None and number < minimum
            or maximum is not None and number > maximum):
        raise where.error(f'must be {_range_words(minimum, maximum, positive)}, '
                          f'got {shown(number)}')
    return number


def _bounds(minimum: Any, maximum: Any) -> Optional[tuple]:
    return None if minimum is None or maximum is None else (minimum, maximum)


@dataclasses.dataclass(frozen=True)
class Integer(Kind):
    """
    An integer in ``[minimum, maximum]`` (either bound optional).

    ``3.0`` and ``true`` are not integers.
    """

    minimum: Optional[int] = None
    maximum: Optional[int] = None

    @property
    def bounds(self) -> Optional[tuple]:
        """Return ``(minimum, maximum)`` when both are set, else None."""
        return _bounds(self.minimum, self.maximum)

    @property
    def constraints(self) -> str:
        """Return the range in words."""
        return _range_words(self.minimum, self.maximum, False)

    def checked(self, value: Any, where: Where) -> int:
        """Return ``value`` if it is an int within the bounds."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise where.type_error('an integer', value)
        return _in_range(value, self.minimum, self.maximum, False, where)


@dataclasses.dataclass(frozen=True)
class Real(Kind):
    """
    A finite real number in ``[minimum, maximum]`` (either bound optional), stored as float.

    Attributes
    ----------
    minimum, maximum : float, optional
        Inclusive bounds.
    positive : bool
        The number must be > 0 (then without ``minimum``).
    integers : bool
        An integer stands for the real number (``rate: 100``), as in scene
        files. A ROS double parameter takes no integer (``0`` is refused where
        ``0.0`` is meant): ``integers=False``. A bool is never a number.

    """

    minimum: Optional[float] = None
    maximum: Optional[float] = None
    positive: bool = False
    integers: bool = True

    @property
    def bounds(self) -> Optional[tuple]:
        """Return ``(minimum, maximum)`` when both are set, else None."""
        return _bounds(self.minimum, self.maximum)

    @property
    def constraints(self) -> str:
        """Return the range in words."""
        return _range_words(self.minimum, self.maximum, self.positive)

    def checked(self, value: Any, where: Where) -> float:
        """Return ``value`` as a float if it is a finite number within the bounds."""
        if isinstance(value, bool) or not isinstance(value, (int, float) if self.integers
                                                     else float):
            raise where.type_error('a number' if self.integers else
                                   'a floating-point number (write 0.0, not 0)', value)
        try:
            number = float(value)
        except OverflowError:   # an integer beyond the float range
            number = math.inf
        if not math.isfinite(number):
            raise where.error(f'must be finite, got {shown(value)}')
        return _in_range(number, self.minimum, self.maximum, self.positive, where)


@dataclasses.dataclass(frozen=True)
class Text(Kind):
    """
    A string: any, one matching ``pattern``, or one ``parser`` accepts.

    Attributes
    ----------
    noun : str
        What the string is, in messages: ``'an absolute topic name such as /imu'``.
    pattern : re.Pattern, optional
        The whole string must match it.
    parser : callable, optional
        ``parser(value)`` raises ValueError, saying why, for a string that is
        not valid (e.g. :func:`rotation_node.conversions.parse_sequence`).

    """

    noun: str = 'a string'
    pattern: Optional[re.Pattern] = None
    parser: Optional[Callable[[str], Any]] = None

    def checked(self, value: Any, where: Where) -> str:
        """Return ``value`` if it is a string that matches and parses."""
        if not isinstance(value, str) or self.pattern and not self.pattern.fullmatch(value):
            raise where.type_error(self.noun, value)
        if self.parser is not None:
            try:
                self.parser(value)
            except ValueError as exc:
                raise where.error(f'{shown(value)} is not {self.noun} ({exc})') from None
        return value


def _not_allowed(item: Any, choices: tuple, words: str, where: Where) -> ValueError:
    return where.error(f'{shown(item)} is not allowed{did_you_mean(item, choices)}; {words}')


@dataclasses.dataclass(frozen=True)
class Choice(Kind):
    """One string of ``choices``."""

    choices: tuple = ()

    @property
    def constraints(self) -> str:
        """Return ``'one of: a, b'``."""
        return f'one of: {", ".join(self.choices)}'

    def checked(self, value: Any, where: Where) -> str:
        """Return ``value`` if it is one of the choices."""
        if not isinstance(value, str):
            raise where.type_error('a string', value)
        if value not in self.choices:
            raise _not_allowed(value, self.choices, self.constraints, where)
        return value


@dataclasses.dataclass(frozen=True)
class ChoiceList(Kind):
    """
    A non-empty list of distinct strings of ``choices``, stored as a tuple in the given order.

    ``item`` names an entry in messages (``'list at least one output'``). A
    missing value (``None``) is an empty list: ROS gives ``outputs: []`` of a
    parameters file as no value.
    """

    choices: tuple = ()
    item: str = 'entry'

    @property
    def constraints(self) -> str:
        """Return ``'each one of: a, b'``."""
        return f'each one of: {", ".join(self.choices)}'

    def checked(self, value: Any, where: Where) -> tuple:
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
class Vector(Kind):
    """A list of ``size`` finite numbers, stored as a tuple of float."""

    size: int

    def checked(self, value: Any, where: Where) -> tuple:
        """Return ``value`` as a tuple of float if it is a list of ``size`` finite numbers."""
        if not isinstance(value, (list, tuple)) or len(value) != self.size:
            raise where.type_error(f'a list of {self.size} numbers', value)
        return tuple(_NUMBER.checked(x, where.index(i)) for i, x in enumerate(value))


@dataclasses.dataclass(frozen=True)
class Reals(Kind):
    """
    A list of finite real numbers, as many as one of ``sizes``, stored as a tuple of float.

    ``integers=False``: each must be a float, as in a ROS double array.
    """

    sizes: tuple = (3,)
    integers: bool = True

    def checked(self, value: Any, where: Where) -> tuple:
        """Return ``value`` as a tuple of float if it is a list of finite numbers of a size."""
        number = Real(integers=self.integers)
        expected = f'a list of {" or ".join(map(str, self.sizes))} numbers'
        if isinstance(value, (str, bytes, dict)) or not isinstance(value, Iterable):
            raise where.type_error(expected, value)
        items = list(value)
        if len(items) not in self.sizes:
            raise where.error(f'expected {expected}, got {len(items)}')
        return tuple(number.checked(x, where.index(i)) for i, x in enumerate(items))


@dataclasses.dataclass(frozen=True)
class Tagged(Kind):
    """
    A mapping that is one of several dataclasses, chosen by the value of its key ``tag``.

    ``classes`` maps each tag value to its dataclass; ``noun`` names them in
    messages (``unknown motion 'wobble'``).
    """

    classes: Mapping[str, type]
    noun: str
    tag: str = 'type'

    def checked(self, value: Any, where: Where) -> Any:
        """Return the dataclass the mapping ``value`` describes."""
        if not isinstance(value, dict):
            raise where.type_error(f'a mapping with a {self.tag}', value)
        expected = f'expected one of {", ".join(self.classes)}'
        if self.tag not in value:
            raise where.key(self.tag).error(f'missing; {expected}')
        name = value[self.tag]
        if not isinstance(name, str) or name not in self.classes:
            raise where.key(self.tag).error(
                f'unknown {self.noun} {shown(name)}{did_you_mean(name, self.classes)}; '
                f'{expected}')
        return built(self.classes[name], value, where, skip=(self.tag,))


@dataclasses.dataclass(frozen=True)
class Sections(Kind):
    """
    A mapping of names of ``classes`` to mappings of their dataclass; stored as a dict.

    A missing value (``None``) is no section; ``noun`` names a section in
    messages (``unknown effect``).
    """

    classes: Mapping[str, type]
    noun: str

    def checked(self, value: Any, where: Where) -> dict:
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
        return {name: built(self.classes[name], fields, where.key(name))
                for name, fields in value.items()}


@dataclasses.dataclass(frozen=True)
class Section(Kind):
    """A mapping that is one dataclass ``cls``, its keys checked as :func:`built` checks them."""

    cls: type

    def checked(self, value: Any, where: Where) -> Any:
        """Return the dataclass the mapping ``value`` describes."""
        if not isinstance(value, dict):
            raise where.type_error('a mapping', value)
        return built(self.cls, value, where)


# --- declared fields ----------------------------------------------------------

@dataclasses.dataclass(frozen=True, kw_only=True)
class Declaration:
    """
    What a dataclass field accepts: its kind and a further check.

    Attributes
    ----------
    kind : Kind
        The kind of value.
    check : callable, optional
        ``check(value, where)`` of a value of the right kind: returns the value
        to store, or raises ``where.error(...)``; for what the domain adds (a
        unit quaternion, a frame name without a leading /).
    name : str
        The field's key in a mapping; the attribute name unless set.
    attribute : str
        The dataclass attribute (set by :func:`declarations`).
    required : bool
        The field has no default (set by :func:`declarations`).

    """

    _METADATA: ClassVar[str] = 'rotation_node.validation'

    kind: Kind
    check: Optional[Callable[[Any, Where], Any]] = None
    name: str = ''
    attribute: str = ''
    required: bool = False

    def checked(self, value: Any, where: Where) -> Any:
        """Return the value to store, checked by the kind and then by ``check``."""
        value = self.kind.checked(value, where)
        return value if self.check is None else self.check(value, where)

    def field(self, default: Any = dataclasses.MISSING,
              default_factory: Any = dataclasses.MISSING) -> Any:
        """Return the ``dataclasses.field`` that carries this declaration."""
        return dataclasses.field(default=default, default_factory=default_factory,
                                 metadata={self._METADATA: self})


def declare(kind: Kind, default: Any = dataclasses.MISSING, *,
            check: Optional[Callable[[Any, Where], Any]] = None,
            default_factory: Any = dataclasses.MISSING) -> Any:
    """
    Return a dataclass field of ``kind``; required unless it has a default.

    Examples
    --------
    >>> @dataclasses.dataclass(frozen=True)
    ... class Noise:
    ...     std: float = declare(Real(0.0))
    >>> built(Noise, {'std': 1}, Where())
    Noise(std=1.0)

    """
    return Declaration(kind=kind, check=check).field(default, default_factory)


_DECLARATIONS: dict[type, tuple[Declaration, ...]] = {}


def declarations(cls: type) -> tuple[Declaration, ...]:
    """Return the declarations of the dataclass ``cls``'s declared fields, in field order."""
    found = _DECLARATIONS.get(cls)
    if found is None:
        found = _DECLARATIONS[cls] = tuple(
            dataclasses.replace(
                f.metadata[Declaration._METADATA], attribute=f.name,
                name=f.metadata[Declaration._METADATA].name or f.name,
                required=f.default is dataclasses.MISSING
                and f.default_factory is dataclasses.MISSING)
            for f in dataclasses.fields(cls) if Declaration._METADATA in f.metadata)
    return found


def checked_values(cls: type, data: Any, where: Where, *, skip: Iterable[str] = (),
                   unknown: Optional[Callable[[str], Exception]] = None) -> dict[str, Any]:
    """
    Return ``{attribute: value}`` of the declared fields of ``cls`` found in the mapping ``data``.

    Parameters
    ----------
    cls : type
        A dataclass with fields made by :func:`declare`.
    data : Mapping or None
        The mapping (None: an empty one).
    where : Where
        Where ``data`` sits.
    skip : iterable of str, optional
        Keys of ``data`` that are the caller's (a tag), neither checked nor unknown.
    unknown : callable, optional
        ``unknown(key)`` returns the error for a key no field declares; by
        default ``'<path>.<key>: unknown key (did you mean ...); expected ...'``.

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
    fields = {declaration.name: declaration for declaration in declarations(cls)}
    for key in data:
        if key not in fields and key not in skip:
            if unknown is not None:
                raise unknown(key)
            expected = [*skip, *fields]
            raise where.key(key).error(f'unknown key{did_you_mean(key, expected)}; '
                                       f'expected {", ".join(expected) or "no keys"}')
    for name, declaration in fields.items():
        if declaration.required and name not in data:
            raise where.key(name).error('missing')
    return {declaration.attribute: declaration.checked(data[name], where.key(name))
            for name, declaration in fields.items() if name in data}


def built(cls: type, data: Any, where: Where, *, skip: Iterable[str] = ()) -> Any:
    """Return the dataclass ``cls`` built from the mapping ``data`` (:func:`checked_values`)."""
    return cls(**checked_values(cls, data, where, skip=skip))


def check_fields(instance: Any, where: Where) -> None:
    """
    Check every declared field of a frozen dataclass, storing the value in its stored form.

    For ``__post_init__`` of a dataclass that is valid by construction.
    """
    for declaration in declarations(type(instance)):
        value = getattr(instance, declaration.attribute)
        object.__setattr__(instance, declaration.attribute,
                           declaration.checked(value, where.key(declaration.name)))
