"""Tests of rotation_node.node.program: the node's command line, read before rclpy reads it."""
import pytest

from rotation_node.errors import ParameterError
from rotation_node.node.program import check_parameter_names, parameters_files, ros_arguments


def test_node_prefixed_parameters_are_checked_for_this_node_only():
    check_parameter_names(['x', '--ros-args', '-p', 'other:zzz:=1', '-p',
                           'rotation_node:qos.depth:=5', '-p', 'use_sim_time:=true'])
    with pytest.raises(ParameterError, match="unknown parameter 'qos.dept' in --param "
                                             r'rotation_node:qos.dept:=5 \(did you mean'):
        check_parameter_names(['x', '--ros-args', '--param', 'rotation_node:qos.dept:=5'])


def test_ros_arguments_are_read_as_rcl_reads_them():
    args = ['rotation_node', '--params-file', 'not-ros.yaml', '--ros-args', '-r', '__ns:=/a',
            '--params-file', 'a.yaml', '--disable-stdout-logs', '-p', 'x:=--params-file', '--',
            'app', '--ros-args', '--params-file', 'b.yaml']
    assert ros_arguments(args) == [
        ('-r', '__ns:=/a'), ('--params-file', 'a.yaml'), ('--disable-stdout-logs', None),
        ('-p', 'x:=--params-file'), ('--params-file', 'b.yaml')]


def test_parameters_files_are_the_values_of_each_params_file_flag():
    assert parameters_files(['x', '--ros-args', '--params-file', 'a.yaml', '-p', 'q:=1',
                             '--', '--ros-args', '--params-file', 'b.yaml',
                             '--params-file']) == ['a.yaml', 'b.yaml']


@pytest.mark.parametrize('args', [
    ['rotation_node', '--help'],
    ['rotation_node', '--ros-args', '-r', '__ns:=/a', '--', '-h'],
])
def test_help_outside_the_ros_arguments_prints_the_usage(capsys, args):
    from rotation_node.node.program import main
    assert main(args) == 0
    out = capsys.readouterr().out
    assert out.startswith('usage: rotation_node ') and 'qos.depth' in out


def test_help_inside_the_ros_arguments_is_not_the_programs(capsys):
    from rotation_node.node.program import main
    # '-h' is the value of a remapping here: rclpy refuses the rule, in one line
    assert main(['rotation_node', '--ros-args', '-r', '-h']) == 1
    err = capsys.readouterr().err
    assert err.startswith('rotation_node: error: ') and err.count('\n') == 1
