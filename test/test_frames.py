"""
Tests of rotation_node.frames: ENU <-> NED and FLU <-> FRD, exactly.

Oracles: the signed-permutation matrices transcribed here by hand, the exact
quaternion products in mpmath (40 digits), and mavros's published formulas
(mavros/src/lib/ftf_frame_conversions.cpp and ftf_quaternion_utils.cpp,
github.com/mavlink/mavros, ROS 2 branch), transcribed to numpy below.
"""
import itertools

import mpmath as mp
import numpy as np
import pytest
from rotation_node import conversions as rc
from rotation_node import covariance as cv
from rotation_node.frames import (
    BODY_FRAMES, ENU_FLU_FROM_NED_FRD, FrameConversion, NED_FRD_FROM_ENU_FLU, WORLD_FRAMES)
from scipy.spatial.transform import Rotation

EPS = np.finfo(float).eps
mp.mp.dps = 40

# Hand transcription: x_ned = y_enu, y_ned = x_enu, z_ned = -z_enu; FRD = (x, -y, -z) of FLU.
P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
B = np.diag([1.0, -1.0, -1.0])
# x_nwu = y_enu (north), y_nwu = -x_enu (west), z_nwu = z_enu (up).
N = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
# Each world's coordinates from ENU's, by hand.
FROM_ENU = {'enu': np.eye(3), 'ned': P, 'nwu': N}
ALL = [FrameConversion(*f) for f in itertools.product(WORLD_FRAMES, BODY_FRAMES,
                                                      WORLD_FRAMES, BODY_FRAMES)]


def matrices_of(conversion):
    return (FROM_ENU[conversion.target_world] @ FROM_ENU[conversion.source_world].T,
            B if conversion.changes_body else np.eye(3))


def test_nwu_by_its_axes():
    """Check north-west-up: east is -y, north is x, up is z; from NED: (x, -y, -z)."""
    to_nwu = FrameConversion('enu', 'flu', 'nwu', 'flu')
    assert np.array_equal(to_nwu.world_vector([1.0, 0.0, 0.0]), [0.0, -1.0, 0.0])
    assert np.array_equal(to_nwu.world_vector([0.0, 1.0, 0.0]), [1.0, 0.0, 0.0])
    assert np.array_equal(FrameConversion('ned', 'frd', 'nwu', 'frd').world_vector([1, 2, 3]),
                          [1.0, -2.0, -3.0])
    # Level, facing east (identity in ENU): yaw -90 deg in NWU (x north, counter-clockwise).
    q = to_nwu.quaternion([0.0, 0.0, 0.0, 1.0])
    assert np.abs(rc.euler_from_quaternion(q, 'xyz', degrees=True) - [0, 0, -90]).max() < 1e-13
    # NED <-> NWU quaternions are exact: (x, y, z, w) -> (w, -z, y, -x), sign to w >= 0.
    assert np.array_equal(FrameConversion('ned', 'flu', 'nwu', 'flu').quaternion(
        [0.1, 0.2, 0.3, 0.9]), [-0.9, 0.3, -0.2, 0.1])


def random_quaternions(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# ---------------------------------------------------------------- mavros, transcribed

def _hamilton(p, q):
    """Hamilton product of (x, y, z, w) quaternions (Eigen's operator*)."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return np.array([pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw,
                     pw * qw - px * qx - py * qy - pz * qz])


def _angle_axis(angle, axis):
    return np.concatenate([np.sin(angle / 2) * np.asarray(axis, float), [np.cos(angle / 2)]])


def mavros_quaternion_from_rpy(roll, pitch, yaw):
    """ftf::quaternion_from_rpy: AngleAxis(yaw, Z) * AngleAxis(pitch, Y) * AngleAxis(roll, X)."""
    return _hamilton(_hamilton(_angle_axis(yaw, [0, 0, 1]), _angle_axis(pitch, [0, 1, 0])),
                     _angle_axis(roll, [1, 0, 0]))


MAVROS_NED_ENU_Q = mavros_quaternion_from_rpy(np.pi, 0.0, np.pi / 2)
MAVROS_AIRCRAFT_BASELINK_Q = mavros_quaternion_from_rpy(np.pi, 0.0, 0.0)
MAVROS_AIRCRAFT_BASELINK_R = Rotation.from_quat(MAVROS_AIRCRAFT_BASELINK_Q).as_matrix()


def mavros_orientation_ned_frd_from_enu_flu(q):
    """transform_orientation: NED_ENU_Q * q (world), then q * AIRCRAFT_BASELINK_Q (body)."""
    return _hamilton(_hamilton(MAVROS_NED_ENU_Q, q), MAVROS_AIRCRAFT_BASELINK_Q)


def mavros_vector_ned_from_enu(v):
    """transform_static_frame(vec, ENU_TO_NED): REFLECTION_XY * (REFLECTION_Z * vec)."""
    return np.array([v[1], v[0], -v[2]])


def mavros_covariance_frd_from_flu(c):
    """transform_static_frame(Covariance6d, BASELINK_TO_AIRCRAFT), rotation block: R C R^T."""
    return MAVROS_AIRCRAFT_BASELINK_R @ c @ MAVROS_AIRCRAFT_BASELINK_R.T


def same_rotation(p, q):
    return min(np.abs(p - q).max(), np.abs(p + q).max())


def test_mavros_constants_are_the_signed_permutations():
    assert np.abs(Rotation.from_quat(MAVROS_NED_ENU_Q).as_matrix() - P).max() < 4 * EPS
    assert np.abs(MAVROS_AIRCRAFT_BASELINK_R - B).max() < 4 * EPS
    assert np.array_equal(NED_FRD_FROM_ENU_FLU.world_matrix(), P)
    assert np.array_equal(NED_FRD_FROM_ENU_FLU.body_matrix(), B)


def test_orientation_matches_mavros(rng):
    for q in random_quaternions(rng, 200):
        ours = NED_FRD_FROM_ENU_FLU.quaternion(q)
        theirs = mavros_orientation_ned_frd_from_enu_flu(q)
        assert same_rotation(ours, theirs) < 4 * EPS, (q, ours, theirs)
        back = ENU_FLU_FROM_NED_FRD.quaternion(ours)
        assert same_rotation(back, q) < 4 * EPS


def test_vectors_and_covariances_match_mavros(rng):
    for v in rng.normal(size=(50, 3)):
        assert np.array_equal(NED_FRD_FROM_ENU_FLU.world_vector(v), mavros_vector_ned_from_enu(v))
        assert np.abs(NED_FRD_FROM_ENU_FLU.body_vector(v)
                      - MAVROS_AIRCRAFT_BASELINK_R @ v).max() < 4 * EPS * np.abs(v).max()
    a = rng.normal(size=(50, 3, 3))
    for c in a @ np.swapaxes(a, -1, -2):
        assert np.abs(NED_FRD_FROM_ENU_FLU.body_covariance(c)
                      - mavros_covariance_frd_from_flu(c)).max() < 8 * EPS * np.abs(c).max()


# ---------------------------------------------------------------- exactness

@pytest.mark.parametrize('conversion', ALL, ids=str)
def test_matrices_vectors_covariances_are_the_exact_signed_permutations(rng, conversion):
    world, body = matrices_of(conversion)
    r = Rotation.random(30, random_state=5).as_matrix()
    assert np.array_equal(conversion.matrix(r), world @ r @ body)
    v = rng.normal(size=(30, 3))
    assert np.array_equal(conversion.world_vector(v), v @ world.T)
    assert np.array_equal(conversion.body_vector(v), v @ body.T)
    a = rng.normal(size=(30, 3, 3))
    c = a @ np.swapaxes(a, -1, -2)
    assert np.array_equal(conversion.world_covariance(c), world @ c @ world.T)
    assert np.array_equal(conversion.body_covariance(c), body @ c @ body.T)
    assert np.array_equal(conversion.inverse.matrix(conversion.matrix(r)), r)
    assert np.array_equal(conversion.inverse.world_covariance(conversion.world_covariance(c)), c)


def mp_product(p, q):
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return [pw * qx + px * qw + py * qz - pz * qy, pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw, pw * qw - px * qx - py * qy - pz * qz]


def world_quaternion(source, target, half):
    """Return the world change's exact quaternion (x, y, z, w), by hand (about one axis)."""
    zero, one = half * 0, half / half
    table = {('enu', 'ned'): [half, half, zero, zero], ('ned', 'enu'): [half, half, zero, zero],
             ('enu', 'nwu'): [zero, zero, -half, half],    # Rz(-90 deg)
             ('nwu', 'enu'): [zero, zero, half, half],     # Rz(+90 deg)
             ('ned', 'nwu'): [one, zero, zero, zero], ('nwu', 'ned'): [one, zero, zero, zero]}
    return table.get((source, target), [zero, zero, zero, one])


@pytest.mark.parametrize('source, target', itertools.product(WORLD_FRAMES, WORLD_FRAMES))
def test_hand_world_quaternions_are_the_hand_matrices(source, target):
    q = np.array(world_quaternion(source, target, np.sqrt(0.5)), dtype=float)
    expected = FROM_ENU[target] @ FROM_ENU[source].T
    assert np.abs(Rotation.from_quat(q).as_matrix() - expected).max() < 4 * EPS


@pytest.mark.parametrize('conversion', ALL, ids=str)
def test_quaternion_within_two_eps_of_the_exact_product(rng, conversion):
    half = mp.sqrt(mp.mpf(1) / 2)
    zero, one = mp.mpf(0), mp.mpf(1)
    q_world = world_quaternion(conversion.source_world, conversion.target_world, half)
    q_body = [one, zero, zero, zero] if conversion.changes_body else [zero, zero, zero, one]
    qs = np.concatenate([random_quaternions(rng, 100),
                         [[0, 0, 0, 1], [1, 0, 0, 0], [0.5, 0.5, 0.5, 0.5], [1, -1, 1e-300, 0]]])
    got = conversion.quaternion(qs)
    for q, g in zip(qs, got):
        exact = mp_product(mp_product(q_world, [mp.mpf(float(c)) for c in q]), q_body)
        norm = max(abs(c) for c in exact)
        error = min(max(abs(mp.mpf(float(gi)) - ei) for gi, ei in zip(g, exact)),
                    max(abs(mp.mpf(float(gi)) + ei) for gi, ei in zip(g, exact)))
        assert error <= 2 * EPS * norm, f'{conversion}: {q} -> {g}, {float(error / EPS):.2f} eps'
        assert g[3] >= 0.0


def test_identity_changes_nothing_and_canonicalises(rng):
    identity = FrameConversion()
    assert identity.is_identity
    q = random_quaternions(rng, 20)
    canonical = np.where(q[:, 3:] < 0, -q, q)
    assert np.array_equal(identity.quaternion(q), canonical)


# ---------------------------------------------------------------- consistency

@pytest.mark.parametrize('conversion', ALL, ids=str)
def test_quaternion_and_matrix_agree(conversion):
    q = Rotation.random(50, random_state=9).as_quat()
    from_quaternion = rc.matrix_from_quaternion(conversion.quaternion(q))
    from_matrix = conversion.matrix(rc.matrix_from_quaternion(q))
    assert np.abs(from_quaternion - from_matrix).max() < 8 * EPS


@pytest.mark.parametrize('conversion', ALL, ids=str)
def test_angular_velocity_and_covariance_stay_consistent(rng, conversion):
    """``w_w = R w_b`` and ``Sigma_world = R Sigma_body R^T`` hold in the new frames."""
    q = Rotation.random(20, random_state=4).as_quat()
    r = rc.matrix_from_quaternion(q)
    w_body = rng.normal(size=(20, 3))
    w_world = np.einsum('...ij,...j->...i', r, w_body)
    r_new = conversion.matrix(r)
    assert np.allclose(conversion.world_vector(w_world),
                       np.einsum('...ij,...j->...i', r_new, conversion.body_vector(w_body)),
                       rtol=0, atol=1e-14)
    a = 1e-3 * rng.normal(size=(20, 3, 3))
    body = a @ np.swapaxes(a, -1, -2)
    expected = conversion.world_covariance(cv.world_rotation_vector_covariance(q, body))
    got = cv.world_rotation_vector_covariance(conversion.quaternion(q),
                                              conversion.body_covariance(body))
    assert np.abs(got - expected).max() < 1e-14 * np.abs(expected).max()


def test_roll_pitch_yaw_in_ned_frd(rng):
    """ENU/FLU roll, pitch, yaw (r, p, y) is (r, -p, pi/2 - y) in NED/FRD: no fold or mirror."""
    rpy = rng.uniform(-1.4, 1.4, size=(100, 3))
    ned = rc.euler_from_quaternion(NED_FRD_FROM_ENU_FLU.quaternion(
        rc.quaternion_from_euler(rpy, 'xyz')), 'xyz')
    expected = np.stack([rpy[:, 0], -rpy[:, 1], np.pi / 2 - rpy[:, 2]], axis=-1)
    diff = (ned - expected + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(diff).max() < 1e-14


def test_names_and_inverse():
    assert NED_FRD_FROM_ENU_FLU.inverse == ENU_FLU_FROM_NED_FRD
    assert NED_FRD_FROM_ENU_FLU.changes_world and NED_FRD_FROM_ENU_FLU.changes_body
    assert not FrameConversion('ned', 'flu', 'ned', 'frd').changes_world


@pytest.mark.parametrize('call, message', [
    (lambda: FrameConversion('enu', 'flu', 'nue', 'frd'), '`target_world`'),
    (lambda: FrameConversion('enu', 'fru', 'ned', 'frd'), '`source_body`'),
    (lambda: NED_FRD_FROM_ENU_FLU.quaternion([0, 0, 1]), '`quaternion`'),
    (lambda: NED_FRD_FROM_ENU_FLU.quaternion([0, 0, np.inf, 1]), '`quaternion`'),
    (lambda: NED_FRD_FROM_ENU_FLU.matrix(np.eye(4)), '`matrix`'),
    (lambda: NED_FRD_FROM_ENU_FLU.world_vector([[1, 2]]), '`vector`'),
    (lambda: NED_FRD_FROM_ENU_FLU.body_covariance(np.eye(2)), '`covariance`'),
])
def test_bad_input_raises_value_error_naming_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()
