"""Tests of rotation_node.scene.cli: the rotation_scene command."""
import os
import signal
import subprocess

from fault_helpers import FULL_DISKS, linear_scan, small_disk, wait_for
import numpy as np
import pytest
from ros_harness import script
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.scene.cli import main

SCENES_DIR = os.path.join(os.path.dirname(__file__), '..', 'config', 'scenes')
CONING = os.path.join(SCENES_DIR, 'coning.yaml')


def test_writes_the_bag_and_says_what_it_wrote(tmp_path, capsys):
    out = tmp_path / 'coning.mcap'
    handlers = [signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)]
    assert main([CONING, str(out)]) == 0
    assert [signal.getsignal(n) for n in (signal.SIGINT, signal.SIGTERM)] == handlers
    printed = capsys.readouterr().out
    assert '401 samples' in printed and 'motion coning' in printed
    with BagReader(out) as reader:
        assert reader.message_counts == {'/imu': 401, '/truth/orientation': 401,
                                         '/truth/angular_velocity': 401}


@pytest.mark.slow
def test_same_seed_gives_a_byte_identical_bag_across_processes(tmp_path):
    """Separate processes, so nothing (heap contents, caches) is shared between the runs."""
    scene = os.path.join(SCENES_DIR, 'every_effect.yaml')
    paths = []
    for run, seed in (('a', '5'), ('b', '5')):
        (tmp_path / run).mkdir()
        paths.append(tmp_path / run / 'out.mcap')   # rosbag2 metadata records the file name
        done = subprocess.run([script('rotation_scene'), scene, str(paths[-1]), '--seed', seed],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
    assert paths[0].read_bytes() == paths[1].read_bytes()
    (tmp_path / 'c').mkdir()
    assert main([scene, str(tmp_path / 'c' / 'out.mcap'), '--seed', '6']) == 0
    assert (tmp_path / 'c' / 'out.mcap').read_bytes() != paths[0].read_bytes()


BAD_SCENES = {
    'negative_rate': ('duration: 1.0\nrate: -5\nmotion: {type: coning, half_angle: 0.1, '
                      'frequency: 1.0}\n', 'rate: must be > 0'),
    'unknown_effect': ('duration: 1.0\nrate: 5\nmotion: {type: coning, half_angle: 0.1, '
                       'frequency: 1.0}\neffects: {gyro_drift: {std: 1}}\n',
                       'effects.gyro_drift: unknown effect'),
    'missing_field': ('duration: 1.0\nrate: 5\nmotion: {type: coning, half_angle: 0.1}\n',
                      'motion.frequency: missing'),
    'not_yaml': ('duration: [1.0\n', 'invalid YAML'),
}


@pytest.mark.parametrize('name', BAD_SCENES)
def test_bad_scene_one_line_error_and_no_output(tmp_path, capsys, name):
    text, message = BAD_SCENES[name]
    scene = tmp_path / 'scene.yaml'
    scene.write_text(text)
    out = tmp_path / 'out.mcap'
    assert main([str(scene), str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith('rotation_scene: error: ') and err.count('\n') == 1
    assert message in err
    assert sorted(os.listdir(tmp_path)) == ['scene.yaml']


def test_missing_scene_file(tmp_path, capsys):
    assert main([str(tmp_path / 'absent.yaml'), str(tmp_path / 'out.mcap')]) == 1
    assert 'cannot read it' in capsys.readouterr().err
    assert os.listdir(tmp_path) == []


def test_existing_output_needs_force(tmp_path, capsys):
    out = tmp_path / 'out.mcap'
    out.write_bytes(b'keep me')
    assert main([CONING, str(out)]) == 1
    assert '--force' in capsys.readouterr().err
    assert out.read_bytes() == b'keep me'
    assert main([CONING, str(out), '--force']) == 0
    with BagReader(out) as reader:
        assert reader.message_counts['/imu'] == 401


@pytest.mark.parametrize('seed', ['-1', 'x', '1.5'])
def test_bad_seed_is_a_usage_error(tmp_path, capsys, seed):
    with pytest.raises(SystemExit) as info:
        main([CONING, str(tmp_path / 'out.mcap'), '--seed', seed])
    assert info.value.code == 2
    assert '--seed' in capsys.readouterr().err
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
def test_console_script_reports_errors_with_status_1(tmp_path):
    out = tmp_path / 'out.mcap'
    out.write_bytes(b'')
    failed = subprocess.run([script('rotation_scene'), CONING, str(out)],
                            capture_output=True, text=True, timeout=120)
    assert failed.returncode == 1
    assert failed.stderr.startswith('rotation_scene: error: ') and failed.stderr.count('\n') == 1


LONG_SCENE = """duration: 10.0
rate: 1000.0
topic: /imu
motion: {type: coning, half_angle: 0.2, frequency: 3.0}
effects: {gyro_noise: {std: 0.01}, dropped_messages: {probability: 0.1}}
"""


@pytest.fixture(scope='module')
def long_scene(tmp_path_factory):
    """Return a 10 001-sample scene and its complete bag, written once in-process."""
    directory = tmp_path_factory.mktemp('long_scene')
    (directory / 'scene.yaml').write_text(LONG_SCENE)
    (directory / 'reference').mkdir()
    assert main([str(directory / 'scene.yaml'),
                 str(directory / 'reference' / 'out.mcap')]) == 0
    return directory


def _scene_process(long_scene, output):
    return subprocess.Popen([script('rotation_scene'), str(long_scene / 'scene.yaml'),
                             str(output)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _size(path):
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


@pytest.mark.slow
def test_sigkill_leaves_a_part_holding_a_prefix_of_the_bag(long_scene, tmp_path):
    reference = (long_scene / 'reference' / 'out.mcap').read_bytes()
    threshold = int(np.random.default_rng(11).uniform(0.1, 0.6) * len(reference))
    output = tmp_path / 'out.mcap'
    process = _scene_process(long_scene, output)
    try:
        assert wait_for(lambda: _size(f'{output}.part') >= threshold
                        or process.poll() is not None, timeout=90)
        process.send_signal(signal.SIGKILL)
    finally:
        process.communicate(timeout=30)
    assert process.returncode == -signal.SIGKILL and not output.exists()
    written = (tmp_path / 'out.mcap.part').read_bytes()
    assert len(written) >= threshold and written == reference[:len(written)]
    recovered = linear_scan(tmp_path / 'out.mcap.part')
    assert recovered and recovered == linear_scan(
        long_scene / 'reference' / 'out.mcap')[:len(recovered)]


@pytest.mark.slow
@pytest.mark.parametrize('stop', [signal.SIGTERM, signal.SIGINT], ids=lambda s: s.name)
def test_signal_removes_the_part_and_says_so_on_one_line(long_scene, tmp_path, stop):
    output = tmp_path / 'out'
    process = _scene_process(long_scene, output)
    try:
        assert wait_for(lambda: _size(tmp_path / 'out.part' / 'out_0.mcap') > 0
                        or process.poll() is not None, timeout=90)
        process.send_signal(stop)
    finally:
        _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + stop, stderr
    assert stderr.splitlines() == [f'rotation_scene: interrupted ({stop.name})']
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
@pytest.mark.parametrize('disk', FULL_DISKS)
def test_full_disk_is_one_line_and_leaves_nothing(long_scene, tmp_path, monkeypatch, capsys,
                                                  disk):
    with small_disk(disk, tmp_path / 'small', 256 * 1024, monkeypatch) as small:
        status = main([str(long_scene / 'scene.yaml'), str(small / 'out')])
        assert os.listdir(small) == []
    assert status == 1
    line, = capsys.readouterr().err.splitlines()
    assert line.startswith('rotation_scene: error: disk full writing ')
