"""
Tests of rotation_node.bag.writing.part_output: exclusive, atomic renames, what a crash leaves.

Fault injection on real ``rotation_bag convert`` processes: SIGKILL at a
seeded random point of the output (the ``.part`` then holds a byte prefix of
the complete bag, whose messages a linear scan recovers in order), SIGTERM (no
file left, one line, status 143, or, if it came after the last message, the
complete bag; for many bags with --jobs, the workers stop too), two converts
of the same output at once (exactly one fails, with one line), and a full disk
(one line, nothing left).
Also: the output's chunk compression follows the input's unless told.
"""
import os
import signal
import subprocess
import time

from fault_helpers import FULL_DISKS, linear_scan, small_disk, wait_for
from mcap.reader import make_reader
import numpy as np
import pytest
from ros_harness import script
from rotation_node.bag.cli import main
from rotation_node.bag.convert import convert
from rotation_node.bag.writing.part_output import rename_exclusive, rename_replacing
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.parameters import parameters_from_yaml
from rotation_node.wire.cdr import message_encoder
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.timeout(120)

PARAMS = """rotation_node:
  ros__parameters:
    input_type: imu
    outputs: [euler, matrix]
"""
T0 = 1_700_000_000_000_000_000


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    """Return an Imu bag of 20000 messages (~7 MB), the parameters file and its conversion."""
    directory = tmp_path_factory.mktemp('convert_faults')
    rng = np.random.default_rng(20261123)
    encode = message_encoder('sensor_msgs/msg/Imu')
    variants = []
    for q in rng.normal(size=(500, 4)):
        msg = Imu()
        msg.header.frame_id = 'imu_link'
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = (
            float(c) for c in q / np.linalg.norm(q))
        variants.append(encode(msg))
    with BagWriter(directory / 'in.mcap', compression='none') as writer:
        for k in range(20000):
            writer.write_serialized('/imu', 'sensor_msgs/msg/Imu', variants[k % 500],
                                    T0 + 1_000_000 * k)
    (directory / 'params.yaml').write_text(PARAMS)
    os.mkdir(directory / 'reference')
    convert(directory / 'in.mcap', directory / 'reference' / 'out.mcap',
            parameters_from_yaml(directory / 'params.yaml'))
    return directory


def _convert(workspace, output, *args):
    return subprocess.Popen(
        [script('rotation_bag'), 'convert', workspace / 'in.mcap', output, '--params',
         workspace / 'params.yaml', *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _size(path):
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


@pytest.mark.slow
@pytest.mark.parametrize('seed', [1])
def test_sigkill_leaves_a_part_holding_a_prefix_of_the_bag(workspace, tmp_path, seed):
    reference = (workspace / 'reference' / 'out.mcap').read_bytes()
    threshold = int(np.random.default_rng(seed).uniform(0.05, 0.6) * len(reference))
    output = tmp_path / 'out.mcap'
    process = _convert(workspace, output)
    try:
        assert wait_for(lambda: _size(f'{output}.part') >= threshold or process.poll() is not None,
                        timeout=90)
        process.send_signal(signal.SIGKILL)
    finally:
        process.communicate(timeout=30)
    part = tmp_path / 'out.mcap.part'
    assert process.returncode == -signal.SIGKILL and not output.exists()
    written = part.read_bytes()
    # Chunks are cut by size only: the killed output is byte for byte the start of the
    # complete one, and its messages are the first ones, in order.
    assert len(written) >= threshold and written == reference[:len(written)]
    recovered = linear_scan(part)
    assert len(recovered) > 100
    assert recovered == linear_scan(workspace / 'reference' / 'out.mcap')[:len(recovered)]


def _sigterm_once_written(process, storage_file):
    """SIGTERM ``process`` once ``storage_file`` (in a ``.part``) holds 1 MiB; return stderr."""
    try:
        assert wait_for(lambda: _size(storage_file) > 1 << 20 or process.poll() is not None,
                        timeout=90)
        process.send_signal(signal.SIGTERM)
    finally:
        _, stderr = process.communicate(timeout=60)
    return stderr


@pytest.mark.slow
def test_sigterm_removes_the_part_and_says_so_on_one_line(workspace, tmp_path):
    process = _convert(workspace, tmp_path / 'out')
    stderr = _sigterm_once_written(process, tmp_path / 'out.part' / 'out_0.mcap')
    assert process.returncode == 143, stderr
    assert stderr.splitlines() == ['rotation_bag convert: interrupted (SIGTERM)']
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
def test_sigterm_at_any_moment_leaves_nothing_or_the_complete_bag(workspace, tmp_path):
    """SIGTERM spread over a whole run: 143, one line and nothing; or the complete output."""
    reference = linear_scan(workspace / 'reference' / 'out.mcap')
    started = time.monotonic()
    process = _convert(workspace, tmp_path / 'timed')
    process.communicate(timeout=90)
    duration = time.monotonic() - started
    outcomes = set()
    for k in range(6):
        output = tmp_path / f'out{k}'
        process = _convert(workspace, output)
        time.sleep(duration * (k + 0.5) / 6)
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=60)
        left = sorted(os.listdir(tmp_path))
        assert f'out{k}.part' not in left, left
        if process.returncode == 143:
            assert stderr.splitlines() in (['rotation_bag convert: interrupted (SIGTERM)'],
                                           ['rotation_bag: interrupted while starting (SIGTERM)'])
        else:   # -15: before Python installed any handler, or while it exits
            assert process.returncode in (0, -signal.SIGTERM), stderr
        if f'out{k}' in left:
            assert process.returncode != 143
            assert linear_scan(output / f'out{k}_0.mcap') == reference
        outcomes.add(process.returncode)
    assert 143 in outcomes, 'no run was interrupted'


@pytest.mark.slow
def test_sigterm_stops_a_many_bag_convert_and_its_workers(workspace, tmp_path):
    """SIGTERM to ``convert A B C OUTDIR --jobs 2``: the workers stop too, no .part is left."""
    inputs = []
    for name in ('a', 'b', 'c'):
        os.symlink(workspace / 'in.mcap', tmp_path / f'{name}.mcap')
        inputs.append(tmp_path / f'{name}.mcap')
    many = tmp_path / 'many'
    process = subprocess.Popen(
        [script('rotation_bag'), 'convert', *inputs, many, '--params',
         workspace / 'params.yaml', '--jobs', '2'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stderr = _sigterm_once_written(process, many / 'a.part' / 'a_0.mcap')
    assert process.returncode == 143, stderr
    *done, last = stderr.splitlines()
    assert last == 'rotation_bag convert: interrupted (SIGTERM)', stderr
    assert all(' -> ' in line for line in done), stderr
    # A bag that finished before the signal is complete and has its line; nothing else is left.
    finished = sorted(os.listdir(many))
    assert [line.split(' -> ')[1].split(':')[0] for line in done] == [
        str(many / name) for name in finished]
    for name in finished:
        assert sorted(os.listdir(many / name)) == ['metadata.yaml', f'{name}_0.mcap']


@pytest.mark.slow
def test_two_concurrent_converts_one_fails_with_one_line(workspace, tmp_path):
    output = tmp_path / 'same'
    processes = [_convert(workspace, output) for _ in range(2)]
    results = [(p.wait(timeout=100), p.communicate()[1]) for p in processes]
    assert sorted(code for code, _ in results) == [0, 1], results
    (error,) = [stderr for code, stderr in results if code == 1]
    line, = error.splitlines()
    assert line.startswith('rotation_bag convert: error: ') and (
        'same.part exists' in line or 'same already exists' in line
        or 'created by another process' in line), line
    assert os.listdir(tmp_path) == ['same']
    assert (linear_scan(output / 'same_0.mcap')
            == linear_scan(workspace / 'reference' / 'out.mcap'))


@pytest.mark.slow
@pytest.mark.parametrize('disk', FULL_DISKS)
def test_full_disk_is_one_line_and_leaves_nothing(workspace, tmp_path, monkeypatch, capsys,
                                                  disk):
    with small_disk(disk, tmp_path / 'small', 2 << 20, monkeypatch) as small:
        status = main(['convert', str(workspace / 'in.mcap'), str(small / 'out'),
                       '--params', str(workspace / 'params.yaml')])
        assert os.listdir(small) == []
    assert status == 1
    line, = capsys.readouterr().err.splitlines()
    assert line.startswith('rotation_bag convert: error: disk full writing ')
    assert (workspace / 'in.mcap').stat().st_size > 0


def test_rename_exclusive_never_replaces(tmp_path):
    for kind in ('file', 'directory'):
        source, destination = tmp_path / f'{kind}.new', tmp_path / f'{kind}.old'
        for path in (source, destination):
            if kind == 'file':
                path.write_text(path.name)
            else:
                os.mkdir(path)   # an empty directory: plain rename(2) would replace it
        with pytest.raises(FileExistsError):
            rename_exclusive(str(source), str(destination))
        assert source.exists() and destination.exists()
    os.symlink(tmp_path / 'nowhere', tmp_path / 'dangling')
    with pytest.raises(FileExistsError):
        rename_exclusive(str(tmp_path / 'file.new'), str(tmp_path / 'dangling'))


def test_rename_replacing_swaps_files_and_directories(tmp_path):
    (tmp_path / 'new').mkdir()
    (tmp_path / 'new' / 'a').write_text('new')
    (tmp_path / 'old').mkdir()
    (tmp_path / 'old' / 'b').write_text('old')
    rename_replacing(str(tmp_path / 'new'), str(tmp_path / 'old'))
    assert os.listdir(tmp_path) == ['old'] and os.listdir(tmp_path / 'old') == ['a']
    (tmp_path / 'file').write_text('file')
    rename_replacing(str(tmp_path / 'file'), str(tmp_path / 'old'))
    assert os.listdir(tmp_path) == ['old'] and (tmp_path / 'old').read_text() == 'file'


@pytest.mark.slow
@pytest.mark.parametrize('option, expected', [(None, 'lz4'), ('zstd', 'zstd'), ('none', '')])
def test_convert_compresses_as_its_input_unless_told(workspace, tmp_path, option, expected):
    source = tmp_path / 'lz4.mcap'
    with BagWriter(source, compression='lz4') as writer:
        for topic, _, _, data in linear_scan(workspace / 'in.mcap')[:3000]:
            writer.write_serialized(topic, 'sensor_msgs/msg/Imu', data, T0)
    output = tmp_path / 'out.mcap'
    convert(source, output, parameters_from_yaml(workspace / 'params.yaml'),
            compression=option)
    with open(output, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    assert {index.compression for index in summary.chunk_indexes} == {expected}
    assert len(linear_scan(output)) == 3 * 3000   # the input and its two outputs
