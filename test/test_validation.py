"""Tests of rotation_node.validation: kinds of value, checked fields, the wording of errors."""
import dataclasses
import math
import re
from typing import Tuple

import pytest
from rotation_node.validation import (
    Boolean, check_fields_in_place, checked_arguments, checked_field, Choice, ChoiceList,
    dataclass_from_mapping, DataclassByTag, DataclassesByName, did_you_mean, field_specs, Integer,
    KeyPath, nearest_name, Real, short_repr, Text, type_and_repr, Vector)


class Problem(ValueError):
    """The error type of the tests' documents."""


TOP = KeyPath(error_type=Problem)


def problem(kind, value, where=TOP.key('x')):
    """Return the message of the error ``kind`` raises for ``value``."""
    with pytest.raises(Problem) as info:
        kind.checked(value, where)
    return str(info.value)


# Wording --------------------------------------------------------------------------

def test_a_long_value_is_shown_briefly_with_its_length():
    text = short_repr('x' * 1_000_000)
    assert len(text) < 100 and text.endswith('(1000002 characters)')
    assert type_and_repr([1] * 500) == 'list <500 items>'
    assert type_and_repr(3) == 'int 3'


def test_the_nearest_name_is_offered_only_when_near():
    assert nearest_name('duratoin', ['duration', 'rate']) == 'duration'
    assert did_you_mean('duratoin', ['duration', 'rate']) == " (did you mean 'duration'?)"
    assert did_you_mean('zzz', ['duration', 'rate']) == ''


def test_where_names_paths_with_its_template_and_raises_its_type():
    where = KeyPath(error_type=Problem, template="parameter '{}'")
    error = where.key('qos').key('depth').error('too deep')
    assert type(error) is Problem and str(error) == "parameter 'qos.depth': too deep"
    assert str(TOP.key('motion').key('orientation').index(2).error('no')) == \
        'motion.orientation[2]: no'


# Kinds ----------------------------------------------------------------------------

@pytest.mark.parametrize('value', [1, 0, 'true', None, 1.0])
def test_a_boolean_is_only_a_bool(value):
    assert problem(Boolean(), value) == f'x: expected a boolean, got {type_and_repr(value)}'


def test_a_boolean_is_stored_as_given():
    assert Boolean().checked(False, TOP) is False


@pytest.mark.parametrize('value', [True, 3.0, '3', None])
def test_an_integer_is_not_a_bool_float_or_string(value):
    assert problem(Integer(), value).startswith('x: expected an integer, got ')


@pytest.mark.parametrize('kind, value, words', [
    (Integer(1, 10), 0, 'from 1 to 10'), (Integer(1, 10), 11, 'from 1 to 10'),
    (Integer(1), -5, '>= 1'), (Integer(maximum=3), 4, '<= 3')])
def test_an_integer_out_of_range_names_the_range(kind, value, words):
    assert problem(kind, value) == f'x: must be {words}, got {value}'
    assert kind.constraints == words


def test_integer_range_ends_are_allowed():
    assert [Integer(1, 10).checked(v, TOP) for v in (1, 10)] == [1, 10]
    assert Integer(1, 10).bounds == (1, 10) and Integer(1).bounds is None


def test_a_real_accepts_integers_unless_it_is_a_ros_double():
    scene_real, ros_double = Real(), Real(integers=False)
    stored = scene_real.checked(3, TOP)
    assert stored == 3.0 and type(stored) is float
    assert problem(ros_double, 3) == \
        'x: expected a floating-point number (write 0.0, not 0), got int 3'
    assert problem(scene_real, True) == 'x: expected a number, got bool True'
    assert problem(ros_double, True).startswith('x: expected a floating-point number')


@pytest.mark.parametrize('value', [math.nan, math.inf, -math.inf, 10**400])
def test_a_real_must_be_finite(value):
    message = problem(Real(), value)
    assert message.startswith('x: must be finite, got ') and len(message) < 120


@pytest.mark.parametrize('kind, value, words', [
    (Real(0.0, math.pi), 4.0, 'from 0 to 3.14159'),
    (Real(0.0, math.pi), -0.1, 'from 0 to 3.14159'),
    (Real(0.0), -1e-3, '>= 0'), (Real(maximum=2.0), 2.5, '<= 2'), (Real(positive=True), 0, '> 0'),
    (Real(positive=True), -1.0, '> 0')])
def test_a_real_out_of_range_names_the_range(kind, value, words):
    assert problem(kind, value) == f'x: must be {words}, got {float(value)!r}'
    assert kind.constraints == words


def test_real_range_ends_are_allowed_and_bounds_are_what_a_descriptor_takes():
    kind = Real(0.0, 1.0, integers=False)
    assert [kind.checked(v, TOP) for v in (0.0, 1.0)] == [0.0, 1.0]
    assert kind.bounds == (0.0, 1.0) and Real(0.0).bounds is None and Real().constraints == ''


def test_text_checks_type_pattern_and_parser():
    topic = Text('a topic such as /imu', re.compile(r'/[a-z]+'))
    assert topic.checked('/imu', TOP) == '/imu'
    assert problem(topic, 'imu') == "x: expected a topic such as /imu, got str 'imu'"
    assert problem(Text(), 3) == 'x: expected a string, got int 3'

    def even_length(text):
        if len(text) % 2:
            raise ValueError(f'{len(text)} characters')
    pair = Text('a pair', parser=even_length)
    assert pair.checked('ab', TOP) == 'ab'
    assert problem(pair, 'abc') == "x: 'abc' is not a pair (3 characters)"


def test_a_choice_names_the_nearest_choice():
    kind = Choice(('enu', 'ned'))
    assert kind.checked('ned', TOP) == 'ned'
    assert problem(kind, 'nde') == \
        "x: 'nde' is not allowed (did you mean 'ned'?); one of: enu, ned"
    assert problem(kind, 1) == 'x: expected a string, got int 1'
    assert kind.constraints == 'one of: enu, ned' and kind.choices == ('enu', 'ned')


@pytest.mark.parametrize('value, message', [
    ([], 'x: list at least one output; choose from euler, matrix'),
    (None, 'x: list at least one output; choose from euler, matrix'),
    ('euler', "x: expected a list of strings, got str 'euler'"),
    (['euler', 3], 'x: expected a list of strings, got list '),
    (['euler', 'eulr'], "x: 'eulr' is not allowed (did you mean 'euler'?); each one of: euler"),
    (['matrix', 'euler', 'matrix', 'euler'], 'x: euler, matrix listed twice'),
])
def test_a_choice_list_is_non_empty_distinct_and_from_the_choices(value, message):
    assert problem(ChoiceList(('euler', 'matrix'), item='output'), value).startswith(message)


def test_a_choice_list_is_stored_as_a_tuple_in_order():
    assert ChoiceList(('a', 'b')).checked(['b', 'a'], TOP) == ('b', 'a')


def test_a_vector_names_the_bad_component():
    kind = Vector(3)
    stored = kind.checked([1, 2.5, -3], TOP)
    assert stored == (1.0, 2.5, -3.0) and all(type(c) is float for c in stored)
    assert problem(kind, [1, 2]) == 'x: expected a list of 3 numbers, got list [1, 2]'
    assert problem(kind, 0.5) == 'x: expected a list of 3 numbers, got float 0.5'
    assert problem(kind, [1, 'a', 3]) == "x[1]: expected a number, got str 'a'"
    assert problem(kind, [1, 2, math.nan]).startswith('x[2]: must be finite')


# Declared fields ------------------------------------------------------------------

def _positive_pair(pair, where):
    if pair[0] > pair[1]:
        raise where.error(f'expected low <= high, got {list(pair)}')
    return pair


@dataclasses.dataclass(frozen=True)
class Noise:
    std: float = checked_field(Real(0.0))


@dataclasses.dataclass(frozen=True)
class Bias:
    constant: Tuple[float, ...] = checked_field(Vector(3), (0.0, 0.0, 0.0))
    band: Tuple[float, ...] = checked_field(Vector(2), (0.0, 1.0), check=_positive_pair)


@dataclasses.dataclass(frozen=True)
class Spin:
    kind = 'spin'
    rate: float = checked_field(Real())
    axis: Tuple[float, ...] = checked_field(Vector(3))


@dataclasses.dataclass(frozen=True)
class Rest:
    kind = 'rest'


@dataclasses.dataclass(frozen=True)
class Document:
    duration: float = checked_field(Real(positive=True))
    motion: object = checked_field(DataclassByTag({'spin': Spin, 'rest': Rest}, 'motion'))
    effects: dict = checked_field(DataclassesByName({'noise': Noise, 'bias': Bias}, 'effect'),
                                  default_factory=dict)
    frame: str = checked_field(Choice(('enu', 'ned')), 'enu')


def test_declarations_list_the_fields_in_order_with_their_names():
    found = field_specs(Document)
    assert [d.attribute for d in found] == ['duration', 'motion', 'effects', 'frame']
    assert [d.name for d in found] == ['duration', 'motion', 'effects', 'frame']
    assert [d.required for d in found] == [True, True, False, False]


def test_a_document_is_built_with_defaults_and_stored_forms():
    document = dataclass_from_mapping(
        Document, {'duration': 2, 'motion': {'type': 'spin', 'rate': 1, 'axis': [0, 0, 1]},
                   'effects': {'noise': {'std': 0}, 'bias': None}}, TOP)
    assert document == Document(duration=2.0, motion=Spin(rate=1.0, axis=(0.0, 0.0, 1.0)),
                                effects={'noise': Noise(std=0.0), 'bias': Bias()}, frame='enu')
    rest = {'duration': 1.0, 'motion': {'type': 'rest'}}
    assert dataclass_from_mapping(Document, rest, TOP).effects == {}


GOOD = {'duration': 1.0, 'motion': {'type': 'spin', 'rate': 1.0, 'axis': [0, 0, 1]}}


def changed(**changes):
    return {**GOOD, **changes}


@pytest.mark.parametrize('data, message', [
    (changed(durration=1.0), "durration: unknown key (did you mean 'duration'?); expected "
                             'duration, motion, effects, frame'),
    ({'duration': 1.0}, 'motion: missing'),
    (changed(duration=0), 'duration: must be > 0, got 0.0'),
    (changed(frame='enuu'),
     "frame: 'enuu' is not allowed (did you mean 'enu'?); one of: enu, ned"),
    (changed(motion='spin'), "motion: expected a mapping with a type, got str 'spin'"),
    (changed(motion={'rate': 1.0}), 'motion.type: missing; expected one of spin, rest'),
    (changed(motion={'type': 'spn'}),
     "motion.type: unknown motion 'spn' (did you mean 'spin'?); expected one of spin, rest"),
    (changed(motion={'type': 3}), 'motion.type: unknown motion 3; expected one of spin, rest'),
    (changed(motion={'type': 'rest', 'rate': 1.0}), 'motion.rate: unknown key; expected type'),
    (changed(motion={'type': 'spin', 'rate': 1.0}), 'motion.axis: missing'),
    (changed(motion={'type': 'spin', 'rate': 1.0, 'axis': [0, 'z', 1]}),
     "motion.axis[1]: expected a number, got str 'z'"),
    (changed(effects=['noise']), 'effects: expected a mapping of effect names, got list'),
    (changed(effects={'nois': {}}),
     "effects.nois: unknown effect (did you mean 'noise'?); expected one of noise, bias"),
    (changed(effects={'noise': {}}), 'effects.noise.std: missing'),
    (changed(effects={'noise': 0.1}), 'effects.noise: expected a mapping, got float 0.1'),
    (changed(effects={'bias': {'band': [2, 1]}}),
     'effects.bias.band: expected low <= high, got [2.0, 1.0]'),
])
def test_errors_name_the_path_of_the_value(data, message):
    with pytest.raises(Problem) as info:
        dataclass_from_mapping(Document, data, TOP)
    assert str(info.value).startswith(message), str(info.value)


def test_unknown_keys_come_before_missing_ones_and_those_before_bad_values():
    with pytest.raises(Problem, match='^speed: unknown key'):
        dataclass_from_mapping(Document, {'duration': -1.0, 'speed': 1}, TOP)
    with pytest.raises(Problem, match='^motion: missing'):
        dataclass_from_mapping(Document, {'duration': -1.0}, TOP)


def test_only_the_values_present_are_returned_and_skipped_keys_are_the_callers():
    assert checked_arguments(Bias, {'constant': [1, 2, 3], 'id': 7}, TOP, skip=('id',)) == {
        'constant': (1.0, 2.0, 3.0)}
    assert checked_arguments(Bias, None, TOP) == {}


def test_the_caller_may_word_an_unknown_key():
    with pytest.raises(KeyError, match='no such thing: std2'):
        checked_arguments(Noise, {'std2': 1.0}, TOP,
                          unknown=lambda key: KeyError(f'no such thing: {key}'))


@dataclasses.dataclass(frozen=True)
class Settings:
    depth: int = checked_field(Integer(1, 100), 10)
    names: tuple = checked_field(ChoiceList(('a', 'b')), ('a',))

    def __post_init__(self):
        check_fields_in_place(self, KeyPath(error_type=Problem, template="setting '{}'"))


def test_check_fields_validates_on_construction_and_stores_the_stored_form():
    assert Settings(names=['b', 'a']).names == ('b', 'a')
    with pytest.raises(Problem, match=r"^setting 'depth': must be from 1 to 100, got 0$"):
        Settings(depth=0)
