"""Tests of rotation_node.scene.reference: the second stream of a scene, against its truth."""
import json
import os

import numpy as np
import pytest
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.errors import BagError
from rotation_node.scene import cli, spec
from rotation_node.scene.reference import (
    reference_index_range, reference_stamps_ns, truth_path, TRUTH_SUFFIX)
from rotation_node.scene.simulator import simulate, write_bag, write_scene_bag
from scipy.spatial.transform import Rotation, Slerp

START_TIME = 1735689600.0
MOUNTING = Rotation.from_euler('xyz', [20.0, -35.0, 110.0], degrees=True).as_quat()
WORLD = Rotation.from_euler('xyz', [3.0, -2.0, 47.0], degrees=True).as_quat()


def reference_scene(motion, *, time_offset=0.0123, rate=120.0, message='pose', noise=0.0,
                    duration=2.0, sensor_rate=200.0):
    return spec.scene_from_dict({
        'duration': duration, 'rate': sensor_rate, 'motion': motion,
        'reference': {'rate': rate, 'topic': '/mocap/pose', 'message': message,
                      'time_offset': time_offset, 'mounting': MOUNTING.tolist(),
                      'world_alignment': WORLD.tolist(), 'orientation_noise': noise}})


CONSTANT_RATE = {'type': 'constant_rate', 'orientation': [0.2, -0.1, 0.4, 0.8888194417315589],
                 'angular_velocity': [0.7, -1.3, 2.1]}
TORQUE_FREE = {'type': 'torque_free', 'inertia': [1, 2, 3], 'orientation': [0, 0, 0, 1],
               'angular_velocity': [0.3, 1.0, 0.2]}


def read(path, topic):
    """Return stamps (ns), quaternions, angular velocities (Imu) and log times of a topic."""
    stamps, quaternions, rates, log_times = [], [], [], []
    with BagReader(path) as reader:
        for record in reader.messages([topic]):
            msg = record.message()
            log_times.append(record.log_time_ns)
            stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            q = msg.pose.orientation if hasattr(msg, 'pose') else msg.orientation
            quaternions.append([q.x, q.y, q.z, q.w])
            if hasattr(msg, 'angular_velocity'):
                w = msg.angular_velocity
                rates.append([w.x, w.y, w.z])
    return np.array(stamps), np.array(quaternions), np.array(rates), np.array(log_times)


def oracle_constant_rate(t):
    """Return the constant-rate motion at times t, by scipy: q0 * exp(w t)."""
    q0 = Rotation.from_quat(CONSTANT_RATE['orientation'])
    return q0 * Rotation.from_rotvec(np.outer(t, CONSTANT_RATE['angular_velocity']))


@pytest.mark.parametrize('time_offset', [0.0123, -0.25, 0.0])
def test_pose_stream_is_world_times_truth_at_offset_times_mounting(tmp_path, time_offset):
    scene = reference_scene(CONSTANT_RATE, time_offset=time_offset)
    path = tmp_path / 'scene.mcap'
    write_scene_bag(scene, path)
    stamps, q, _, log_times = read(path, '/mocap/pose')
    assert np.array_equal(stamps, log_times)
    t = (stamps - int(START_TIME) * 1_000_000_000) / 1e9
    # Every stamp and every motion time within the scene, and none left out.
    assert t.min() >= 0.0 and t.max() <= scene.duration
    assert (t + time_offset).min() >= -1e-9 and (t + time_offset).max() <= scene.duration + 1e-9
    expected_count = sum(1 for k in range(0, 1000)
                         if 0 <= k / 120.0 <= 2.0 and -1e-9 <= k / 120.0 + time_offset <= 2.0)
    assert len(stamps) == expected_count
    expected = (Rotation.from_quat(WORLD) * oracle_constant_rate(t + time_offset)
                * Rotation.from_quat(MOUNTING))
    error = (expected.inv() * Rotation.from_quat(q)).magnitude()
    assert error.max() < 1e-12


def test_reference_against_the_estimate_stream_by_its_own_convention(tmp_path):
    """R_ref(t) = W R_est(t + dt) M, R_est interpolated (slerp) in the noiseless sensor stream."""
    dt = 0.0123
    scene = reference_scene(TORQUE_FREE, time_offset=dt, message='imu')
    path = tmp_path / 'scene.mcap'
    write_scene_bag(scene, path)
    truth = json.loads(open(truth_path(path)).read())
    est_stamps, est_q, est_w, _ = read(path, truth['estimate']['topic'])
    ref_stamps, ref_q, ref_w, _ = read(path, truth['reference']['topic'])
    W = Rotation.from_quat(truth['world_alignment']['quaternion'])
    M = Rotation.from_quat(truth['mounting']['quaternion'])
    offset = truth['time_offset_s']
    est_t, ref_t = est_stamps / 1e9, ref_stamps / 1e9
    estimate = Slerp(est_t - est_t[0], Rotation.from_quat(est_q))(ref_t + offset - est_t[0])
    error = ((W * estimate * M).inv() * Rotation.from_quat(ref_q)).magnitude()
    # Interpolation over 5 ms at about 1 rad/s: (w h)^2 / 8 ~ 3e-6 rad.
    assert error.max() < 1e-5
    # Imu reference: the body rate in the reference body, M^T w(t + dt).
    w_at = np.array([np.interp(ref_t + offset, est_t, est_w[:, i]) for i in range(3)]).T
    assert np.abs(ref_w - M.inv().apply(w_at)).max() < 1e-3
    assert truth['reference']['messages'] == len(ref_stamps)
    assert truth['estimate']['messages'] == len(est_stamps)


@pytest.mark.slow
def test_reference_noise_is_body_side_with_the_std_asked(tmp_path):
    scene = reference_scene(CONSTANT_RATE, noise=0.01, rate=500.0, duration=4.0)
    path = tmp_path / 'scene.mcap'
    write_scene_bag(scene, path)
    stamps, q, _, _ = read(path, '/mocap/pose')
    t = (stamps - int(START_TIME) * 1_000_000_000) / 1e9
    clean = (Rotation.from_quat(WORLD) * oracle_constant_rate(t + 0.0123)
             * Rotation.from_quat(MOUNTING))
    body_noise = (clean.inv() * Rotation.from_quat(q)).as_rotvec()
    std = body_noise.std(axis=0)
    assert np.all(np.abs(std - 0.01) < 0.1 * 0.01), std   # ~2000 samples: within 10 %
    assert np.abs(body_noise.mean(axis=0)).max() < 0.1 * 0.01
    truth = json.loads(open(truth_path(path)).read())
    assert truth['noise']['reference_orientation_std_rad'] == 0.01


def test_streamed_bag_and_truth_equal_the_two_steps(tmp_path):
    scene = reference_scene(TORQUE_FREE, noise=0.002, message='imu')
    streamed, whole = tmp_path / 'streamed' / 'bag.mcap', tmp_path / 'whole' / 'bag.mcap'
    streamed.parent.mkdir()
    whole.parent.mkdir()
    write_scene_bag(scene, streamed, seed=5, block_samples=37)
    write_bag(simulate(scene, 5), whole)
    assert streamed.read_bytes() == whole.read_bytes()
    assert open(truth_path(streamed)).read() == open(truth_path(whole)).read()
    with BagReader(streamed) as reader:
        log_times = [record.log_time_ns for record in reader.messages()]
    assert log_times == sorted(log_times)


def test_reference_stamps_and_range():
    scene = reference_scene(CONSTANT_RATE, time_offset=-0.5, rate=10.0)
    first, stop = reference_index_range(scene)
    assert (first, stop) == (5, 21)   # t in [0.5, 2.0]: the motion at t - 0.5 in [0, 1.5]
    stamps = reference_stamps_ns(scene, first, stop)
    assert stamps[0] == int(START_TIME) * 1_000_000_000 + 500_000_000
    assert np.all(np.diff(stamps) == 100_000_000)


def test_scene_without_reference_writes_no_truth_file(tmp_path):
    scene = spec.scene_from_dict({'duration': 0.1, 'rate': 10.0, 'motion': CONSTANT_RATE})
    write_scene_bag(scene, tmp_path / 'plain.mcap')
    assert sorted(os.listdir(tmp_path)) == ['plain.mcap']


def test_existing_truth_file_is_one_line_and_nothing_is_written(tmp_path, capsys):
    scene_file = tmp_path / 'scene.yaml'
    scene_file.write_text(
        'duration: 0.5\nrate: 50.0\nmotion: {type: coning, half_angle: 0.2, frequency: 3.0}\n'
        'reference: {rate: 30.0}\n')
    out = tmp_path / 'out.mcap'
    (tmp_path / ('out.mcap' + TRUTH_SUFFIX)).write_text('kept')
    assert cli.main([str(scene_file), str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'out.mcap.truth.json already exists' in err[0]
    assert sorted(os.listdir(tmp_path)) == ['out.mcap.truth.json', 'scene.yaml']
    assert (tmp_path / 'out.mcap.truth.json').read_text() == 'kept'
    assert cli.main([str(scene_file), str(out), '--force']) == 0
    assert 'reference stream: 16 messages on /reference/pose' in capsys.readouterr().out
    truth = json.loads((tmp_path / 'out.mcap.truth.json').read_text())
    assert truth['reference']['messages'] == 16


def test_failed_bag_leaves_no_truth_file(tmp_path):
    scene = reference_scene(CONSTANT_RATE)
    (tmp_path / 'taken.mcap').write_text('not mine')
    with pytest.raises(BagError):
        write_scene_bag(scene, tmp_path / 'taken.mcap')
    assert sorted(os.listdir(tmp_path)) == ['taken.mcap']
