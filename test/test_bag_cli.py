"""
Tests of the rotation_bag command line (rotation_node.bag.cli): results and bad input.

Every bad input must end with exit status 1 and one line on stderr naming the
problem, leave no output file behind and leave the input untouched. convert
and plot run in-process through ``main``; play (which initialises rclpy) and
the installed console script run as subprocesses.
"""
import os
import re
import shutil
import signal
import subprocess
import sys

from bag_helpers import imu_messages, stamp_ns
import numpy as np
import pytest
from ros_harness import script
from rotation_node.bag.cli import build_parser, main
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing.writer import BagWriter

PARAMS_YAML = """rotation_node:
  ros__parameters:
    input_type: imu
    outputs: [euler, angular_velocity]
    euler: {sequence: ZYX, degrees: true}
"""


@pytest.fixture(scope='module')
def template(tmp_path_factory):
    """imu.mcap (/imu and a /foreign topic of an uninstalled type) and params.yaml."""
    directory = tmp_path_factory.mktemp('template')
    with BagWriter(directory / 'imu.mcap') as writer:
        writer.add_topic(TopicMetadata('/foreign', 'foreign_msgs/msg/Thing',
                                       definition='int32 a\n', type_hash=''))
        # Several chunks, so that damage in the middle hits one.
        for msg in imu_messages(np.random.default_rng(7), 8000):
            writer.write('/imu', msg, stamp_ns(msg))
        writer.write_serialized('/foreign', 'foreign_msgs/msg/Thing', b'\0\1\0\0\7\0\0\0',
                                stamp_ns(msg))
    (directory / 'params.yaml').write_text(PARAMS_YAML)
    return directory


@pytest.fixture
def workspace(template, tmp_path):
    """Return a fresh copy of the template files in tmp_path."""
    for name in os.listdir(template):
        shutil.copy(template / name, tmp_path / name)
    return tmp_path


def _snapshot(directory):
    return {name: (directory / name).read_bytes() for name in sorted(os.listdir(directory))}


def _damage(workspace, how):
    path = workspace / 'imu.mcap'
    data = path.read_bytes()
    if how == 'truncated':
        path.write_bytes(data[:len(data) // 2])
    elif how == 'corrupt':
        middle = len(data) // 2
        path.write_bytes(data[:middle] + b'\xff' * 64 + data[middle + 64:])
    elif how == 'zeroed':   # as a power loss leaves it
        middle = len(data) // 2
        path.write_bytes(data[:middle] + bytes(4096) + data[middle + 4096:])
    elif how == 'bad_value':
        (workspace / 'params.yaml').write_text(PARAMS_YAML.replace('ZYX', 'ZZX'))
    elif how == 'bad_yaml':
        (workspace / 'params.yaml').write_text('rotation_node: [unclosed\n  ros__parameters:')


def _run(capsys, *argv):
    handlers = [signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)]
    status = main([str(a) for a in argv])
    # The stop flag is main's only: Ctrl-C works again in the caller.
    assert [signal.getsignal(n) for n in (signal.SIGINT, signal.SIGTERM)] == handlers
    return status, capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize('damage, args, match', [
    (None, ['missing.mcap', 'out.mcap', '--params', 'params.yaml'],
     'cannot open bag missing.mcap'),
    ('truncated', ['imu.mcap', 'out.mcap', '--params', 'params.yaml', '--strict'],
     'imu.mcap: unfinished recording (no MCAP summary or footer)'),
    ('corrupt', ['imu.mcap', 'out.mcap', '--params', 'params.yaml', '--strict'],
     'could not be read'),
    (None, ['imu.mcap', 'out.mcap', '--params', 'params.yaml', '--topic', '/nope'],
     'topic /nope not in imu.mcap'),
    (None, ['imu.mcap', 'out.mcap', '--params', 'params.yaml', '--topic', '/foreign'],
     'topic /foreign in imu.mcap is foreign_msgs/msg/Thing, but input_type expects'),
    ('bad_value', ['imu.mcap', 'out.mcap', '--params', 'params.yaml'],
     "parameter 'euler.sequence': 'ZZX' is not an Euler sequence"),
    ('bad_yaml', ['imu.mcap', 'out.mcap', '--params', 'params.yaml'],
     'parameters file params.yaml: invalid YAML'),
    (None, ['imu.mcap', 'out.mcap', '--params', 'missing.yaml'],
     'parameters file missing.yaml: cannot read it'),
    (None, ['imu.mcap', 'imu.mcap', '--params', 'params.yaml', '--force'],
     'output imu.mcap is the input bag'),
    (None, ['imu.mcap', 'params.yaml', '--params', 'params.yaml'],
     'output params.yaml already exists'),
], ids=['missing', 'truncated', 'corrupt', 'topic_not_in_bag', 'wrong_type', 'bad_value',
        'bad_yaml', 'missing_params', 'output_is_input', 'output_exists'])
def test_convert_bad_input(workspace, capsys, monkeypatch, damage, args, match):
    monkeypatch.chdir(workspace)
    _damage(workspace, damage)
    before = _snapshot(workspace)
    status, stderr = _run(capsys, 'convert', *args)
    assert status == 1
    line, = stderr.splitlines()
    assert line.startswith('rotation_bag convert: error: ') and match in line
    assert _snapshot(workspace) == before


@pytest.mark.slow
def test_convert_writes_and_reports(workspace, capsys, monkeypatch):
    monkeypatch.chdir(workspace)
    status, stderr = _run(capsys, 'convert', 'imu.mcap', 'out.mcap', '--params', 'params.yaml')
    assert status == 0, stderr
    assert '/imu: 8000 messages -> /imu/euler, /imu/angular_velocity: 16000 messages' in stderr
    with BagReader(workspace / 'out.mcap') as reader:
        assert reader.message_counts == {'/imu': 8000, '/foreign': 1, '/imu/euler': 8000,
                                         '/imu/angular_velocity': 8000}


@pytest.mark.slow
def test_convert_notes_what_a_damaged_chunk_held(workspace, capsys, monkeypatch):
    """Zeroed bytes were a silent loss: fewer messages, exit 0, no note (also with --strict)."""
    monkeypatch.chdir(workspace)
    _damage(workspace, 'zeroed')
    status, stderr = _run(capsys, 'convert', 'imu.mcap', 'out.mcap', '--params', 'params.yaml')
    assert status == 0, stderr
    described, note, converted, wrote = stderr.splitlines()
    assert described == 'imu.mcap: MCAP file (zstd chunks), 8001 messages'
    lost = re.fullmatch(r'imu.mcap: (\d+) messages could not be read \(/imu (\d+)\): .* at '
                        r'offset \d+', note)
    received = int(re.match(r'/imu: (\d+) messages -> ', converted)[1])
    assert int(lost[1]) == int(lost[2]) == 8000 - received > 0
    with BagReader(workspace / 'out.mcap') as reader:
        assert reader.message_counts['/imu'] == received
    before = _snapshot(workspace)
    status, stderr = _run(capsys, 'convert', 'imu.mcap', 'strict.mcap', '--params',
                          'params.yaml', '--strict')
    line, = stderr.splitlines()
    assert status == 1 and line.endswith('; refused (--strict)') and 'at offset' in line
    assert _snapshot(workspace) == before


@pytest.mark.slow
def test_plot_default_name_and_bad_topic(workspace, capsys, monkeypatch):
    monkeypatch.chdir(workspace)
    assert _run(capsys, 'convert', 'imu.mcap', 'out.mcap', '--params', 'params.yaml')[0] == 0
    status, stderr = _run(capsys, 'plot', 'out.mcap', '--topic', '/imu/euler',
                          '--params', 'params.yaml')
    assert status == 0 and 'plotted 8000 messages of /imu/euler to out_imu_euler.png' in stderr
    assert (workspace / 'out_imu_euler.png').read_bytes()[:4] == b'\x89PNG'
    before = _snapshot(workspace)
    for topic, match in (('/nope', 'topic /nope not in out.mcap'),
                         ('/foreign', 'cannot plot foreign_msgs/msg/Thing')):
        status, stderr = _run(capsys, 'plot', 'out.mcap', '--topic', topic, '-o', 'x.png')
        line, = stderr.splitlines()
        assert status == 1 and line.startswith('rotation_bag plot: error: ') and match in line
    assert _snapshot(workspace) == before


@pytest.mark.parametrize('args, match', [
    (['missing.mcap', '--reference', '/imu', '--estimate', '/imu'],
     'cannot open bag missing.mcap'),
    (['imu.mcap', 'imu.mcap', 'imu.mcap', '--reference', '/imu', '--estimate', '/imu'],
     'compare takes one bag or two'),
    (['imu.mcap', '--reference', '/nope', '--estimate', '/imu'], 'topic /nope not in imu.mcap'),
    (['imu.mcap', '--reference', '/foreign', '--estimate', '/imu'],
     'cannot compare /foreign: foreign_msgs/msg/Thing has no orientation the node reads'),
    (['imu.mcap', '--reference', '/imu', '--estimate', '/imu', '--reference-type', 'pose'],
     '/imu is sensor_msgs/msg/Imu, not geometry_msgs/msg/PoseStamped'),
    (['imu.mcap', '--reference', '/imu', '--estimate', '/imu', '--json', 'params.yaml'],
     'output params.yaml already exists'),
], ids=['missing', 'three_bags', 'topic_not_in_bag', 'unknown_type', 'wrong_input_type',
        'output_exists'])
def test_compare_bad_input(workspace, capsys, monkeypatch, args, match):
    monkeypatch.chdir(workspace)
    before = _snapshot(workspace)
    status, stderr = _run(capsys, 'compare', *args)
    line, = stderr.splitlines()
    assert status == 1 and line.startswith('rotation_bag compare: error: ') and match in line
    assert _snapshot(workspace) == before


@pytest.mark.parametrize('option', [['--time-offset', 'soon'], ['--time-offset', 'nan'],
                                    ['--max-gap', '0'], ['--align', 'sideways']])
def test_compare_usage_errors_exit_2(capsys, option):
    with pytest.raises(SystemExit) as exit_:
        main(['compare', 'in.mcap', '--reference', '/a', '--estimate', '/b', *option])
    assert exit_.value.code == 2
    assert f'argument {option[0]}' in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize('args, match', [
    (['missing.mcap'], 'cannot open bag missing.mcap'),
    (['imu.mcap', '--topics', '/nope'], 'topic /nope not in imu.mcap'),
    (['imu.mcap', '--topics', '/foreign'], "unknown message type 'foreign_msgs/msg/Thing'"),
    (['imu.mcap', '--rate', '-1'], 'rate must be 0 or a finite number >= 1e-09, got -1.0'),
    (['imu.mcap', '--rate', '1e-300'], 'rate must be 0 or a finite number >= 1e-09, got 1e-300'),
    (['imu.mcap', '--rate', 'inf'], 'rate must be 0 or a finite number >= 1e-09, got inf'),
    (['imu.mcap', '--delay', '1e300'], 'delay must be a number of seconds in [0, '),
    (['imu.mcap', '--delay', 'nan'], 'delay must be a number of seconds in [0, '),
    (['imu.mcap', '--topics', '/imu-raw'],
     "'/imu-raw' is not a valid ROS 2 topic name: topic name must not contain characters"),
], ids=['missing', 'topic_not_in_bag', 'unknown_type', 'negative_rate', 'tiny_rate',
        'infinite_rate', 'huge_delay', 'nan_delay', 'invalid_topic_name'])
def test_play_bad_input(workspace, args, match):
    before = _snapshot(workspace)
    result = subprocess.run([script('rotation_bag'), 'play', *args], cwd=workspace,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    line, = result.stderr.splitlines()
    assert line.startswith('rotation_bag play: error: ') and match in line
    assert _snapshot(workspace) == before


@pytest.mark.slow
def test_usage_error_exits_2():
    result = subprocess.run([script('rotation_bag'), 'convert', 'in.mcap'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and 'the following arguments are required' in result.stderr


#: What ``convert`` of an MCAP bag of a fixed-layout type does without (its start-up).
NOT_LOADED_BY_CONVERT = (
    'rclpy', 'rosidl_parser', 'std_msgs', 'sensor_msgs', 'geometry_msgs', 'builtin_interfaces',
    'rosbags', 'matplotlib', 'mcap.writer', 'numba', 'concurrent.futures', 'ctypes.util')


@pytest.mark.slow
def test_convert_of_an_mcap_bag_loads_no_ros_client_library(workspace):
    """
    Load neither rclpy (the rcl libraries) nor the message packages, rosbags, numba...

    The messages are decoded and encoded from the types' installed descriptions;
    the kernels of a small bag run interpreted.
    """
    probe = ('import sys; from rotation_node.bag.cli import main; '
             "status = main(['convert', 'imu.mcap', 'out.mcap', '--params', 'params.yaml']); "
             f'print(status, sorted(m for m in {NOT_LOADED_BY_CONVERT!r} if m in sys.modules))')
    result = subprocess.run([sys.executable, '-c', probe], cwd=workspace, capture_output=True,
                            text=True, timeout=300)
    assert result.stdout.split('\n')[-2] == '0 []', result.stderr
    assert (workspace / 'out.mcap').exists()


def test_ros_args_are_removed_as_rclpy_removes_them(workspace, capsys, monkeypatch):
    monkeypatch.chdir(workspace)
    assert main(['convert', 'imu.mcap', 'out.mcap', '--ros-args', '-r', '__ns:=/x', '--',
                 '--params', 'params.yaml']) == 0
    assert (workspace / 'out.mcap').exists()


COMMAND_LINES = [
    ['record', 'out.mcap', '--topics', '/imu', '/odom', '--duration', '2', '--compression', 'lz4'],
    ['play', 'in.mcap', '--rate', '0', '--topics', '/imu', '--loop', '--strict'],
    ['convert', 'a.mcap', 'b.mcap', 'outdir', '--params', 'p.yaml', '--topic', '/imu', '--jobs',
     '2', '--force'],
    ['plot', 'in.mcap', '--topic', '/imu/euler', '-o', 'x.png'],
    ['export', 'in.mcap', 'out.csv', '--params', 'p.yaml', '--topic', '/imu'],
    ['compare', 'ref.mcap', 'est.mcap', '--reference', '/a', '--estimate', '/b', '--time-offset',
     '0.5', '--align', 'world', '--reference-frames', 'map', 'base'],
]


@pytest.mark.parametrize('arguments', COMMAND_LINES, ids=[line[0] for line in COMMAND_LINES])
def test_the_parser_of_one_command_reads_it_as_the_whole_parser(arguments):
    assert vars(build_parser(arguments[0]).parse_args(arguments)) == vars(
        build_parser().parse_args(arguments))


def test_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(['--help'])
    assert exit_.value.code == 0
    listed = re.findall(r'^    (\w+) ', capsys.readouterr().out, re.MULTILINE)
    assert listed == [line[0] for line in COMMAND_LINES]
