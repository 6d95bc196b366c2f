"""Tests of rotation_node.comparison._alignment: world alignment, mounting and time offset."""
import numpy as np
import pytest
from rotation_dev.two_streams import two_streams
from rotation_node import comparison
from rotation_node.errors import ComparisonError, DegenerateMotionError
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation, Slerp

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def angle_deg(p, q):
    return np.degrees((Rotation.from_quat(p).inv() * Rotation.from_quat(q)).magnitude())


def statistics_at(streams, dt, world, mounting):
    series = comparison.aligned_series(streams.t_ref, streams.q_ref, streams.t_est,
                                       streams.q_est, time_offset=dt, world=world,
                                       mounting=mounting)
    return comparison.error_statistics(series.errors)


def as_list(statistics):
    return [statistics.rmse, statistics.mean, statistics.median, statistics.p95,
            *statistics.axis_rmse]


@pytest.mark.slow
def test_sixty_seconds_at_a_third_of_a_degree():
    """The issue's case: 100 Hz reference, 200 Hz estimate, 0.3 deg noise on both."""
    streams = two_streams(11, duration=60.0, rate_ref=100.0, rate_est=200.0, noise_ref_deg=0.3,
                          noise_est_deg=0.3, time_offset=0.0373)
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est)
    assert abs(found.time_offset - streams.time_offset) < 1e-3
    assert angle_deg(found.world, streams.world) < 0.1
    assert angle_deg(found.mounting, streams.mounting) < 0.1
    assert found.matched == streams.t_ref.size
    # The standard deviations are fair: the errors within 5 of them.
    assert abs(found.time_offset - streams.time_offset) < 5.0 * found.time_offset_std
    assert np.radians(angle_deg(found.world, streams.world)) < 5.0 * np.linalg.norm(
        found.world_std)
    # The errors after the estimated alignment: within 5 % of those after the true one.
    estimated = statistics_at(streams, found.time_offset, found.world, found.mounting)
    true = statistics_at(streams, streams.time_offset, streams.world, streams.mounting)
    np.testing.assert_allclose(as_list(estimated), as_list(true), rtol=0.05)


@pytest.mark.slow
def test_time_offset_std_counts_the_estimate_noise_its_fit_smooths():
    """
    Over draws of estimate noise, the time offset errors spread as much as its std says.

    The estimate's local fit averages its noise, correlated over neighbouring reference
    samples; the time offset still sees every estimate sample's noise (the std of
    ``s^2 (J^T J)^-1`` was 1.6 times too small).
    """
    errors, stds = [], []
    for seed in range(8):
        streams = two_streams(seed, duration=20.0, noise_ref_deg=0.0, noise_est_deg=0.3,
                              time_offset=0.0237)
        found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                              streams.q_est)
        errors.append(found.time_offset - streams.time_offset)
        stds.append(found.time_offset_std)
    ratio = np.sqrt(np.mean(np.square(errors))) / np.mean(stds)
    assert 0.6 < ratio < 1.3


@pytest.mark.slow
def test_error_statistics_are_the_injected_noise():
    """With a noise-free estimate the errors are the reference's noise (reversed)."""
    streams = two_streams(12, duration=30.0, noise_ref_deg=0.3, noise_est_deg=0.0,
                          time_offset=-0.0123)
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est)
    statistics = statistics_at(streams, found.time_offset, found.world, found.mounting)
    injected = comparison.error_statistics(streams.noise_ref)
    np.testing.assert_allclose(as_list(statistics) + [statistics.maximum],
                               as_list(injected) + [injected.maximum], rtol=0.05)


@pytest.mark.slow
@pytest.mark.parametrize('seed, duration, rate_ref, rate_est, noise_deg, offset, start', [
    (21, 20.0, 50.0, 100.0, 1.0, 0.25, 0.0),
    (22, 30.0, 120.0, 400.0, 0.1, -0.0042, 1.7e4),
    (23, 15.0, 100.0, 100.0, 0.5, 0.0, 0.0),
])
def test_rates_lengths_and_noise(seed, duration, rate_ref, rate_est, noise_deg, offset, start):
    streams = two_streams(seed, duration=duration, rate_ref=rate_ref, rate_est=rate_est,
                          noise_ref_deg=noise_deg, noise_est_deg=noise_deg, time_offset=offset,
                          start=start)
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est)
    assert abs(found.time_offset - offset) < max(5.0 * found.time_offset_std, 1e-4)
    assert abs(found.time_offset - offset) < 2e-3
    for estimate, truth, std in ((found.world, streams.world, found.world_std),
                                 (found.mounting, streams.mounting, found.mounting_std)):
        assert angle_deg(estimate, truth) < max(np.degrees(5.0 * np.linalg.norm(std)), 1e-3)
        assert angle_deg(estimate, truth) < 0.3


@pytest.mark.slow
@pytest.mark.parametrize('world, mounting', [(True, False), (False, True), (False, False)])
def test_one_rotation_fixed_to_the_identity(world, mounting):
    streams = two_streams(31, duration=10.0, time_offset=0.11,
                          world=None if world else IDENTITY,
                          mounting=None if mounting else IDENTITY)
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est, world=world, mounting=mounting)
    assert abs(found.time_offset - 0.11) < 1e-3
    assert angle_deg(found.world, streams.world) < 0.1
    assert angle_deg(found.mounting, streams.mounting) < 0.1
    if not world:
        np.testing.assert_array_equal(found.world, IDENTITY)
        np.testing.assert_array_equal(found.world_std, 0.0)
    if not mounting:
        np.testing.assert_array_equal(found.mounting, IDENTITY)


@pytest.mark.slow
def test_a_given_time_offset_is_kept():
    streams = two_streams(32, duration=10.0, time_offset=0.05)
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est, time_offset=0.05)
    assert found.time_offset == 0.05 and found.time_offset_std == 0.0
    assert angle_deg(found.mounting, streams.mounting) < 0.1


def test_nothing_to_estimate_gives_the_residual_of_the_identity(rng):
    streams = two_streams(33, duration=10.0, time_offset=0.05, world=IDENTITY, mounting=IDENTITY)
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est, time_offset=0.05, world=False,
                                          mounting=False)
    assert found.time_offset == 0.05 and found.time_offset_std == 0.0
    np.testing.assert_array_equal(found.world, IDENTITY)
    np.testing.assert_array_equal(found.mounting, IDENTITY)
    assert found.matched >= 20 and 0.0 < found.residual_rms < np.radians(1.0)
    q_ref, q_est = pairs(rng, 50, 2.0, IDENTITY, IDENTITY)
    found = comparison.align_pairs(q_ref, q_est, world=False, mounting=False)
    errors = (Rotation.from_quat(q_ref).inv() * Rotation.from_quat(q_est)).magnitude()
    assert found.matched == 50
    assert found.residual_rms == pytest.approx(np.sqrt(np.mean(errors ** 2)), rel=1e-12)


def chordal_kabsch(q_ref, q_est):
    """M minimising sum |M - R_est^T R_ref|_F^2, by scipy's align_vectors on the columns."""
    per_pair = (Rotation.from_quat(q_est).inv() * Rotation.from_quat(q_ref)).as_matrix()
    a = np.concatenate([per_pair[:, :, k] for k in range(3)])
    b = np.repeat(np.eye(3), len(q_ref), axis=0)
    return Rotation.align_vectors(a, b)[0].as_quat()


def pairs(rng, n, noise_deg, world, mounting):
    est = Rotation.random(n, random_state=rng)
    noise = Rotation.from_rotvec(rng.normal(0.0, np.radians(noise_deg), (n, 3)))
    ref = Rotation.from_quat(world) * est * Rotation.from_quat(mounting) * noise
    return ref.as_quat(), est.as_quat()


def test_pairs_without_noise_give_the_rotations_exactly(rng):
    world, mounting = Rotation.random(2, random_state=rng).as_quat()
    q_ref, q_est = pairs(rng, 50, 0.0, world, mounting)
    found = comparison.align_pairs(q_ref, q_est)
    assert angle_deg(found.world, world) < 1e-10 and angle_deg(found.mounting, mounting) < 1e-10


@pytest.mark.parametrize('noise_deg, tolerance_deg', [(0.3, 1e-6), (2.0, 1e-3)])
def test_pairs_least_squares_against_kabsch(rng, noise_deg, tolerance_deg):
    """On SO(3) and chordal least squares differ by O(noise^3) only."""
    mounting = Rotation.random(random_state=rng).as_quat()
    q_ref, q_est = pairs(rng, 400, noise_deg, IDENTITY, mounting)
    found = comparison.align_pairs(q_ref, q_est, world=False)
    assert angle_deg(found.mounting, chordal_kabsch(q_ref, q_est)) < tolerance_deg
    assert angle_deg(found.mounting, mounting) < noise_deg / 4.0


def geodesic_cost(q_ref, q_est, world, mounting):
    aligned = Rotation.from_quat(world) * Rotation.from_quat(q_est) * Rotation.from_quat(mounting)
    return np.sum((Rotation.from_quat(q_ref).inv() * aligned).magnitude() ** 2)


def test_pairs_least_squares_against_a_brute_force_search(rng):
    """Six pairs with 5 deg noise: no point of a grid around the answer is lower."""
    mounting = Rotation.random(random_state=rng).as_quat()
    q_ref, q_est = pairs(rng, 6, 5.0, IDENTITY, mounting)
    found = comparison.align_pairs(q_ref, q_est, world=False)
    best = geodesic_cost(q_ref, q_est, IDENTITY, found.mounting)
    steps = np.radians(np.linspace(-0.5, 0.5, 21))
    grid = np.stack(np.meshgrid(steps, steps, steps), axis=-1).reshape(-1, 1, 3)
    candidates = Rotation.from_quat(found.mounting) * Rotation.from_rotvec(grid.reshape(-1, 3))
    aligned = (Rotation.from_quat(np.broadcast_to(q_est, (len(grid), 6, 4)).reshape(-1, 4))
               * Rotation.from_quat(np.repeat(candidates.as_quat(), 6, axis=0)))
    errors = (Rotation.from_quat(np.tile(q_ref, (len(grid), 1))).inv() * aligned).magnitude()
    costs = np.sum(errors.reshape(-1, 6) ** 2, axis=1)
    assert best <= np.min(costs) + 1e-15
    assert np.argmin(costs) == len(grid) // 2   # the centre: no step of the grid is better


@pytest.mark.slow
def test_pairs_with_both_rotations_against_a_general_minimiser(rng):
    world, mounting = Rotation.random(2, random_state=rng).as_quat()
    q_ref, q_est = pairs(rng, 8, 5.0, world, mounting)
    found = comparison.align_pairs(q_ref, q_est)

    def cost(x):
        world = Rotation.from_quat(found.world) * Rotation.from_rotvec(x[:3])
        mounting = Rotation.from_quat(found.mounting) * Rotation.from_rotvec(x[3:])
        return geodesic_cost(q_ref, q_est, world.as_quat(), mounting.as_quat())
    result = minimize(cost, np.full(6, 0.01), method='Nelder-Mead',
                      options={'xatol': 1e-10, 'fatol': 1e-16, 'maxiter': 20000})
    assert np.linalg.norm(result.x) < 1e-6
    assert cost(np.zeros(6)) <= result.fun + 1e-14


@pytest.mark.slow
def test_rotation_about_one_axis_only():
    streams = two_streams(41, duration=10.0, axes=(0.0, 0.0, 1.0))
    with pytest.raises(DegenerateMotionError, match='cannot be told apart'):
        comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                      streams.q_est)
    # One of them alone is determined.
    streams = two_streams(41, duration=10.0, axes=(0.0, 0.0, 1.0), mounting=IDENTITY)
    found = comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                          streams.q_est, mounting=False)
    assert angle_deg(found.world, streams.world) < 0.1


@pytest.mark.slow
def test_no_motion():
    streams = two_streams(42, duration=10.0, amplitude=0.0)
    with pytest.raises(DegenerateMotionError, match='too little motion'):
        comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                      streams.q_est)
    with pytest.raises(DegenerateMotionError, match='cannot be told apart'):
        comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                      streams.q_est, time_offset=0.0)


def test_constant_rate_about_one_axis_does_not_time():
    t = np.arange(0.0, 20.0, 0.01)
    q = Rotation.from_rotvec(np.outer(0.8 * t, [0.0, 0.6, 0.8])).as_quat()
    with pytest.raises(DegenerateMotionError):
        comparison.estimate_alignment(t, q, t, q, world=True, mounting=False)


def test_too_short_or_no_overlap():
    streams = two_streams(43, duration=0.1, time_offset=0.0)
    with pytest.raises(ComparisonError, match='only 10 reference samples'):
        comparison.estimate_alignment(streams.t_ref, streams.q_ref, streams.t_est,
                                      streams.q_est, time_offset=0.0)
    with pytest.raises(ComparisonError, match='do not overlap'):
        comparison.aligned_series(streams.t_ref, streams.q_ref, streams.t_est, streams.q_est,
                                  time_offset=100.0)


def test_aligned_errors_against_scipy():
    streams = two_streams(44, duration=10.0, time_offset=0.0123)
    world, mounting = streams.world, streams.mounting
    series = comparison.aligned_series(streams.t_ref, streams.q_ref, streams.t_est,
                                       streams.q_est, time_offset=0.0123, world=world,
                                       mounting=mounting)
    estimate = Slerp(streams.t_est, Rotation.from_quat(streams.q_est))(streams.t_ref + 0.0123)
    aligned = Rotation.from_quat(world) * estimate * Rotation.from_quat(mounting)
    errors = (Rotation.from_quat(streams.q_ref).inv() * aligned).as_rotvec()
    np.testing.assert_allclose(series.errors, errors, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(series.reference_index, np.arange(streams.t_ref.size))
