"""Tests of rotation_node.comparison._time_offset: the time offset from angular rate magnitudes."""
import numpy as np
import pytest
from rotation_dev.two_streams import two_streams
from rotation_node import comparison
from rotation_node.errors import ComparisonError, DegenerateMotionError
from scipy.spatial.transform import Rotation


@pytest.mark.slow
@pytest.mark.parametrize('seed, offset, rate_ref, rate_est, noise_deg', [
    (1, 0.0373, 100.0, 200.0, 0.3),
    (2, -0.4125, 120.0, 400.0, 0.3),
    (3, 1.7, 50.0, 100.0, 1.0),
    (4, 0.0, 200.0, 200.0, 0.1),
])
def test_offset_recovered_within_a_millisecond(seed, offset, rate_ref, rate_est, noise_deg):
    streams = two_streams(seed, duration=30.0, rate_ref=rate_ref, rate_est=rate_est,
                          noise_ref_deg=noise_deg, noise_est_deg=noise_deg, time_offset=offset,
                          margin=2.0)
    found = comparison.estimate_time_offset(streams.t_ref, streams.q_ref, streams.t_est,
                                            streams.q_est)
    assert abs(found.seconds - offset) < 1e-3
    # The standard deviation is a fair figure: the error within a few of it.
    assert 0.0 < found.std < 1e-3 and abs(found.seconds - offset) < 5.0 * found.std + 1e-4
    assert found.correlation > 0.9


def test_given_rates_are_used(rng):
    streams = two_streams(5, duration=20.0, time_offset=-0.021)
    # The reference rates are the estimate's, rotated by M^T: their magnitudes match.
    found = comparison.estimate_time_offset(
        streams.t_ref, streams.q_ref, streams.t_est, streams.q_est,
        rates_est=streams.rates_est + rng.normal(0.0, 0.05, streams.rates_est.shape))
    assert abs(found.seconds + 0.021) < 1e-3


def test_max_offset_limits_the_search():
    streams = two_streams(6, duration=20.0, time_offset=0.5, margin=1.0)
    with pytest.raises(DegenerateMotionError, match=r'do not match .* within \+-0\.2 s'):
        comparison.estimate_time_offset(streams.t_ref, streams.q_ref, streams.t_est,
                                        streams.q_est, max_offset=0.2)


def test_still_streams_raise():
    t = np.arange(0.0, 10.0, 0.01)
    q = Rotation.from_rotvec(np.random.default_rng(0).normal(0.0, 1e-3, (t.size, 3))).as_quat()
    with pytest.raises(DegenerateMotionError, match='too little motion'):
        comparison.estimate_time_offset(t, q, t, q)


def test_different_motions_raise():
    one, other = two_streams(7, duration=20.0), two_streams(8, duration=20.0)
    with pytest.raises(DegenerateMotionError, match='do not match'):
        comparison.estimate_time_offset(one.t_ref, one.q_ref, other.t_est, other.q_est)


def test_stamps_of_different_clocks_are_refused():
    streams = two_streams(9, duration=10.0)
    with pytest.raises(ComparisonError, match='span 1.7e'):
        comparison.estimate_time_offset(streams.t_ref + 1.7e9, streams.q_ref, streams.t_est,
                                        streams.q_est)
