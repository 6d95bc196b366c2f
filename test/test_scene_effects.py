"""Tests of rotation_node.scene.effects: each effect alone, its fields only, its own draws."""
import dataclasses
import itertools

import numpy as np
import pytest

from rotation_node.conversions import quaternion_distance
from rotation_node.scene import effects, spec
from rotation_node.scene.effects import SensorStream
from rotation_node.scene.simulator import simulate

RATE = 100.0

# Effect parameters strong enough to change something in 201 samples, and the
# stream fields the effect may change (the test's own statement of the contract).
EFFECT_CASES = {
    'gyro_bias': ({'constant': [0.01, -0.02, 0.03], 'random_walk': 0.01},
                  {'angular_velocity'}),
    'gyro_noise': ({'std': 0.01}, {'angular_velocity', 'angular_velocity_covariance'}),
    'orientation_noise': ({'std': 0.01}, {'orientation', 'orientation_covariance'}),
    'quaternion_sign_flips': ({'probability': 0.5}, {'orientation'}),
    'non_unit_quaternions': ({'scale': [0.5, 2.0]}, {'orientation'}),
    'nan_bursts': ({'probability': 0.05, 'length': 3}, {'orientation', 'angular_velocity'}),
    'orientation_unknown': ({'probability': 0.3}, {'orientation', 'orientation_covariance'}),
    'timestamp_jitter': ({'std': 0.005}, {'stamp_ns'}),
    'dropped_messages': ({'probability': 0.3}, {'published'}),
}
STREAM_FIELDS = [f.name for f in dataclasses.fields(SensorStream)]


def coning_scene(effect_params=None, duration=2.0):
    return spec.scene_from_dict({
        'duration': duration, 'rate': RATE,
        'motion': {'type': 'coning', 'half_angle': 0.3, 'frequency': 2.0},
        'effects': effect_params or {}})


def simulate_with(*names, seed=7, **overrides):
    params = {name: EFFECT_CASES[name][0] for name in names}
    params.update(overrides)
    return simulate(coning_scene(params), seed)


@pytest.fixture(scope='module')
def perfect():
    return simulate(coning_scene(), seed=7)


def test_without_effects_the_sensor_is_the_truth(perfect):
    sensor = perfect.sensor
    np.testing.assert_array_equal(sensor.orientation, perfect.truth_orientation)
    np.testing.assert_array_equal(sensor.angular_velocity, perfect.truth_angular_velocity)
    np.testing.assert_array_equal(sensor.stamp_ns, perfect.stamp_ns)
    assert sensor.published.all()
    assert not sensor.orientation_covariance.any()
    assert not sensor.angular_velocity_covariance.any()
    assert perfect.effect_masks == {}


@pytest.mark.parametrize('name', EFFECT_CASES)
def test_one_effect_changes_only_its_fields(name, perfect):
    simulation = simulate_with(name)
    np.testing.assert_array_equal(simulation.truth_orientation, perfect.truth_orientation)
    np.testing.assert_array_equal(simulation.truth_angular_velocity,
                                  perfect.truth_angular_velocity)
    touched = EFFECT_CASES[name][1]
    for field in STREAM_FIELDS:
        got, clean = getattr(simulation.sensor, field), getattr(perfect.sensor, field)
        if field in touched:
            assert not np.array_equal(got, clean), f'{name} did not change {field}'
        else:
            np.testing.assert_array_equal(got, clean, err_msg=f'{name} changed {field}')
    assert set(simulation.effect_masks) == {name}
    assert simulation.effect_masks[name].any()


@pytest.mark.parametrize('name, other', list(itertools.permutations(EFFECT_CASES, 2)))
def test_enabling_another_effect_leaves_this_effects_draws_alone(name, other):
    alone = simulate_with(name)
    together = simulate_with(name, other)
    np.testing.assert_array_equal(together.effect_masks[name], alone.effect_masks[name])


def test_all_effects_together_give_what_each_gives_on_disjoint_fields():
    together = simulate_with(*EFFECT_CASES)
    np.testing.assert_array_equal(together.sensor.stamp_ns,
                                  simulate_with('timestamp_jitter').sensor.stamp_ns)
    np.testing.assert_array_equal(together.sensor.published,
                                  simulate_with('dropped_messages').sensor.published)


def test_order_of_effects_in_the_scene_does_not_matter():
    names = list(EFFECT_CASES)
    forward = simulate(coning_scene({n: EFFECT_CASES[n][0] for n in names}), 3)
    backward = simulate(coning_scene({n: EFFECT_CASES[n][0] for n in reversed(names)}), 3)
    for field in STREAM_FIELDS:
        np.testing.assert_array_equal(getattr(forward.sensor, field),
                                      getattr(backward.sensor, field))


def test_seed_changes_the_draws():
    a, b = simulate_with('dropped_messages', seed=1), simulate_with('dropped_messages', seed=2)
    assert not np.array_equal(a.sensor.published, b.sensor.published)


def test_effect_rng_is_reproducible_and_distinct_per_effect():
    first = effects.effect_rng(5, 'gyro_noise').standard_normal(4)
    np.testing.assert_array_equal(first, effects.effect_rng(5, 'gyro_noise').standard_normal(4))
    assert not np.array_equal(first, effects.effect_rng(5, 'gyro_bias').standard_normal(4))
    assert not np.array_equal(first, effects.effect_rng(6, 'gyro_noise').standard_normal(4))


def long_run(name, **params):
    return simulate(coning_scene({name: params}, duration=100.0), seed=11)


def test_gyro_noise_statistics_and_covariance():
    simulation = long_run('gyro_noise', std=0.02)
    error = simulation.sensor.angular_velocity - simulation.truth_angular_velocity
    np.testing.assert_allclose(error.std(axis=0), 0.02, rtol=0.05)
    np.testing.assert_allclose(error.mean(axis=0), 0.0, atol=5 * 0.02 / np.sqrt(len(error)))
    np.testing.assert_array_equal(simulation.sensor.angular_velocity_covariance,
                                  np.tile([4e-4, 0, 0, 0, 4e-4, 0, 0, 0, 4e-4], (len(error), 1)))


def test_constant_gyro_bias():
    simulation = simulate_with('gyro_bias', gyro_bias={'constant': [0.1, -0.2, 0.3]})
    error = simulation.sensor.angular_velocity - simulation.truth_angular_velocity
    np.testing.assert_allclose(error, np.broadcast_to([0.1, -0.2, 0.3], error.shape),
                               rtol=0, atol=1e-15)


def test_gyro_bias_random_walk_increments():
    """Steps between samples dt apart are N(0, random_walk^2 dt) per axis; the walk starts at 0."""
    simulation = long_run('gyro_bias', random_walk=0.05)
    bias = simulation.sensor.angular_velocity - simulation.truth_angular_velocity
    np.testing.assert_allclose(bias[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(np.diff(bias, axis=0).std(axis=0), 0.05 * np.sqrt(1 / RATE),
                               rtol=0.05)


def test_orientation_noise_is_a_small_body_rotation():
    simulation = long_run('orientation_noise', std=0.01)
    truth, sensor = simulation.truth_orientation, simulation.sensor.orientation
    np.testing.assert_allclose(np.linalg.norm(sensor, axis=1), 1.0, atol=1e-15)
    assert np.all(np.einsum('ij,ij->i', truth, sensor) > 0)    # sign kept
    angle = quaternion_distance(truth, sensor)
    # |v|^2 for v ~ N(0, std^2 I3) has mean 3 std^2.
    np.testing.assert_allclose(np.mean(angle ** 2), 3e-4, rtol=0.05)
    assert simulation.sensor.orientation_covariance[0].tolist() == [1e-4, 0, 0, 0, 1e-4, 0,
                                                                    0, 0, 1e-4]


def test_sign_flips_negate_exactly_the_flipped_samples():
    simulation = simulate_with('quaternion_sign_flips')
    flipped = simulation.effect_masks['quaternion_sign_flips']
    np.testing.assert_array_equal(simulation.sensor.orientation[flipped],
                                  -simulation.truth_orientation[flipped])
    np.testing.assert_array_equal(simulation.sensor.orientation[~flipped],
                                  simulation.truth_orientation[~flipped])
    assert 0.35 < flipped.mean() < 0.65


def test_non_unit_quaternions_keep_the_direction():
    simulation = simulate_with('non_unit_quaternions')
    norm = np.linalg.norm(simulation.sensor.orientation, axis=1)
    assert norm.min() >= 0.5 and norm.max() <= 2.0 and norm.max() - norm.min() > 1.0
    np.testing.assert_allclose(simulation.sensor.orientation / norm[:, None],
                               simulation.truth_orientation, rtol=0, atol=1e-15)


@pytest.mark.parametrize('fields', [['orientation'], ['angular_velocity'],
                                    ['orientation', 'angular_velocity']])
def test_nan_bursts_in_the_listed_fields(fields):
    simulation = simulate_with('nan_bursts', nan_bursts={'probability': 0.05, 'length': 4,
                                                         'fields': fields})
    burst = simulation.effect_masks['nan_bursts']
    for field in ('orientation', 'angular_velocity'):
        nan = np.isnan(getattr(simulation.sensor, field))
        expected = burst if field in fields else np.zeros_like(burst)
        np.testing.assert_array_equal(nan.all(axis=1), expected)
        np.testing.assert_array_equal(nan.any(axis=1), expected)
    # Every burst lasts at least `length` samples, unless cut by the end of the scene.
    edges = np.diff(np.concatenate(([0], burst.astype(int), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    lengths = ends - starts
    assert len(lengths) > 0
    assert np.all((lengths >= 4) | (ends == len(burst)))


def test_orientation_unknown_everywhere_by_default():
    simulation = simulate(coning_scene({'orientation_unknown': None}), seed=0)
    sensor = simulation.sensor
    assert not sensor.orientation.any()
    np.testing.assert_array_equal(sensor.orientation_covariance[:, 0], -1.0)
    assert not sensor.orientation_covariance[:, 1:].any()


def test_orientation_unknown_overrides_orientation_noise_covariance():
    simulation = simulate_with('orientation_noise', 'orientation_unknown')
    unknown = simulation.effect_masks['orientation_unknown']
    covariance = simulation.sensor.orientation_covariance
    np.testing.assert_array_equal(covariance[unknown, 0], -1.0)
    np.testing.assert_array_equal(covariance[~unknown, 0], 1e-4)


def test_timestamp_jitter_moves_stamps_and_may_reverse_them():
    simulation = simulate_with('timestamp_jitter')
    offset = (simulation.sensor.stamp_ns - simulation.stamp_ns) * 1e-9
    assert 0.003 < offset.std() < 0.007
    assert np.any(np.diff(simulation.sensor.stamp_ns) < 0)   # documented: not monotonic


def test_dropped_messages_fraction():
    dropped = long_run('dropped_messages', probability=0.2).effect_masks['dropped_messages']
    assert abs(dropped.mean() - 0.2) < 0.02
