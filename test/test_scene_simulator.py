"""Tests of rotation_node.scene.simulator: arrays -> messages -> MCAP bag."""
import os
import tracemalloc

import numpy as np
import pytest

from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.errors import BagError
from rotation_node.scene import spec
from rotation_node.scene.simulator import (sample_stamps_ns, simulate, simulate_blocks,
                                           write_bag, write_scene_bag)

SCENES_DIR = os.path.join(os.path.dirname(__file__), '..', 'config', 'scenes')
TRUTH_TOPICS = ('/truth/orientation', '/truth/angular_velocity')


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def read_topic(path, topic):
    with BagReader(path) as reader:
        return [(record.log_time_ns, record.message()) for record in reader.messages([topic])]


@pytest.fixture(scope='module')
def every_effect(tmp_path_factory):
    """Return the shipped every-effect scene, simulated and written once."""
    simulation = simulate(spec.load_scene(os.path.join(SCENES_DIR, 'every_effect.yaml')), 4)
    path = tmp_path_factory.mktemp('bags') / 'every_effect.mcap'
    write_bag(simulation, path)
    return simulation, path


def test_bag_topics_and_counts(every_effect):
    simulation, path = every_effect
    n = len(simulation.time)
    with BagReader(path) as reader:
        assert reader.topics == {'/imu': 'sensor_msgs/msg/Imu',
                                 '/truth/orientation': 'geometry_msgs/msg/QuaternionStamped',
                                 '/truth/angular_velocity': 'geometry_msgs/msg/Vector3Stamped'}
        assert reader.message_counts == {'/imu': int(simulation.sensor.published.sum()),
                                         '/truth/orientation': n,
                                         '/truth/angular_velocity': n}
    assert 0 < simulation.sensor.published.sum() < n


def test_truth_messages_hold_the_truth_at_the_nominal_stamps(every_effect):
    simulation, path = every_effect
    orientation = read_topic(path, '/truth/orientation')
    angular_velocity = read_topic(path, '/truth/angular_velocity')
    for k, ((log_q, q), (log_w, w)) in enumerate(zip(orientation, angular_velocity)):
        assert log_q == log_w == stamp_ns(q.header) == stamp_ns(w.header) == simulation.stamp_ns[k]
        assert q.header.frame_id == w.header.frame_id == 'imu_link'
        m = q.quaternion
        assert [m.x, m.y, m.z, m.w] == simulation.truth_orientation[k].tolist()
        v = w.vector
        assert [v.x, v.y, v.z] == simulation.truth_angular_velocity[k].tolist()


def test_imu_messages_hold_the_sensor_stream(every_effect):
    simulation, path = every_effect
    sensor = simulation.sensor
    published = np.flatnonzero(sensor.published)
    messages = read_topic(path, '/imu')
    assert len(messages) == len(published)
    for k, (log_time, msg) in zip(published, messages):
        assert log_time == simulation.stamp_ns[k]            # recorder clock: nominal
        assert stamp_ns(msg.header) == sensor.stamp_ns[k]    # sensor clock: jittered
        assert msg.header.frame_id == 'imu_link'
        o, w = msg.orientation, msg.angular_velocity
        np.testing.assert_array_equal([o.x, o.y, o.z, o.w], sensor.orientation[k])
        np.testing.assert_array_equal([w.x, w.y, w.z], sensor.angular_velocity[k])
        np.testing.assert_array_equal(msg.orientation_covariance, sensor.orientation_covariance[k])
        np.testing.assert_array_equal(msg.angular_velocity_covariance,
                                      sensor.angular_velocity_covariance[k])
        a = msg.linear_acceleration
        assert [a.x, a.y, a.z] == [0.0, 0.0, 0.0]
        assert msg.linear_acceleration_covariance.tolist() == [-1.0] + [0.0] * 8


def test_every_effect_scene_shows_every_effect(every_effect):
    simulation, _ = every_effect
    sensor = simulation.sensor
    assert set(simulation.effect_masks) == set(spec.EFFECT_PARAMETERS)
    assert np.isnan(sensor.orientation).any() and np.isnan(sensor.angular_velocity).any()
    assert (sensor.orientation_covariance[:, 0] == -1).any()
    assert np.any(np.diff(sensor.stamp_ns) < 0)
    known = np.isfinite(sensor.orientation).all(axis=1) & sensor.orientation.any(axis=1)
    dots = np.einsum('ij,ij->i', sensor.orientation[known], simulation.truth_orientation[known])
    assert (dots < 0).any() and (dots > 0).any()


def test_scene_without_effects_writes_sensor_equal_to_truth(tmp_path):
    path = tmp_path / 'coning.mcap'
    write_bag(simulate(spec.load_scene(os.path.join(SCENES_DIR, 'coning.yaml'))), path)
    imu = read_topic(path, '/imu')
    truth_q = read_topic(path, '/truth/orientation')
    truth_w = read_topic(path, '/truth/angular_velocity')
    assert len(imu) == len(truth_q) == len(truth_w) == 401
    for (_, msg), (_, q), (_, w) in zip(imu, truth_q, truth_w):
        assert msg.header == q.header == w.header
        assert msg.orientation == q.quaternion
        assert msg.angular_velocity == w.vector


def test_same_scene_and_seed_give_a_byte_identical_bag(tmp_path):
    """Same file name in other directories: rosbag2's metadata records the file name."""
    scene = spec.load_scene(os.path.join(SCENES_DIR, 'every_effect.yaml'))
    paths = []
    for run, seed in (('a', 9), ('b', 9), ('c', 10)):
        (tmp_path / run).mkdir()
        paths.append(tmp_path / run / 'out.mcap')
        write_bag(simulate(scene, seed), paths[-1])
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()


def test_existing_bag_is_kept_unless_overwrite(tmp_path):
    path = tmp_path / 'out.mcap'
    path.write_bytes(b'precious')
    simulation = simulate(spec.load_scene(os.path.join(SCENES_DIR, 'coning.yaml')))
    with pytest.raises(BagError):
        write_bag(simulation, path)
    assert path.read_bytes() == b'precious'
    write_bag(simulation, path, overwrite=True)
    with BagReader(path) as reader:
        assert reader.message_counts['/imu'] == 401


@pytest.mark.parametrize('start_time, rate, expected', [
    (1735689600.0, 100.0, [1735689600_000_000_000, 1735689600_010_000_000]),
    (12.25, 3.0, [12_250_000_000, 12_583_333_333]),
    (0.0, 1e9, [0, 1]),
])
def test_sample_stamps(start_time, rate, expected):
    scene = spec.scene_from_dict({'duration': 1.0 / rate, 'rate': rate, 'start_time': start_time,
                                  'motion': {'type': 'coning', 'half_angle': 0.1,
                                             'frequency': 1.0}})
    np.testing.assert_array_equal(sample_stamps_ns(scene), expected)


def test_simulation_times_come_from_the_stamps():
    scene = spec.load_scene(os.path.join(SCENES_DIR, 'coning.yaml'))
    simulation = simulate(scene)
    np.testing.assert_array_equal(simulation.time,
                                  (simulation.stamp_ns - simulation.stamp_ns[0]) / 1e9)
    assert simulation.time[-1] == scene.duration


@pytest.mark.parametrize('seed', [-1, 1.5, True, '3'])
def test_bad_seed(seed):
    scene = spec.load_scene(os.path.join(SCENES_DIR, 'coning.yaml'))
    with pytest.raises(ValueError, match='seed'):
        simulate(scene, seed)


SHIPPED_SCENES = sorted(name for name in os.listdir(SCENES_DIR) if name.endswith('.yaml'))


@pytest.mark.slow
@pytest.mark.parametrize('name', SHIPPED_SCENES)
def test_blocks_are_bit_identical_to_the_whole_simulation(name):
    """Motion state, sign continuity, random walks and bursts carry over from block to block."""
    scene = spec.load_scene(os.path.join(SCENES_DIR, name))
    whole = simulate(scene, 7)
    blocks = list(simulate_blocks(scene, 7, block_samples=37))
    assert len(blocks) == -(-len(whole.time) // 37)
    for field in ('stamp_ns', 'time', 'truth_orientation', 'truth_angular_velocity'):
        np.testing.assert_array_equal(np.concatenate([getattr(b, field) for b in blocks]),
                                      getattr(whole, field), err_msg=field)
    for field in ('stamp_ns', 'orientation', 'angular_velocity', 'orientation_covariance',
                  'angular_velocity_covariance', 'published'):
        np.testing.assert_array_equal(
            np.concatenate([getattr(b.sensor, field) for b in blocks]),
            getattr(whole.sensor, field), err_msg=field)
    for effect, mask in whole.effect_masks.items():
        np.testing.assert_array_equal(np.concatenate([b.effect_masks[effect] for b in blocks]),
                                      mask, err_msg=effect)


def test_streamed_bag_is_byte_identical_to_the_two_steps(tmp_path):
    scene = spec.load_scene(os.path.join(SCENES_DIR, 'every_effect.yaml'))
    for run in ('streamed', 'whole'):
        (tmp_path / run).mkdir()
    samples, published = write_scene_bag(scene, tmp_path / 'streamed' / 'bag.mcap', seed=3,
                                         block_samples=50)
    simulation = simulate(scene, 3)
    write_bag(simulation, tmp_path / 'whole' / 'bag.mcap')
    assert (samples, published) == (len(simulation.time), simulation.sensor.published.sum())
    assert ((tmp_path / 'streamed' / 'bag.mcap').read_bytes()
            == (tmp_path / 'whole' / 'bag.mcap').read_bytes())


def test_streamed_simulation_memory_does_not_grow_with_the_scene(tmp_path):
    def peak_bytes(duration):
        scene = spec.scene_from_dict({
            'duration': duration, 'rate': 1000.0,
            'motion': {'type': 'torque_free', 'inertia': [1.0, 2.0, 3.0],
                       'orientation': [0.0, 0.0, 0.0, 1.0],
                       'angular_velocity': [0.1, 2.0, 0.1]},
            'effects': {'gyro_bias': {'random_walk': 0.01}, 'gyro_noise': {'std': 0.01},
                        'nan_bursts': {'probability': 0.01, 'length': 5}}})
        tracemalloc.start()
        try:
            for block in simulate_blocks(scene, 1, block_samples=2000):
                del block
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    peak_bytes(1.0)   # compiles the integrator first: its allocations are not the scene's
    short, long = peak_bytes(10.0), peak_bytes(80.0)   # 10 001 and 80 001 samples
    # All at once, the 80 s scene alone holds ~30 MB of arrays; in blocks ~1 MB at any length.
    assert long < 1.3 * short < 4 << 20, (short, long)
