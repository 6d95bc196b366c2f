"""Tests of rotation_node.parameters: the parameter table, validation and YAML loading."""
import math
import os
from pathlib import Path
import re
import tempfile

import pytest
from rotation_node.conversions import SEQUENCES
from rotation_node.errors import ParameterError
from rotation_node.parameters import (
    NODE_NAME, NodeParameters, OUTPUTS, PARAMETERS, PARAMETERS_BY_NAME, parameters_from_yaml)
import yaml

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'params.yaml'


def write(tmp_path, text, name='params.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return path


# The table ------------------------------------------------------------------------

def test_every_field_has_one_row_with_a_description():
    assert [spec.attribute for spec in PARAMETERS] == list(NodeParameters.__dataclass_fields__)
    assert len(PARAMETERS_BY_NAME) == len(PARAMETERS)
    assert all(len(spec.description) > 20 for spec in PARAMETERS)


def test_the_issues_name_every_parameter():
    assert set(PARAMETERS_BY_NAME) == {
        'input_type', 'outputs', 'euler.sequence', 'euler.degrees', 'euler.unwrap',
        'euler.singularity_threshold', 'quaternion.continuity', 'quaternion.norm_tolerance',
        'angular_velocity.input_frame', 'angular_velocity.output_frame',
        'covariance.frame', 'covariance.max_linearisation_ratio', 'frames.input_world',
        'frames.input_body', 'frames.output_world', 'frames.output_body',
        'mounting.body_rotation', 'mounting.world_rotation', 'mounting.yaw_offset',
        'mounting.magnetic_declination', 'mounting.tf_sensor_frame', 'mounting.tf_body_frame',
        'qos.reliability', 'qos.depth', 'tf.parent_frame', 'tf.child_frame'}


def test_defaults_follow_ros_conventions():
    params = NodeParameters()
    assert params.euler_sequence == 'xyz'                 # roll, pitch, yaw (REP 103)
    assert params.angular_velocity_input_frame == 'body'  # REP 145
    assert params.euler_degrees is False                  # REP 103: radians
    assert params.covariance_frame == 'fixed'             # REP 145: about fixed axes
    assert (params.frames_input_world, params.frames_input_body, params.frames_output_world,
            params.frames_output_body) == ('enu', 'flu', 'enu', 'flu')   # REP 103


def test_ros_names_round_trip():
    params = NodeParameters(outputs=['euler', 'matrix'], euler_sequence='ZYZ', qos_depth=3)
    ros = params.to_ros()
    assert ros['outputs'] == ['euler', 'matrix'] and ros['euler.sequence'] == 'ZYZ'
    assert NodeParameters.from_ros(ros) == params


def test_rotations_are_stored_as_tuples_of_float_from_any_sequence():
    import array
    params = NodeParameters.from_ros({'mounting.body_rotation': array.array('d', [1.0, 2.0, 3.0]),
                                      'mounting.world_rotation': [0.0, 0.0, 0.6, 0.8]})
    assert params.mounting_body_rotation == (1.0, 2.0, 3.0)
    assert params.to_ros()['mounting.world_rotation'] == [0.0, 0.0, 0.6, 0.8]


def test_string_arrays_are_stored_as_tuples():
    assert NodeParameters(outputs=['quaternion']).outputs == ('quaternion',)


def test_replaced_changes_only_the_named_parameters():
    params = NodeParameters().replaced({'euler.degrees': True})
    assert params == NodeParameters(euler_degrees=True)


def test_replaced_rejects_an_unknown_name():
    with pytest.raises(ParameterError, match="unknown parameter 'euler.sequnce'"):
        NodeParameters().replaced({'euler.sequnce': 'ZYX'})


@pytest.mark.parametrize('name, nearest', [
    ('euler.sequnce', " (did you mean 'euler.sequence'?)"),
    ('qos.reliable', " (did you mean 'qos.reliability'?)"),
    ('outptus', " (did you mean 'outputs'?)"),
    ('zzz', '')])
def test_an_unknown_name_names_the_nearest_parameter(name, nearest):
    with pytest.raises(ParameterError) as error:
        NodeParameters().replaced({name: 'x'})
    assert str(error.value).startswith(f"unknown parameter '{name}'{nearest}; the node's "
                                       'parameters are input_type, outputs, euler.sequence')


def test_a_value_not_allowed_names_the_nearest_choice():
    with pytest.raises(ParameterError, match=r"'outputs': 'eulr' is not allowed \(did you mean "
                                             r"'euler'\?\); each one of: quaternion, euler"):
        NodeParameters(outputs=('quaternion', 'eulr'))
    with pytest.raises(ParameterError, match=r"'input_type': 'gps' is not allowed; one of"):
        NodeParameters(input_type='gps')


@pytest.mark.parametrize('value', [[], (), None])
def test_no_outputs_is_reported_as_an_empty_list(value):
    with pytest.raises(ParameterError, match="'outputs': list at least one output; choose from "
                                             'quaternion, euler'):
        NodeParameters(outputs=value)


def test_a_long_value_is_described_briefly():
    with pytest.raises(ParameterError) as error:
        NodeParameters(euler_degrees='x' * 1_000_000)
    assert len(str(error.value)) < 200 and '(1000002 characters)' in str(error.value)


# Validation -----------------------------------------------------------------------

@pytest.mark.parametrize('sequence', SEQUENCES)
def test_every_euler_convention_is_accepted(sequence):
    assert NodeParameters(euler_sequence=sequence).euler_sequence == sequence


@pytest.mark.parametrize('name, value, message', [
    ('euler.sequence', 'xxy', "'euler.sequence': 'xxy' is not an Euler sequence"),
    ('euler.sequence', 'XyZ', "'euler.sequence': 'XyZ' is not an Euler sequence"),
    ('euler.sequence', 'rpy', "'euler.sequence': 'rpy' is not an Euler sequence"),
    ('euler.sequence', 'xy', "'euler.sequence': 'xy' is not an Euler sequence"),
    ('input_type', 'twist', "'input_type': 'twist' is not allowed; one of: quaternion"),
    ('outputs', ['euler', 'eular'], "'outputs': 'eular' is not allowed"),
    ('outputs', [], "'outputs': list at least one output"),
    ('outputs', ['euler', 'matrix', 'euler'], "'outputs': euler listed twice"),
    ('outputs', 'euler', "'outputs': expected a list of strings, got str"),
    ('euler.degrees', 1, "'euler.degrees': expected a boolean, got int"),
    ('euler.unwrap', 'true', "'euler.unwrap': expected a boolean, got str"),
    ('euler.singularity_threshold', -0.1,
     "'euler.singularity_threshold': must be from 0 to 1.5708, got -0.1"),
    ('euler.singularity_threshold', 2.0,
     "'euler.singularity_threshold': must be from 0 to 1.5708, got 2.0"),
    ('euler.singularity_threshold', 0, "'euler.singularity_threshold': expected a floating"),
    ('euler.singularity_threshold', math.nan, "'euler.singularity_threshold': must be finite"),
    ('quaternion.norm_tolerance', True, "'quaternion.norm_tolerance': expected a floating"),
    ('quaternion.norm_tolerance', math.inf, "'quaternion.norm_tolerance': must be finite"),
    ('angular_velocity.input_frame', 'imu', "'angular_velocity.input_frame': 'imu' is not"),
    ('angular_velocity.output_frame', 'World', "'angular_velocity.output_frame': 'World'"),
    ('qos.reliability', 'sensor_data', "'qos.reliability': 'sensor_data' is not allowed"),
    ('qos.depth', 0, "'qos.depth': must be from 1 to 10000, got 0"),
    ('qos.depth', 10.0, "'qos.depth': expected an integer, got float"),
    ('mounting.body_rotation', [0.0, 0.0, 0.0, 2.0],
     "'mounting.body_rotation': expected a unit quaternion [x, y, z, w], got norm 2.0"),
    ('mounting.body_rotation', [0.0, 0.0], "'mounting.body_rotation': expected a list of 3 or "
     '4 numbers, got 2'),
    ('mounting.world_rotation', [0, 0, 90], "'mounting.world_rotation[0]': expected a floating"),
    ('mounting.world_rotation', 'yaw', "'mounting.world_rotation': expected a list of 3 or 4"),
    ('mounting.world_rotation', [0.0, math.inf, 0.0], "'mounting.world_rotation[1]': must be "
     'finite'),
    ('mounting.yaw_offset', 1, "'mounting.yaw_offset': expected a floating"),
    ('mounting.magnetic_declination', math.nan, "'mounting.magnetic_declination': must be "
     'finite'),
])
def test_invalid_values_are_rejected_naming_the_parameter(name, value, message):
    with pytest.raises(ParameterError, match=re.escape(message)):
        NodeParameters.from_ros({name: value})


@pytest.mark.parametrize('values, message', [
    ({'input_type': 'tf'}, "'tf.parent_frame': required with input_type tf"),
    ({'input_type': 'tf', 'tf.parent_frame': 'map'}, "'tf.child_frame': required"),
    ({'input_type': 'tf', 'tf.parent_frame': 'map', 'tf.child_frame': 'map'},
     "'tf.parent_frame' and 'tf.child_frame' are both 'map'"),
    ({'tf.child_frame': '/base_link'}, "'tf.child_frame': '/base_link' starts with '/'"),
    ({'tf.parent_frame': 1}, "'tf.parent_frame': expected a string"),
])
def test_tf_frames_are_required_and_different_with_input_type_tf(values, message):
    with pytest.raises(ParameterError, match=re.escape(message)):
        NodeParameters.from_ros(values)


def test_tf_frames_are_optional_for_other_input_types():
    params = NodeParameters.from_ros({'input_type': 'tf', 'tf.parent_frame': 'map',
                                      'tf.child_frame': 'base_link'})
    assert (params.tf_parent_frame, params.tf_child_frame) == ('map', 'base_link')
    assert NodeParameters(input_type='imu', tf_parent_frame='map').tf_child_frame == ''
    with pytest.raises(ParameterError, match="'tf.child_frame': required"):
        params.replaced({'tf.child_frame': ''})


def test_parameter_error_is_a_value_error():
    with pytest.raises(ValueError):
        NodeParameters(qos_depth=-1)


@pytest.mark.parametrize('name, value', [
    ('euler.singularity_threshold', 0.0), ('euler.singularity_threshold', math.pi / 2),
    ('quaternion.norm_tolerance', 0.0), ('quaternion.norm_tolerance', 1.0),
    ('qos.depth', 1), ('qos.depth', 10000), ('outputs', list(OUTPUTS)),
])
def test_range_ends_and_every_output_are_accepted(name, value):
    assert NodeParameters.from_ros({name: value}).to_ros()[name] == value


# YAML -----------------------------------------------------------------------------

def test_shipped_config_holds_every_parameter_at_its_default():
    assert parameters_from_yaml(CONFIG) == NodeParameters()
    section = yaml.safe_load(CONFIG.read_text())[f'/**/{NODE_NAME}']['ros__parameters']

    def names(mapping, prefix=''):
        for key, value in mapping.items():
            if isinstance(value, dict):
                yield from names(value, f'{prefix}{key}.')
            else:
                yield f'{prefix}{key}'
    assert sorted(names(section)) == sorted(PARAMETERS_BY_NAME)


NESTED = """
rotation_node:
  ros__parameters:
    input_type: odometry
    outputs: [quaternion, angular_velocity]
    euler:
      sequence: ZYX
      degrees: true
    qos:
      depth: 50
"""

FLAT = """
rotation_node:
  ros__parameters:
    input_type: odometry
    outputs: [quaternion, angular_velocity]
    euler.sequence: ZYX
    euler.degrees: true
    qos.depth: 50
"""

EXPECTED = NodeParameters(
    input_type='odometry', outputs=('quaternion', 'angular_velocity'),
    euler_sequence='ZYX', euler_degrees=True, qos_depth=50)


@pytest.mark.parametrize('text', [NESTED, FLAT], ids=['nested', 'dotted'])
def test_nested_and_dotted_names_are_read(tmp_path, text):
    assert parameters_from_yaml(write(tmp_path, text)) == EXPECTED


@pytest.mark.parametrize('key', ['rotation_node', '/rotation_node', '/**', '/**/rotation_node',
                                 '/*'])
def test_node_keys_and_wildcards_are_matched(tmp_path, key):
    text = NESTED.replace('rotation_node:', f'{key}:', 1)
    assert parameters_from_yaml(write(tmp_path, text)) == EXPECTED


def test_sections_apply_in_file_order_and_other_nodes_are_ignored(tmp_path):
    text = """
/**:
  ros__parameters:
    use_sim_time: true
    euler.sequence: ZYZ
other_node:
  ros__parameters:
    input_type: not_ours
rotation_node:
  ros__parameters:
    euler.degrees: true
"""
    assert parameters_from_yaml(write(tmp_path, text)) == NodeParameters(
        euler_sequence='ZYZ', euler_degrees=True)


def test_a_namespaced_node_name_is_matched(tmp_path):
    text = NESTED.replace('rotation_node:', '/robot/rotation_node:', 1)
    assert parameters_from_yaml(write(tmp_path, text), '/robot/rotation_node') == EXPECTED
    with pytest.raises(ParameterError, match="no section for node '/rotation_node'"):
        parameters_from_yaml(write(tmp_path, text))


def test_nested_namespace_keys_are_sections(tmp_path):
    text = 'robot:\n  rotation_node:\n    ros__parameters:\n      qos.depth: 5\n'
    assert parameters_from_yaml(write(tmp_path, text), '/robot/rotation_node').qos_depth == 5
    with pytest.raises(ParameterError, match=r"no section for node '/rotation_node' \(its "
                                             r"sections: 'robot/rotation_node'; key it"):
        parameters_from_yaml(write(tmp_path, text))


def test_a_malformed_section_of_another_node_is_an_error(tmp_path):
    """The whole file is refused, for every node, as rcl does: by the node and convert."""
    text = '/**/rotation_node:\n  ros__parameters: {}\nother_node:\n  rate: 5\n'
    with pytest.raises(ParameterError, match="section 'other_node' needs a 'ros__param"):
        parameters_from_yaml(write(tmp_path, text))


@pytest.mark.parametrize('text', ['1e-3', '1.0e-3', '0.001', '.001'])
def test_exponent_floats_are_read_as_ros_reads_them(tmp_path, text):
    path = write(tmp_path, f'/**:\n  ros__parameters:\n    quaternion.norm_tolerance: {text}\n')
    assert parameters_from_yaml(path).quaternion_norm_tolerance == 0.001


def test_missing_file(tmp_path):
    with pytest.raises(ParameterError, match='nope.yaml: cannot read it'):
        parameters_from_yaml(tmp_path / 'nope.yaml')


@pytest.mark.parametrize('text, message', [
    ('rotation_node: [unclosed', 'invalid YAML'),
    ('- a list', 'expected a mapping of node names'),
    ('other_node:\n  ros__parameters: {}\n', "no section for node '/rotation_node'"),
    ('rotation_node:\n  input_type: imu\n', "section 'rotation_node' needs a 'ros__parameters:"),
    ('rotation_node:\n  ros__parameters:\n    euler:\n      sequense: xyz\n',
     "unknown parameter 'euler.sequense'"),
    ('rotation_node:\n  ros__parameters:\n    euler.sequence: xxy\n',
     "parameter 'euler.sequence': 'xxy' is not an Euler sequence"),
    ('rotation_node:\n  ros__parameters:\n    euler.singularity_threshold: 0\n',
     "parameter 'euler.singularity_threshold': expected a floating-point number"),
    ('rotation_node:\n  ros__parameters:\n    outputs: euler\n',
     "parameter 'outputs': expected a list of strings"),
])
def test_bad_files_name_the_file_and_the_problem(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ParameterError) as error:
        parameters_from_yaml(path)
    assert str(error.value).startswith(f'parameters file {path}: ')
    assert message in str(error.value)


def test_a_launch_files_parameters_are_not_reported_against_launch_ros_temporary_file(
        tmp_path):
    """launch_ros writes parameters=[{...}] to /tmp/launch_params_*: the user never wrote it."""
    with tempfile.NamedTemporaryFile('w', prefix='launch_params_', suffix='', delete=False) as f:
        f.write('/**:\n  ros__parameters:\n    input_type: twist\n')   # as launch_ros dumps it
    try:
        with pytest.raises(ParameterError) as error:
            parameters_from_yaml(f.name)
        message = str(error.value)
        assert message.startswith("the parameters the launch file gives: parameter 'input_type': "
                                  "'twist' is not allowed")
        assert f.name not in message and 'launch_params_' not in message
    finally:
        os.unlink(f.name)
    # A user's own file of that name elsewhere keeps its path.
    path = write(tmp_path, '/**:\n  ros__parameters:\n    input_type: twist\n',
                 name='launch_params_abc')
    with pytest.raises(ParameterError, match=f'^parameters file {re.escape(str(path))}: '):
        parameters_from_yaml(path)
