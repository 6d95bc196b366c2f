"""Tests of rotation_node.conversions._euler: 24 conventions, gimbal lock, singularity margin."""
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
import mp_reference as mpr
import numpy as np
import pytest
from rotation_dev.hard_cases import hard_quaternions, near_gimbal_lock_angles
from rotation_node import conversions as rc
from rotation_node.conversions._euler import euler_atan2_arguments, euler_from_half_angles
from rotation_node.conversions._trigonometry import atan2
from scipy.spatial.transform import Rotation
import transforms3d

BOUND = 8
ROUND_TRIP = 16
SEQUENCES = rc.SEQUENCES


def _regular_angles(rng, n, seq):
    """Angles away from gimbal lock, inside each convention's ranges."""
    a = rng.uniform(-np.pi, np.pi, (n, 3))
    if rc.parse_sequence(seq).proper:
        a[:, 1] = rng.uniform(0.1, np.pi - 0.1, n)
    else:
        a[:, 1] = rng.uniform(-np.pi / 2 + 0.1, np.pi / 2 - 0.1, n)
    return a


def test_there_are_24_conventions():
    assert len(set(SEQUENCES)) == 24
    assert all(rc.parse_sequence(s).name == s for s in SEQUENCES)


@pytest.mark.parametrize('seq', SEQUENCES)
def test_quaternion_from_euler_matches_scipy(rng, seq):
    a = rng.uniform(-4, 4, (50, 3))
    expected = rc.canonical_quaternion(Rotation.from_euler(seq, a).as_quat())
    assert np.allclose(rc.quaternion_from_euler(a, seq), expected, atol=1e-15)


@pytest.mark.parametrize('seq', SEQUENCES)
def test_euler_from_quaternion_matches_scipy_away_from_gimbal_lock(rng, seq):
    a = _regular_angles(rng, 50, seq)
    q = Rotation.from_euler(seq, a).as_quat()
    got = rc.euler_from_quaternion(q, seq)
    assert np.allclose(got, Rotation.from_quat(q).as_euler(seq), atol=1e-13)
    assert np.allclose(got, a, atol=1e-13)


@pytest.mark.parametrize('seq', ['sxyz', 'szyx', 'rzyx', 'rxyz', 'szxz', 'rzxz', 'syzy', 'rxzx'])
def test_matrix_from_euler_matches_transforms3d(rng, seq):
    # transforms3d: 's' = static (extrinsic), 'r' = rotating (intrinsic).
    ours = seq[1:] if seq[0] == 's' else seq[1:].upper()
    a = rng.uniform(-3, 3, 3)
    assert np.allclose(rc.matrix_from_euler(a, ours), transforms3d.euler.euler2mat(*a, axes=seq),
                       atol=1e-15)


def test_textbook_zxz_matrix():
    """The textbook R_WB = R_Z(phi) R_X(theta) R_Z(psi), with its R_Z written out."""
    phi, theta, psi = 0.3, 1.1, -2.0

    def r_z(t):
        return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])

    def r_x(t):
        return np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])

    expected = r_z(phi) @ r_x(theta) @ r_z(psi)
    assert np.allclose(rc.matrix_from_euler([phi, theta, psi], 'ZXZ'), expected, atol=1e-15)


def test_ros_roll_pitch_yaw_conventions():
    roll, pitch, yaw = 0.1, -0.2, 2.5
    q_rpy = rc.quaternion_from_euler([roll, pitch, yaw], 'xyz')
    q_ypr = rc.quaternion_from_euler([yaw, pitch, roll], 'ZYX')
    assert np.allclose(q_rpy, q_ypr, atol=1e-16)
    # tf2's setRPY: R = Rz(yaw) Ry(pitch) Rx(roll)
    expected = (Rotation.from_rotvec([0, 0, yaw]) * Rotation.from_rotvec([0, pitch, 0])
                * Rotation.from_rotvec([roll, 0, 0])).as_matrix()
    assert np.allclose(rc.matrix_from_quaternion(q_rpy), expected, atol=1e-15)


@pytest.mark.parametrize('seq', SEQUENCES)
def test_output_ranges(rng, seq):
    angles = rc.euler_from_quaternion(rng.normal(size=(500, 4)), seq)
    assert np.all((angles[:, [0, 2]] > -np.pi) & (angles[:, [0, 2]] <= np.pi))
    if rc.parse_sequence(seq).proper:
        assert np.all((angles[:, 1] >= 0) & (angles[:, 1] <= np.pi))
    else:
        assert np.all(np.abs(angles[:, 1]) <= np.pi / 2)


@pytest.mark.parametrize('seq', SEQUENCES)
def test_quaternion_from_euler_near_gimbal_lock_against_mpmath(rng, seq):
    a = near_gimbal_lock_angles(rng, 48, seq)
    got = rc.quaternion_from_euler(a, seq)
    errors = [mpr.error_in_eps(g, mpr.quaternion_from_euler(x, seq)) for g, x in zip(got, a)]
    assert max(errors) <= BOUND


@pytest.mark.parametrize('seq', SEQUENCES)
def test_euler_from_quaternion_near_gimbal_lock_against_mpmath(rng, seq):
    truth = [mpr.quaternion_from_euler(x, seq) for x in near_gimbal_lock_angles(rng, 48, seq)]
    q = np.array([[float(c) for c in t] for t in truth])
    angles = rc.euler_from_quaternion(q, seq)
    errors = [mpr.error_in_eps(mpr.quaternion_from_euler(a, seq), mpr.mpf_vector(x))
              for a, x in zip(angles, q)]
    assert max(errors) <= BOUND


@pytest.mark.parametrize('seq', SEQUENCES)
def test_round_trip_near_gimbal_lock(rng, seq):
    q = rc.quaternion_from_euler(near_gimbal_lock_angles(rng, 200, seq), seq)
    back = rc.quaternion_from_euler(rc.euler_from_quaternion(q, seq), seq)
    assert rc.quaternion_distance(q, back).max() <= ROUND_TRIP * mpr.EPS


@pytest.mark.parametrize('seq', SEQUENCES)
def test_round_trip_hard_quaternions(rng, seq):
    q = hard_quaternions(rng, 200)
    back = rc.quaternion_from_euler(rc.euler_from_quaternion(q, seq), seq)
    assert rc.quaternion_distance(q, back).max() <= ROUND_TRIP * mpr.EPS


def _exactly_locked_quaternion(seq, first_angle):
    """
    Return a quaternion whose middle angle is exactly singular for ``seq``.

    ``e_first (x) J`` with ``J`` the rotation by pi/2 (Tait-Bryan) or pi (proper)
    about the middle axis, written with components 0 and 1 (any norm is a
    rotation), so every component of the product is exact.
    """
    spec = rc.parse_sequence(seq)
    i, j = spec.axes[0], spec.axes[1]
    lock = np.zeros(4)
    lock[j] = 1.0
    lock[3] = 0.0 if spec.proper else 1.0
    first = np.zeros(4)
    first[i], first[3] = np.sin(first_angle / 2), np.cos(first_angle / 2)
    if spec.intrinsic:
        return rc.quaternion_product(first, lock)
    return rc.quaternion_product(lock, first)


@pytest.mark.parametrize('seq', SEQUENCES)
@pytest.mark.parametrize('first_angle', [0.0, 0.7, -2.9])
def test_exact_gimbal_lock_sets_third_angle_to_zero(seq, first_angle):
    q = _exactly_locked_quaternion(seq, first_angle)
    assert rc.euler_singularity_margin(q, seq) == 0.0
    angles = rc.euler_from_quaternion(q, seq)
    assert angles[2] == 0.0
    singular = np.pi if rc.parse_sequence(seq).proper else np.pi / 2
    assert abs(angles[1]) == pytest.approx(singular, abs=4 * mpr.EPS)
    back = rc.quaternion_from_euler(angles, seq)
    assert rc.quaternion_distance(q, back) <= ROUND_TRIP * mpr.EPS


@pytest.mark.parametrize('seq', ['xyz', 'ZYX', 'zxz', 'YXY'])
def test_exact_gimbal_lock_from_a_matrix(seq):
    # A matrix at exact lock: rotate 90 deg about the middle axis (Tait-Bryan) or identity-like
    # (proper).
    middle = 'xyz'.index(seq[1].lower())
    m = np.zeros((3, 3))
    m[middle, middle] = 1.0
    a, b = [i for i in range(3) if i != middle]
    m[a, b], m[b, a] = -1.0, 1.0
    if rc.parse_sequence(seq).proper:
        m = np.eye(3)
    angles = rc.euler_from_matrix(m, seq)
    assert np.isfinite(angles).all()
    back = rc.matrix_from_euler(angles, seq)
    assert np.allclose(back, m, atol=4e-16)


@pytest.mark.parametrize('seq', SEQUENCES)
def test_singularity_margin_is_distance_to_singular_middle_angle(rng, seq):
    a = near_gimbal_lock_angles(rng, 100, seq)
    truth = [mpr.quaternion_from_euler(x, seq) for x in a]
    q = np.array([[float(c) for c in t] for t in truth])
    margin = rc.euler_singularity_margin(q, seq)
    if rc.parse_sequence(seq).proper:
        expected = np.minimum(a[:, 1], np.pi - a[:, 1])
    else:
        expected = np.pi / 2 - np.abs(a[:, 1])
    # The angles were rounded to float64 before and after; compare to that precision.
    assert np.allclose(margin, expected, rtol=1e-6, atol=8 * mpr.EPS)
    assert np.all((margin >= 0) & (margin <= np.pi / 2))


def test_singularity_margin_regular_orientation():
    q = rc.quaternion_from_euler([0.1, 0.5, 0.2], 'xyz')
    assert rc.euler_singularity_margin(q, 'xyz') == pytest.approx(np.pi / 2 - 0.5, rel=1e-15)


@pytest.mark.parametrize('seq', ['xyz', 'ZXZ'])
def test_degrees(rng, seq):
    a = _regular_angles(rng, 10, seq)
    q = rc.quaternion_from_euler(np.rad2deg(a), seq, degrees=True)
    assert np.allclose(q, rc.quaternion_from_euler(a, seq), atol=1e-15)
    assert np.allclose(rc.euler_from_quaternion(q, seq, degrees=True), np.rad2deg(a), atol=1e-12)
    assert np.allclose(rc.euler_from_matrix(rc.matrix_from_quaternion(q), seq, degrees=True),
                       np.rad2deg(a), atol=1e-12)


@pytest.mark.parametrize('seq', SEQUENCES)
def test_euler_from_matrix_equals_quaternion_path(rng, seq):
    q = hard_quaternions(rng, 100)
    m = rc.matrix_from_quaternion(q)
    via_matrix = rc.quaternion_from_euler(rc.euler_from_matrix(m, seq), seq)
    assert rc.quaternion_distance(via_matrix, q).max() <= ROUND_TRIP * mpr.EPS


def test_leading_dimensions_are_kept(rng):
    q = rng.normal(size=(2, 3, 5, 4))
    angles = rc.euler_from_quaternion(q, 'zyx')
    assert angles.shape == (2, 3, 5, 3)
    assert np.array_equal(angles[1, 2, 3], rc.euler_from_quaternion(q[1, 2, 3], 'zyx'))
    assert rc.euler_singularity_margin(q, 'zyx').shape == (2, 3, 5)


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(q=arrays(np.float64, 4, elements=st.floats(-1, 1)).filter(lambda q: np.abs(q).max() > 1e-6),
       seq=st.sampled_from(SEQUENCES))
def test_round_trip_property(q, seq):
    back = rc.quaternion_from_euler(rc.euler_from_quaternion(q, seq), seq)
    assert rc.quaternion_distance(q, back) <= ROUND_TRIP * mpr.EPS


@pytest.mark.parametrize('seq', SEQUENCES)
def test_batch_schedule_is_as_exact_as_the_fused_kernel(rng, seq):
    # Large enough for the staged (numpy arctan2) schedule; hard cases throughout.
    q = np.concatenate([hard_quaternions(rng, 1024),
                        rc.quaternion_from_euler(near_gimbal_lock_angles(rng, 1024, seq), seq)])
    batch = rc.euler_from_quaternion(q, seq)
    fused = np.array([rc.euler_from_quaternion(x, seq) for x in q[::37]])
    back = rc.quaternion_from_euler(batch, seq)
    assert rc.quaternion_distance(q, back).max() <= ROUND_TRIP * mpr.EPS
    assert rc.quaternion_distance(rc.quaternion_from_euler(fused, seq), back[::37]).max() \
        <= ROUND_TRIP * mpr.EPS


@pytest.mark.slow
@pytest.mark.parametrize('seq', ['xyz', 'ZXZ', 'zyz', 'YXZ'])
def test_batch_schedule_is_the_scalar_formulas_with_the_branch_free_atan2(rng, seq):
    # The batch differs from single samples only in its atan2 (0.8 ulp, branch-free):
    # with that atan2 in the scalar formulas the two agree bit for bit, in every chunk.
    q = np.concatenate([hard_quaternions(rng, 3000),
                        rc.quaternion_from_euler(near_gimbal_lock_angles(rng, 3000, seq), seq)])
    batch = rc.euler_from_quaternion(q, seq, degrees=True)
    i, j, k = rc.parse_sequence(seq).axes
    intrinsic = rc.parse_sequence(seq).intrinsic
    for s in range(0, len(q), 13):
        (y1, y2, y3), (x1, x2, x3) = euler_atan2_arguments(*q[s], i, j, k, intrinsic)
        angles = euler_from_half_angles(atan2(y1, x1), atan2(y2, x2), atan2(y3, x3), x1,
                                        i, j, k, intrinsic)
        assert np.array_equal(batch[s], np.array(angles) * (180.0 / np.pi)), s


def test_batch_schedule_reports_the_first_bad_sample(rng):
    q = rng.normal(size=(10000, 4))   # several chunks
    q[9000, 1] = np.inf
    q[9500] = 0.0
    with pytest.raises(ValueError, match=r'`q` at index \(9000,\) has'):
        rc.euler_from_quaternion(q, 'zyx')
    q[9000, 1] = 1.0
    with pytest.raises(ValueError, match=r'`q` at index \(9500,\)'):
        rc.euler_from_quaternion(q, 'zyx')


# ------------------------------------------- documented ranges, exactly
# At multiples of pi/2 the rounding of each atan2 decides whether an outer
# angle comes out as +pi or -pi (only +pi is in range) and whether a quaternion
# has w == 0 exactly: the inputs below sit on those branches.

_STEPS = np.arange(-4, 5) * (np.pi / 2)   # -2 pi .. 2 pi in steps of pi/2
GRID_ANGLES = np.stack(np.meshgrid(_STEPS, _STEPS, _STEPS, indexing='ij'), -1).reshape(-1, 3)


def _signed_unit_quaternions():
    """Return unit quaternions with components in {0, +-1/2, +-sqrt(1/2), +-1}: 48 rotations."""
    values = (0.0, 0.5, -0.5, np.sqrt(0.5), -np.sqrt(0.5), 1.0, -1.0)
    q = np.stack(np.meshgrid(values, values, values, values, indexing='ij'), -1).reshape(-1, 4)
    return q[np.abs(np.einsum('ij,ij->i', q, q) - 1.0) <= 1e-15]


GRID_QUATERNIONS = _signed_unit_quaternions()


def _assert_in_documented_ranges(angles, seq):
    angles = np.asarray(angles).reshape(-1, 3)
    outer = angles[:, [0, 2]]
    inside = (outer > -np.pi) & (outer <= np.pi)
    assert np.all(inside), outer[~inside]
    if rc.parse_sequence(seq).proper:
        assert np.all((angles[:, 1] >= 0.0) & (angles[:, 1] <= np.pi))
    else:
        assert np.all((angles[:, 1] >= -np.pi / 2) & (angles[:, 1] <= np.pi / 2))


def _assert_same_rotations(angles, seq, q):
    """Return the angles are the rotations ``q`` (scipy as the independent oracle)."""
    back = Rotation.from_euler(seq, np.asarray(angles).reshape(-1, 3)).as_quat()
    assert np.max(mpr.rotation_distance(back, np.asarray(q).reshape(-1, 4))) <= 1e-14


def _euler_every_path(q, seq):
    """Euler angles of the quaternions ``q`` by every route and schedule: (name, angles) pairs."""
    m = Rotation.from_quat(q).as_matrix()
    many = np.tile(q, (-(-1100 // len(q)), 1))   # >= BATCH_SAMPLES: the staged schedule
    return [
        ('quaternion, one by one', np.array([rc.euler_from_quaternion(x, seq) for x in q])),
        ('quaternion, small batch', rc.euler_from_quaternion(q, seq)),
        ('quaternion, large batch', rc.euler_from_quaternion(many, seq)[:len(q)]),
        ('matrix, one by one', np.array([rc.euler_from_matrix(x, seq) for x in m])),
        ('matrix, small batch', rc.euler_from_matrix(m, seq)),
        ('matrix, large batch', rc.euler_from_matrix(np.tile(m, (len(many) // len(q), 1, 1)),
                                                     seq)[:len(q)]),
    ]


@pytest.mark.parametrize('seq', SEQUENCES)
def test_outer_angles_are_never_minus_pi_at_multiples_of_half_pi(seq):
    """Reported: euler_from_quaternion([1, 0, 0, 0], 'XYZ') gave -pi as its first angle."""
    q = np.concatenate([GRID_QUATERNIONS, Rotation.from_euler(seq, GRID_ANGLES).as_quat(),
                        rc.quaternion_from_euler(GRID_ANGLES, seq)])
    for _, angles in _euler_every_path(q, seq):
        _assert_in_documented_ranges(angles, seq)
        _assert_same_rotations(angles, seq, q)
    degrees = np.concatenate([rc.euler_from_quaternion(q, seq, degrees=True),
                              [rc.euler_from_quaternion(x, seq, degrees=True) for x in q[::5]]])
    assert np.all((degrees[:, [0, 2]] > -180.0) & (degrees[:, [0, 2]] <= 180.0))


@pytest.mark.parametrize('seq, q, expected', [
    ('XYZ', [1, 0, 0, 0], [np.pi, 0, 0]),
    ('xzy', [0, 1, 0, 0], [0, 0, np.pi]),
    ('zyx', [0, 0, 1, 0], [np.pi, 0, 0]),
    ('ZXY', [0, 0, 1, 0], [np.pi, 0, 0]),
])
def test_reported_minus_pi_cases(seq, q, expected):
    assert np.array_equal(rc.euler_from_quaternion(q, seq), expected)
    assert np.array_equal(rc.euler_from_matrix(Rotation.from_quat(q).as_matrix(), seq), expected)


_NEAR_STEP = st.tuples(st.integers(-4, 4), st.integers(-2, 2)).map(
    lambda kn: float(np.nextafter(kn[0] * (np.pi / 2), np.inf * kn[1])) if kn[1] else
    kn[0] * (np.pi / 2))


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(angles=st.tuples(_NEAR_STEP, _NEAR_STEP, _NEAR_STEP), seq=st.sampled_from(SEQUENCES),
       through_matrix=st.booleans())
def test_ranges_hold_at_and_next_to_multiples_of_half_pi(angles, seq, through_matrix):
    q = Rotation.from_euler(seq, angles).as_quat()
    if through_matrix:
        got = rc.euler_from_matrix(Rotation.from_quat(q).as_matrix(), seq)
    else:
        got = rc.euler_from_quaternion(q, seq)
    _assert_in_documented_ranges(got, seq)
    _assert_same_rotations(got, seq, q)
    ours = rc.quaternion_from_euler(angles, seq)
    assert mpr.is_canonical(ours)
    _assert_in_documented_ranges(rc.euler_from_quaternion(ours, seq), seq)


@pytest.mark.parametrize('seq', SEQUENCES)
def test_quaternions_from_euler_are_canonical_on_the_grid(seq):
    q = rc.quaternion_from_euler(GRID_ANGLES, seq)
    assert all(mpr.is_canonical(x) for x in q)
    assert all(mpr.is_canonical(rc.quaternion_from_euler(a, seq)) for a in GRID_ANGLES[::7])
