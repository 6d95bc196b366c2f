"""
Tests of rotation_node.bag.batch: many bags in parallel processes and on Dask.

Each output must be the bag that converting its input alone gives (the same
messages and metadata); a bad bag fails on its own line without stopping the others, and the
exit status says whether any failed.
"""
import os
import sqlite3

from bag_helpers import imu_messages, serialized_rows, write_rosbag2
from mcap.reader import make_reader
import pytest
from rotation_node.bag import batch
from rotation_node.bag.batch import (
    batch_output_path, batch_output_paths, convert_bag, convert_bags, convert_bags_on_dask)
from rotation_node.bag.cli import main
from rotation_node.bag.convert import convert
from rotation_node.bag.reading.reader import open_bag
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters

PARAMS = NodeParameters(input_type='imu', outputs=('euler', 'quaternion'))
PARAMS_YAML = """rotation_node:
  ros__parameters:
    input_type: imu
    outputs: [euler, quaternion]
"""


@pytest.fixture
def inputs(tmp_path, rng):
    """Three good bags of different formats and one bad one: [(path, good)]."""
    directory = tmp_path / 'in'
    directory.mkdir()
    bags = [
        (write_rosbag2(directory / 'day1', serialized_rows('/imu', imu_messages(rng, 50))), True),
        (write_rosbag2(directory / 'day2', serialized_rows('/imu', imu_messages(rng, 60)),
                       storage='sqlite3', compression='message'), True),
        (directory / 'broken.mcap', False),
        (write_rosbag2(directory / 'day3', serialized_rows('/imu', imu_messages(rng, 70)),
                       compression='file'), True),
    ]
    (directory / 'broken.mcap').write_text('not a bag\n')
    return [(str(path), good) for path, good in bags]


def _expected_outputs(tmp_path, inputs):
    """Each good input converted alone: {output name: messages}."""
    expected = {}
    for path, good in inputs:
        if good:
            output = tmp_path / 'alone' / (os.path.basename(path) + '.mcap')
            output.parent.mkdir(exist_ok=True)
            convert(path, output, PARAMS)
            expected[os.path.basename(path)] = _messages(output)
    return expected


def _messages(path):
    with open_bag(path) as bag:
        return bag.topic_metadata, [(m.topic, m.data, m.log_time_ns, m.publish_time_ns)
                                    for m in bag.messages()]


def _outputs(directory):
    """{name: messages} of the outputs in ``directory``."""
    return {name: _messages(directory / name) for name in sorted(os.listdir(directory))}


def test_output_names():
    assert batch_output_path('runs/day1/', 'out') == os.path.join('out', 'day1')
    assert batch_output_path('a/imu.mcap', 'out') == os.path.join('out', 'imu')
    assert batch_output_path('x_0.mcap.zstd', 'out') == os.path.join('out', 'x_0')
    assert batch_output_path('old.bag', 'out') == os.path.join('out', 'old')
    with pytest.raises(BagError, match='a/x.mcap and b/x.bag would both be written to'):
        batch_output_paths(['a/x.mcap', 'b/x.bag'], 'out')


@pytest.mark.slow
def test_parallel_processes_one_line_per_bag_and_a_bad_bag_fails_alone(
        tmp_path, inputs, capsys):
    expected = _expected_outputs(tmp_path, inputs)
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    out = tmp_path / 'out'
    status = main(['convert', *[path for path, _ in inputs], str(out),
                   '--params', str(tmp_path / 'params.yaml'), '--jobs', '2'])
    lines = capsys.readouterr().err.splitlines()
    assert status == 1
    assert lines[-1] == 'rotation_bag convert: error: 1 of 4 bags failed'
    per_bag = sorted(lines[:-1])
    assert len(per_bag) == 4
    for path, good in inputs:
        line, = [line for line in per_bag if line.startswith(path)]
        if good:
            assert line.startswith(f'{path} -> {out / os.path.basename(path)}: rosbag2 '
                                   'directory (')
            assert '; /imu ' in line and ' messages (/imu/euler, /imu/quaternion)' in line
        else:
            assert line == f'{path}: error: text file, not a bag (readable: rosbag2 ' \
                           'directories, MCAP, sqlite3 and ROS 1 bags)'
    assert _outputs(out) == expected


def test_good_bags_exit_zero(tmp_path, inputs, capsys):
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    good = [path for path, ok in inputs if ok]
    out = tmp_path / 'out'
    out.mkdir()   # IN OUTDIR: an existing directory that is not a bag
    status = main(['convert', good[0], str(out), '--params', str(tmp_path / 'params.yaml'),
                   '--compression', 'lz4'])
    assert status == 0
    assert capsys.readouterr().err.splitlines()[-1] == f'converted 1 bags into {out}'
    assert os.listdir(out) == ['day1']
    # Each output is a rosbag2 directory, its chunks compressed as asked.
    assert sorted(os.listdir(out / 'day1')) == ['day1_0.mcap', 'metadata.yaml']
    with open(out / 'day1' / 'day1_0.mcap', 'rb') as stream:
        summary = make_reader(stream).get_summary()
    assert {index.compression for index in summary.chunk_indexes} == {'lz4'}


@pytest.mark.slow
def test_same_tasks_on_a_dask_local_cluster(tmp_path, inputs):
    """The documented Dask route: every bag a task on worker processes, bounded waits."""
    from distributed import Client, LocalCluster
    expected = _expected_outputs(tmp_path, inputs)
    out = tmp_path / 'dask'
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None, silence_logs=40) as cluster, \
            Client(cluster, timeout=60) as client:
        results = convert_bags_on_dask(client, [path for path, _ in inputs], str(out), PARAMS,
                                       timeout=240)
    assert sorted((r.input_path, r.ok) for r in results) == sorted(inputs)
    assert _outputs(out) == expected


def test_local_processes_and_dask_give_the_same_results(tmp_path, inputs):
    local = convert_bags([path for path, _ in inputs], str(tmp_path / 'a'), PARAMS, jobs=1)
    assert [(r.input_path, r.ok) for r in local] == inputs
    with pytest.raises(BagError, match='jobs must be a positive integer'):
        convert_bags([inputs[0][0]], str(tmp_path / 'b'), PARAMS, jobs=0)


@pytest.fixture
def damaged_in_the_middle(tmp_path, rng):
    """good1 good2 damaged good3: the damaged one a sqlite3 bag with a TEXT message row."""
    directory = tmp_path / 'in'
    directory.mkdir()
    bags = [(write_rosbag2(directory / name, serialized_rows('/imu', imu_messages(rng, count)),
                           storage=storage), True)
            for name, count, storage in [('good1', 40, 'mcap'), ('good2', 50, 'sqlite3'),
                                         ('damaged', 60, 'sqlite3'), ('good3', 70, 'mcap')]]
    with sqlite3.connect(directory / 'damaged' / 'damaged.db3') as database:
        database.execute("UPDATE messages SET data = 'lost' WHERE id = 30")
    database.close()
    bags[2] = (bags[2][0], False)
    return [(str(path), good) for path, good in bags]


@pytest.mark.slow
@pytest.mark.parametrize('jobs', ['1', '2'])
def test_a_damaged_bag_in_the_middle_stops_nothing(tmp_path, damaged_in_the_middle, capsys,
                                                   jobs):
    """Every input gets its line, good bags keep their outputs, the exit status is 1."""
    inputs = damaged_in_the_middle
    expected = _expected_outputs(tmp_path, inputs)
    (tmp_path / 'params.yaml').write_text(PARAMS_YAML)
    out = tmp_path / 'out'
    status = main(['convert', *[path for path, _ in inputs], str(out),
                   '--params', str(tmp_path / 'params.yaml'), '--jobs', jobs])
    lines = capsys.readouterr().err.splitlines()
    assert status == 1
    assert lines[-1] == 'rotation_bag convert: error: 1 of 4 bags failed'
    assert len(lines) == 5
    for path, good in inputs:
        line, = [line for line in lines[:-1] if line.startswith(path)]
        if not good:
            assert line == (f'{path}: error: {path}/damaged.db3 is corrupt: messages table, '
                            'row id 30: data is TEXT, not a BLOB')
    assert _outputs(out) == expected


def test_convert_bag_reports_a_damaged_input(tmp_path, damaged_in_the_middle):
    """The unit of work of processes and Dask returns a result, it does not raise."""
    path, _ = damaged_in_the_middle[2]
    result = convert_bag(path, str(tmp_path / 'damaged.mcap'), PARAMS)
    assert not result.ok and 'row id 30: data is TEXT, not a BLOB' in result.line
    assert not os.path.exists(tmp_path / 'damaged.mcap')


def test_an_error_of_the_package_surfaces_after_the_other_bags(tmp_path, inputs, monkeypatch):
    """Not a bad bag but a bug: raised as itself, once every other bag is converted."""
    def convert_bag_with_a_bug(input_path, *args, **kwargs):
        if input_path.endswith('day2'):
            raise KeyError('a programming error')
        return convert_bag(input_path, *args, **kwargs)

    monkeypatch.setattr(batch, 'convert_bag', convert_bag_with_a_bug)
    lines = []
    with pytest.raises(KeyError, match='a programming error'):
        convert_bags([path for path, _ in inputs], str(tmp_path / 'out'), PARAMS, jobs=1,
                     on_result=lambda result: lines.append((result.input_path, result.ok)))
    assert lines == [(path, good and not path.endswith('day2')) for path, good in inputs]
    assert sorted(os.listdir(tmp_path / 'out')) == ['day1', 'day3']
