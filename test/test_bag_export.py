"""Tests of rotation_node.bag.export: one topic's converted values as a CSV or Parquet table."""
import csv
import os
import sys

from bag_helpers import imu_messages, serialized_rows, write_rosbag2
import numpy as np
import pytest
from ros_harness import make_input_message
from rotation_node.bag.cli import main
from rotation_node.bag.convert import convert
from rotation_node.bag.export import output_columns, table_columns
from rotation_node.bag.plot import output_panels
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.parameters import NodeParameters
from rotation_node.registry import OUTPUTS
from scipy.spatial.transform import Rotation
import yaml


def params_file(tmp_path, **parameters):
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump({'rotation_node': {'ros__parameters': parameters}}))
    return path


def read_csv(path):
    with open(path, newline='') as stream:
        header, *rows = list(csv.reader(stream))
    return header, rows


def numbers(rows, header, names):
    index = [header.index(name) for name in names]
    return np.array([[float(row[i]) if row[i] else np.nan for i in index] for row in rows])


@pytest.fixture
def imu_bag(tmp_path, rng):
    """Return a rosbag2 directory by the rosbags writer: 40 Imu messages and another topic."""
    messages = imu_messages(rng, 40)
    others = [make_input_message('quaternion', Rotation.identity(),
                                 stamp_ns=1_700_000_000 * 10**9)]
    path = tmp_path / 'imu_bag'
    write_rosbag2(path, sorted(serialized_rows('/imu', messages) + serialized_rows('/q', others),
                               key=lambda row: row[3]))
    return path, messages


def test_columns_and_values_against_scipy(imu_bag, tmp_path, capsys):
    path, messages = imu_bag
    out = tmp_path / 'imu.csv'
    params = params_file(tmp_path, input_type='imu', outputs=[
        'quaternion', 'euler', 'matrix', 'angular_velocity', 'euler_stddev', 'euler_covariance'])
    assert main(['export', str(path), str(out), '--params', str(params)]) == 0
    assert 'wrote 40 rows' in capsys.readouterr().err
    header, rows = read_csv(out)
    assert header[:8] == ['stamp_ns', 'frame_id', 'qx', 'qy', 'qz', 'qw', 'roll', 'pitch']
    assert 'r11' in header and 'wz' in header and 'yaw_stddev' in header
    assert header[-1] == 'euler_covariance_22'
    assert [int(row[0]) for row in rows] == [
        m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in messages]
    assert {row[1] for row in rows} == {'imu_link'}
    truth = Rotation.from_quat([[m.orientation.x, m.orientation.y, m.orientation.z,
                                 m.orientation.w] for m in messages])
    q = numbers(rows, header, ['qx', 'qy', 'qz', 'qw'])
    assert np.abs(q - truth.as_quat(canonical=True)).max() < 1e-15
    rpy = numbers(rows, header, ['roll', 'pitch', 'yaw'])
    assert np.abs(rpy - truth.as_euler('xyz')).max() < 1e-12
    matrix = numbers(rows, header, [f'r{i}{j}' for i in (1, 2, 3) for j in (1, 2, 3)])
    assert np.abs(matrix - truth.as_matrix().reshape(-1, 9)).max() < 1e-15
    w = numbers(rows, header, ['wx', 'wy', 'wz'])
    assert np.array_equal(w, [[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                              for m in messages])
    angles = numbers(rows, header, [f'euler_covariance_angle_{i}' for i in range(3)])
    assert np.array_equal(angles, rpy)
    variances = numbers(rows, header, ['euler_covariance_00', 'euler_covariance_11',
                                       'euler_covariance_22'])
    stddev = numbers(rows, header, ['roll_stddev', 'pitch_stddev', 'yaw_stddev'])
    ok = ~np.isnan(stddev[:, 0])
    assert ok.sum() > 30
    assert np.abs(np.sqrt(variances[ok]) - stddev[ok]).max() < 1e-15


@pytest.mark.parametrize('outputs', [['quaternion', 'euler', 'angular_velocity', 'euler_rates'],
                                     ['euler', 'euler_stddev']])
def test_values_are_converts_bit_for_bit(imu_bag, tmp_path, outputs):
    """The block pipeline (first case) and the per-message one (second) as convert runs them."""
    path, _ = imu_bag
    params = NodeParameters(input_type='imu', outputs=outputs, euler_sequence='ZYX',
                            euler_degrees=True, mounting_body_rotation=(0.0, 90.0, 0.0))
    out = tmp_path / 'imu.csv'
    file = params_file(tmp_path, **params.to_ros())
    assert main(['export', str(path), str(out), '--params', str(file), '--topic', '/imu']) == 0
    convert(path, tmp_path / 'converted.mcap', params, topics=['/imu'])
    header, rows = read_csv(out)
    with BagReader(tmp_path / 'converted.mcap') as reader:
        for name in outputs:
            expected = [OUTPUTS[name].message.numbers(record.message())
                        for record in reader.messages([f'/imu/{name}'])]
            got = numbers(rows, header, output_columns(name, params))
            got = [tuple(row) for row in got if not np.isnan(row).all()]
            assert len(expected) >= 39
            assert got == [tuple(map(float, e)) for e in expected], name


def test_missing_outputs_leave_empty_cells(tmp_path):
    """A finite difference has no value at the first message: its cells are empty."""
    messages = [make_input_message('quaternion', Rotation.from_rotvec([0.0, 0.0, 0.1 * k]),
                                   stamp_ns=1_700_000_000 * 10**9 + k * 10**7, frame_id='map')
                for k in range(5)]
    bag = tmp_path / 'q_bag'
    write_rosbag2(bag, serialized_rows('/q', messages))
    out = tmp_path / 'q.csv'
    params = params_file(tmp_path, input_type='quaternion', outputs=['angular_velocity', 'euler'],
                         euler={'sequence': 'ZYX'})
    assert main(['export', str(bag), str(out), '--params', str(params)]) == 0
    header, rows = read_csv(out)
    assert header == ['stamp_ns', 'frame_id', 'wx', 'wy', 'wz',
                      'euler_ZYX_0', 'euler_ZYX_1', 'euler_ZYX_2']
    assert rows[0][2:5] == ['', '', ''] and rows[0][5] != ''
    w = numbers(rows[1:], header, ['wx', 'wy', 'wz'])
    assert np.abs(w - [0.0, 0.0, 10.0]).max() < 1e-9
    assert {row[1] for row in rows} == {'map'}


def test_every_output_has_as_many_columns_as_numbers():
    for sequence in ('xyz', 'ZXZ'):
        params = NodeParameters(outputs=tuple(OUTPUTS), euler_sequence=sequence)
        columns = table_columns(params)
        assert len(columns) == len(set(columns))
        for name in OUTPUTS:
            width = max(panel.start + len(panel.labels) for panel in output_panels(name, params))
            assert len(output_columns(name, params)) == width, name


def _listing(directory):
    return sorted(os.listdir(directory))


@pytest.mark.parametrize('arguments, message', [
    (['--topic', '/nope'], '/nope'),
    (['--topic', '/q'], 'input_type expects sensor_msgs/msg/Imu'),
    ([], None),
])
def test_bad_input_is_one_line_exit_1_and_nothing_written(imu_bag, tmp_path, capsys,
                                                          arguments, message):
    path, _ = imu_bag
    params = params_file(tmp_path, input_type='imu', outputs=['euler'])
    out = tmp_path / ('imu.txt' if message is None else 'imu.csv')
    before = _listing(tmp_path)
    assert main(['export', str(path), str(out), '--params', str(params), *arguments]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('rotation_bag export: error: ')
    assert (message or 'expected a .csv or .parquet file name') in err[0]
    assert _listing(tmp_path) == before


def test_corrupt_bag_leaves_nothing(tmp_path, capsys):
    bag = tmp_path / 'broken.mcap'
    bag.write_bytes(b'\x89MCAP0\r\n' + os.urandom(300))
    params = params_file(tmp_path, input_type='imu', outputs=['euler'])
    before = _listing(tmp_path)
    assert main(['export', str(bag), str(tmp_path / 'x.csv'), '--params', str(params)]) == 1
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert _listing(tmp_path) == before


def test_existing_output_needs_force(imu_bag, tmp_path, capsys):
    path, _ = imu_bag
    params = params_file(tmp_path, input_type='imu', outputs=['euler'])
    out = tmp_path / 'imu.csv'
    out.write_text('mine')
    assert main(['export', str(path), str(out), '--params', str(params)]) == 1
    assert 'already exists' in capsys.readouterr().err
    assert out.read_text() == 'mine'
    assert main(['export', str(path), str(out), '--params', str(params), '--force']) == 0
    assert read_csv(out)[0] == ['stamp_ns', 'frame_id', 'roll', 'pitch', 'yaw']


def test_parquet_without_pyarrow_is_one_line(imu_bag, tmp_path, capsys, monkeypatch):
    path, _ = imu_bag
    monkeypatch.setitem(sys.modules, 'pyarrow', None)   # import pyarrow raises ImportError
    params = params_file(tmp_path, input_type='imu', outputs=['euler'])
    before = _listing(tmp_path)
    assert main(['export', str(path), str(tmp_path / 'imu.parquet'), '--params',
                 str(params)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['rotation_bag export: error: writing Parquet needs pyarrow, which is not '
                   'installed (pip install pyarrow), or write a .csv file']
    assert _listing(tmp_path) == before


class _PyarrowForAnotherNumpy:
    """A meta path finder: ``import pyarrow`` fails as pyarrow >= 22 does under numpy 1."""

    def find_spec(self, name, path=None, target=None):
        if name == 'pyarrow' or name.startswith('pyarrow.'):
            raise ImportError('pyarrow requires NumPy 2.0 or newer, found 1.26.4')
        return None


def test_parquet_with_a_pyarrow_that_does_not_load_is_one_line(
        imu_bag, tmp_path, capsys, monkeypatch):
    path, _ = imu_bag
    for name in [name for name in sys.modules if name.split('.')[0] == 'pyarrow']:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, 'meta_path', [_PyarrowForAnotherNumpy(), *sys.meta_path])
    params = params_file(tmp_path, input_type='imu', outputs=['euler'])
    before = _listing(tmp_path)
    assert main(['export', str(path), str(tmp_path / 'imu.parquet'), '--params',
                 str(params)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['rotation_bag export: error: writing Parquet needs pyarrow, which does not '
                   'load here (pyarrow requires NumPy 2.0 or newer, found 1.26.4); install one '
                   'that does, or write a .csv file']
    assert _listing(tmp_path) == before


@pytest.mark.slow
def test_parquet_holds_the_csvs_values(imu_bag, tmp_path):
    import pyarrow.parquet as pq  # in requirements.txt: the test suite has it
    path, _ = imu_bag
    params = params_file(tmp_path, input_type='imu', outputs=['quaternion', 'euler_stddev'])
    for name in ('imu.csv', 'imu.parquet'):
        assert main(['export', str(path), str(tmp_path / name), '--params', str(params)]) == 0
    header, rows = read_csv(tmp_path / 'imu.csv')
    table = pq.read_table(tmp_path / 'imu.parquet')
    assert table.column_names == header
    assert table.column('stamp_ns').to_pylist() == [int(row[0]) for row in rows]
    for column in header[2:]:
        got = np.array([np.nan if x is None else x for x in table.column(column).to_pylist()])
        expected = numbers(rows, header, [column])[:, 0]
        assert np.array_equal(got, expected, equal_nan=True), column


def test_tf_input_exports_one_row_per_lookup(tmp_path):
    """The tf input type: /tf and /tf_static together, one row per sample the lookup gives."""
    from geometry_msgs.msg import TransformStamped
    from rotation_node.bag.writing.writer import BagWriter
    from tf2_msgs.msg import TFMessage

    def edge(parent, child, rotation, stamp_ns):
        msg = TransformStamped()
        msg.header.frame_id, msg.child_frame_id = parent, child
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
        r = msg.transform.rotation
        r.x, r.y, r.z, r.w = (float(c) for c in rotation.as_quat())
        return msg

    start = 1_700_000_000 * 10**9
    mount = Rotation.from_euler('xyz', [0.0, 0.0, 30.0], degrees=True)
    yaws = [0.1 * k for k in range(6)]
    bag = tmp_path / 'tf.mcap'
    with BagWriter(bag) as writer:
        writer.write('/tf_static', TFMessage(transforms=[edge('odom', 'base_link', mount, 0)]),
                     start)
        for k, yaw in enumerate(yaws):
            stamp = start + k * 10**7
            writer.write('/tf', TFMessage(transforms=[
                edge('map', 'odom', Rotation.from_euler('z', yaw), stamp)]), stamp + 1)
    out = tmp_path / 'tf.csv'
    params = params_file(tmp_path, input_type='tf', outputs=['euler'],
                         tf={'parent_frame': 'map', 'child_frame': 'base_link'})
    assert main(['export', str(bag), str(out), '--params', str(params)]) == 0
    header, rows = read_csv(out)
    assert header == ['stamp_ns', 'frame_id', 'roll', 'pitch', 'yaw']
    assert [int(row[0]) for row in rows] == [start + k * 10**7 for k in range(6)]
    assert {row[1] for row in rows} == {'map'}
    yaw = numbers(rows, header, ['yaw'])[:, 0]
    assert np.abs(yaw - (np.array(yaws) + np.radians(30.0))).max() < 1e-12


def test_a_table_inside_the_input_bag_is_refused(imu_bag, tmp_path, capsys):
    """The outputs convert refuses (the input, inside it) export refuses too: the same check."""
    path, _ = imu_bag
    params = params_file(tmp_path, input_type='imu', outputs=['euler'])
    before = sorted(os.listdir(path))
    assert main(['export', str(path), str(path / 'imu.csv'), '--params', str(params)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'is inside the input bag' in err[0]
    assert sorted(os.listdir(path)) == before
