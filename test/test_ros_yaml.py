"""
Tests of rotation_node.ros_yaml: the one YAML loader of parameters files and scenes.

Scalars are checked against the C library's ``strtol``/``strtod`` (through
ctypes), which is what rcl_yaml_param_parser calls; the bounds against an
alias bomb, an oversized and an over-deep file; and parameters files and scenes
against each other (the same text means the same in both).
"""
import ctypes
import ctypes.util
import math
import time

from hypothesis import given, settings
from hypothesis import strategies as st
import pytest
from rotation_node.errors import ParameterError, SceneError
from rotation_node.parameters import parameters_from_yaml
from rotation_node.ros_yaml import load_ros_yaml, MAX_DEPTH, MAX_FILE_BYTES, MAX_NODES, ros_scalar
from rotation_node.scene.spec import load_scene

LIBC = ctypes.CDLL(ctypes.util.find_library('c'), use_errno=True)
LIBC.strtol.restype = ctypes.c_long
LIBC.strtol.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_char_p), ctypes.c_int]
LIBC.strtod.restype = ctypes.c_double
LIBC.strtod.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_char_p)]

NUMBER_TEXTS = [
    '0', '42', '-7', '+5', '-0', '0x1F', '0X1f', '017', '09', '08.5', '1_000', '1e-3', '.5e-3',
    '1_0e3', '1.', '.5', '3.0', '-2.5E+2', '1e999', '-1e999', '1e-400', '0e-400', '5e-324',
    '4.9e-324', '2.2250738585072011e-308', '0x1p-1074', '-0x1p-1030', '0x1.8p-1074',
    '0x1p-3', '0x1P+4', '0x.8p1', 'inf', '-Infinity', 'nan', 'NaN', 'nan(1)',
    '9223372036854775807', '9223372036854775808', '-9223372036854775809',
    '99999999999999999999', '1:30', '0b101', '0o7', '2024-01-01', 'abc', '1e', 'e1', '.', '+',
    '0x', '1.2.3', '12abc']


def c_library_value(text):
    """Return what rcl_yaml_param_parser's get_value makes of a plain scalar (bool words aside)."""
    raw = text.encode()
    end = ctypes.c_char_p()
    ctypes.set_errno(0)
    integer = LIBC.strtol(raw, ctypes.byref(end), 0)
    if ctypes.get_errno() == 0 and raw and end.value == b'':
        return integer
    ctypes.set_errno(0)
    double = LIBC.strtod(raw, ctypes.byref(end))
    if ctypes.get_errno() == 0 and raw and end.value == b'':
        return double
    return text


def same(a, b):
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return type(a) is type(b) and a == b


@pytest.mark.parametrize('text', NUMBER_TEXTS)
def test_numbers_are_read_as_the_c_library_reads_them(text):
    assert same(ros_scalar(text), c_library_value(text)), (ros_scalar(text), c_library_value(text))


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(st.from_regex(r'[+-]?(0[xX])?[0-9a-fA-F_]{0,6}\.?[0-9]{0,4}([eEpP][+-]?[0-9]{1,4})?',
                     fullmatch=True))
def test_number_like_texts_agree_with_the_c_library(text):
    if text in ('', '+', '-'):
        return
    assert same(ros_scalar(text), c_library_value(text))


@pytest.mark.parametrize('text, value', [
    *[(word, True) for word in ('y', 'Y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE',
                                'on', 'On', 'ON')],
    *[(word, False) for word in ('n', 'N', 'no', 'No', 'NO', 'false', 'False', 'FALSE',
                                 'off', 'Off', 'OFF')],
    ('.inf', math.inf), ('-.Inf', -math.inf), ('+.INF', math.inf),
    ('', None), ('~', None), ('null', None), ('tRUE', 'tRUE'),
])
def test_words(text, value):
    assert same(ros_scalar(text), value)


def write(tmp_path, text, name='file.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_quoted_scalars_are_strings_and_keys_stay_names(tmp_path):
    path = write(tmp_path, 'a: "1"\nb: \'yes\'\non: 1e3\n1: [.5, 0x10, x]\n')
    assert load_ros_yaml(path, 'f', ValueError) == {
        'a': '1', 'b': 'yes', 'on': 1000.0, '1': [0.5, 16, 'x']}


@pytest.mark.parametrize('text, message', [
    ('a: 1\nb: 2\na: 3\n', "f: invalid YAML (line 3, column 1): duplicate key 'a'"),
    ('a: [1\n', 'f: invalid YAML (line 2, column 1)'),
    ('[' * (MAX_DEPTH + 1) + ']' * (MAX_DEPTH + 1), f'f: nested deeper than {MAX_DEPTH}'),
    ('a: !!binary AAAA\nb: [*nope]\n', 'f: invalid YAML'),
])
def test_bad_documents_are_one_line_errors(tmp_path, text, message):
    with pytest.raises(ValueError) as error:
        load_ros_yaml(write(tmp_path, text), 'f', ValueError)
    assert str(error.value).startswith(message) and '\n' not in str(error.value)


def test_unreadable_and_oversized_files(tmp_path):
    with pytest.raises(ValueError, match=r'^f: cannot read it \(No such file'):
        load_ros_yaml(tmp_path / 'absent.yaml', 'f', ValueError)
    big = write(tmp_path, '#' * MAX_FILE_BYTES + '\na: 1\n')
    with pytest.raises(ValueError, match=f'^f: larger than {MAX_FILE_BYTES} bytes'):
        load_ros_yaml(big, 'f', ValueError)


def alias_bomb(levels=9):
    """Nine aliases per level: 9**levels leaves from a few hundred bytes."""
    lines = ['l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]']
    for level in range(1, levels + 1):
        lines.append(f'l{level}: &l{level} [' + ', '.join([f'*l{level - 1}'] * 9) + ']')
    return '\n'.join(lines), f'*l{levels}'


def test_an_alias_bomb_is_refused_at_once(tmp_path):
    anchors, bomb = alias_bomb()
    scene = write(tmp_path, f'{anchors}\nduration: {bomb}\nrate: 10\n', 'scene.yaml')
    params = write(tmp_path, f'x: {{{anchors.replace(chr(10), ", ")}}}\n'
                             f'rotation_node:\n  ros__parameters:\n    outputs: {bomb}\n')
    for load, path, message in (
            (load_scene, scene, f'aliases expand it beyond {MAX_NODES} YAML nodes; refused'),
            (parameters_from_yaml, params, r'line 1, column 69\): aliases \(\*name\) are not '
                                           'allowed in a parameters file')):
        start = time.monotonic()
        with pytest.raises(ValueError, match=message):
            load(path)
        assert time.monotonic() - start < 0.5


def test_shared_aliases_within_the_bound_are_read(tmp_path):
    anchors, bomb = alias_bomb(levels=3)   # 9**4 leaves, under the bound
    document = load_ros_yaml(write(tmp_path, f'{anchors}\nall: {bomb}\n'), 'f', ValueError)
    assert len(document['all']) == 9 and document['all'][0][0][0] == ['lol'] * 9


SCENE = 'rate: 10\nmotion: {type: coning, half_angle: 0.1, frequency: 1.0}\nduration: '
PARAMS = 'rotation_node:\n  ros__parameters:\n    quaternion.norm_tolerance: '


@pytest.mark.parametrize('text', ['.5e-3', '5e-4', '0.0005', '5.0E-4'])
def test_a_number_means_the_same_in_parameters_and_scenes(tmp_path, text):
    scene = load_scene(write(tmp_path, SCENE + text + '\n', 'scene.yaml'))
    params = parameters_from_yaml(write(tmp_path, PARAMS + text + '\n'))
    assert scene.duration == params.quaternion_norm_tolerance == 0.0005


@pytest.mark.parametrize('text', ['1_0e-3', '5e-4s'])
def test_a_non_number_is_refused_by_both(tmp_path, text):
    with pytest.raises(SceneError, match=f"duration: expected a number, got str '{text}'"):
        load_scene(write(tmp_path, SCENE + text + '\n', 'scene.yaml'))
    with pytest.raises(ParameterError,
                       match=f"expected a floating-point number.*got str '{text}'"):
        parameters_from_yaml(write(tmp_path, PARAMS + text + '\n'))
