"""Tests of rotation_node.scene.motions: the truth of every motion."""
import os

import numpy as np
import pytest
from rotation_node import conversions as rc
from rotation_node.scene import motions, spec
from rotation_node.scene.simulator import simulate
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

SCENES_DIR = os.path.join(os.path.dirname(__file__), '..', 'config', 'scenes')

# Scene motions, each exercising something hard; Euler sweeps end at SWEEP_DURATION.
MOTIONS = {
    'constant_rate': spec.ConstantRate([0.2, -0.1, 0.4, np.sqrt(0.79)],
                                       [1.3, -2.1, 4.0]),  # passes |w| t = pi
    'coning': spec.Coning(0.2, 3.0),
    'coning_wide': spec.Coning(2.5, -1.7),
    'torque_free': spec.TorqueFree([1.0, 2.0, 2.5], [0.1, -0.2, 0.3, np.sqrt(0.86)],
                                   [3.0, 0.5, 1.0]),
    'dzhanibekov': spec.TorqueFree([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0], [0.01, 4.0, 0.01]),
    'euler_sweep_gimbal_lock': spec.EulerSweep('ZYX', [-0.5, np.pi / 2 - 0.4, 0.3],
                                               [0.7, np.pi / 2 + 0.4, -0.4]),
    'euler_sweep_proper': spec.EulerSweep('zxz', [0.3, -0.2, 1.0], [-1.0, 0.3, 2.0]),
}
SWEEP_DURATION = 2.0


def sample(name, t):
    return motions.motion_truth(MOTIONS[name], t, SWEEP_DURATION)


def geodesic_distance(p, q):
    """Angle between rotations, up to sign (the oracle's own formula, not the package's)."""
    p = p / np.linalg.norm(p, axis=-1, keepdims=True)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    relative = Rotation.from_quat(p).inv() * Rotation.from_quat(q)
    return np.linalg.norm(relative.as_rotvec(), axis=-1)


def world_momentum(inertia, q, w):
    return Rotation.from_quat(q).apply(np.asarray(inertia) * w)


@pytest.mark.parametrize('name', MOTIONS)
def test_angular_velocity_is_the_derivative_of_the_orientation(name):
    """``w`` = 2 vec(q^-1 q'), q' by central differences: error ~h^2 |dddq| / 3 < 2e-7 here."""
    h = 1e-4
    t = np.arange(0.0, 1.0 + h / 2, h)
    q, w = sample(name, t)
    q_dot = (q[2:] - q[:-2]) / (2 * h)
    w_fd = 2 * rc.quaternion_product(rc.quaternion_conjugate(q[1:-1]), q_dot)[:, :3]
    assert np.abs(w_fd - w[1:-1]).max() < 1e-6


@pytest.mark.parametrize('name', MOTIONS)
def test_orientation_is_unit_and_sign_continuous(name):
    t = np.arange(0.0, 3.0, 0.01)
    q, w = sample(name, t)
    assert q.shape == (len(t), 4) and w.shape == (len(t), 3)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert np.all(np.einsum('ij,ij->i', q[1:], q[:-1]) > 0)


def test_constant_rate_is_exact():
    q0 = np.array([0.2, -0.1, 0.4, np.sqrt(0.79)])
    w0 = np.array([1.3, -2.1, 4.0])
    t = np.linspace(0.0, 10.0, 1001)
    q, w = motions.motion_truth(spec.ConstantRate(q0, w0), t, 10.0)
    expected = (Rotation.from_quat(q0) * Rotation.from_rotvec(w0 * t[:, None])).as_quat()
    assert geodesic_distance(q, expected).max() < 1e-13
    np.testing.assert_array_equal(q[0], q0)
    np.testing.assert_array_equal(w, np.broadcast_to(w0, w.shape))


def test_coning_matches_numerics_md_with_phase_zero_at_first_sample():
    """docs/numerics.md, scalar first: q = [cos(a/2), sin(a/2) cos(Wt), sin(a/2) sin(Wt), 0]."""
    a, big_w = 0.2, 3.0
    t = np.linspace(0.0, 4.0, 401)
    q, w = motions.coning_truth(a, big_w, t)
    scalar_first = np.stack([np.full_like(t, np.cos(a / 2)), np.sin(a / 2) * np.cos(big_w * t),
                             np.sin(a / 2) * np.sin(big_w * t), np.zeros_like(t)], axis=1)
    np.testing.assert_allclose(q, np.roll(scalar_first, -1, axis=1), rtol=0, atol=1e-16)
    expected_w = np.stack([-big_w * np.sin(a) * np.sin(big_w * t),
                           big_w * np.sin(a) * np.cos(big_w * t),
                           np.full_like(t, -big_w * (1 - np.cos(a)))], axis=1)
    np.testing.assert_allclose(w, expected_w, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(q[0], [np.sin(a / 2), 0.0, 0.0, np.cos(a / 2)])


def test_coning_body_z_axis_stays_on_the_cone():
    a = 0.35
    q, _ = motions.coning_truth(a, 2.0, np.linspace(0.0, 5.0, 301))
    z_world = Rotation.from_quat(q).apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(z_world[:, 2], np.cos(a), atol=1e-15)


def invariant_drift(name, duration=20.0, rate=100.0):
    t = np.arange(0.0, duration + 0.5 / rate, 1.0 / rate)
    q, w = sample(name, t)
    inertia = np.asarray(MOTIONS[name].inertia)
    energy = np.einsum('ij,ij->i', w, inertia * w)
    momentum = np.linalg.norm(inertia * w, axis=1)
    momentum_world = world_momentum(inertia, q, w)
    return (np.abs(energy / energy[0] - 1).max(),
            np.abs(momentum / momentum[0] - 1).max(),
            np.linalg.norm(momentum_world - momentum_world[0], axis=1).max() / momentum[0])


@pytest.mark.parametrize('name', ['torque_free', 'dzhanibekov'])
def test_torque_free_conserves_energy_and_angular_momentum(name):
    """Kinetic energy, |I w| and the world-frame R I w: required < 1e-10, measured ~1e-14."""
    energy, momentum, momentum_world = invariant_drift(name)
    assert energy < 1e-12
    assert momentum < 1e-12
    assert momentum_world < 1e-12


def test_torque_free_symmetric_top_precesses_analytically():
    """I1 = I2: w3 constant and (w1, w2) turning at (I3 - I1) / I1 w3 (Landau-Lifshitz 33)."""
    inertia = [2.0, 2.0, 3.0]
    w0 = np.array([0.4, -0.3, 2.5])
    t = np.linspace(0.0, 20.0, 2001)
    _, w = motions.motion_truth(spec.TorqueFree(inertia, [0, 0, 0, 1], w0), t, 20.0)
    rate = (inertia[2] - inertia[0]) / inertia[0] * w0[2]
    transverse = (w0[0] + 1j * w0[1]) * np.exp(1j * rate * t)
    np.testing.assert_allclose(w[:, 0] + 1j * w[:, 1], transverse, rtol=0, atol=1e-11)
    np.testing.assert_allclose(w[:, 2], w0[2], rtol=0, atol=1e-13)


def test_torque_free_matches_a_tight_reference_integration():
    """Against scipy DOP853 at rtol 1e-13 on (q, w): agreement to ~1e-12 over 10 s."""
    motion = MOTIONS['torque_free']
    inertia, q0, w0 = (np.asarray(x, dtype=float)
                       for x in (motion.inertia, motion.orientation, motion.angular_velocity))
    t = np.linspace(0.0, 10.0, 1001)

    def rhs(_, y):
        q, w = y[:4], y[4:]
        q_dot = 0.5 * np.append(q[3] * w + np.cross(q[:3], w), -q[:3] @ w)
        return np.concatenate((q_dot, np.cross(inertia * w, w) / inertia))

    reference = solve_ivp(rhs, (0.0, 10.0), np.concatenate((q0, w0)), method='DOP853',
                          t_eval=t, rtol=1e-13, atol=1e-14).y.T
    q, w = motions.motion_truth(motion, t, 10.0)
    assert np.abs(w - reference[:, 4:]).max() < 1e-10
    assert geodesic_distance(q, reference[:, :4]).max() < 1e-10


def test_tumbling_box_scene_flips_about_its_intermediate_axis():
    """Dzhanibekov: the spin about body y reverses, and back, within the scene."""
    scene = spec.load_scene(os.path.join(SCENES_DIR, 'tumbling_box.yaml'))
    inertia = np.asarray(scene.motion.inertia)
    assert np.argsort(inertia)[1] == 1   # body y is the intermediate axis
    simulation = simulate(scene)
    w_y = simulation.truth_angular_velocity[:, 1]
    reversals = np.count_nonzero(np.diff(np.sign(w_y)) != 0)
    assert reversals >= 3
    assert w_y.min() < -0.99 * w_y[0]
    # The body y axis points along -y in the world, halfway through a flip.
    y_world = Rotation.from_quat(simulation.truth_orientation).apply([0.0, 1.0, 0.0])
    assert y_world[:, 1].min() < -0.99


@pytest.mark.parametrize('seq', ['ZYX', 'xyz', 'zxz', 'YXY'])
def test_euler_sweep_follows_its_angles(seq):
    start, end, duration = np.array([0.3, -0.2, 1.0]), np.array([-1.0, 0.4, 2.0]), 2.0
    t = np.linspace(0.0, duration, 201)
    q, _ = motions.motion_truth(spec.EulerSweep(seq, start, end), t, duration)
    angles = start + (end - start) * (t / duration)[:, None]
    assert geodesic_distance(q, Rotation.from_euler(seq, angles).as_quat()).max() < 1e-14
    assert geodesic_distance(q[-1], Rotation.from_euler(seq, end).as_quat()) < 1e-14


def test_gimbal_lock_scene_passes_through_the_singularity():
    scene = spec.load_scene(os.path.join(SCENES_DIR, 'gimbal_lock_sweep.yaml'))
    simulation = simulate(scene)
    margin = rc.euler_singularity_margin(simulation.truth_orientation, scene.motion.sequence)
    assert margin.min() < 1e-12
    assert margin[0] > 0.3 and margin[-1] > 0.3
    assert np.all(np.isfinite(simulation.truth_angular_velocity))


def test_motion_truth_dispatches_on_the_scene_motion():
    t = np.linspace(0.0, 1.0, 11)
    coning = spec.Coning(half_angle=0.3, frequency=2.0)
    q, w = motions.motion_truth(coning, t, 1.0)
    expected_q, expected_w = motions.coning_truth(0.3, 2.0, t)
    np.testing.assert_array_equal(q, expected_q)
    np.testing.assert_array_equal(w, expected_w)
