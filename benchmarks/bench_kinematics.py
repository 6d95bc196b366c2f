#!/usr/bin/env python3
"""
Benchmark rotation_node.kinematics against plain numpy / scipy peers, side by side in one run.

Printed, all measured in this run on this machine:

1. single sample (what the node does per message): time per call, validation
   included, of each public function and of a peer doing the same job without
   validation (numpy formula or scipy), and the ratio package / peer;
2. batch of 10^5 samples: time per sample for both, the speed-up peer /
   package, and the memory floor (numpy reading the inputs and writing an
   output of the same size once) with the package's time as a multiple of it;
3. attitude integration on coning motion (docs/numerics.md): for each method the
   largest geodesic error at 100 and 200 steps over 2 s, the observed order
   log2(e100 / e200), rate evaluations per step and time per step; scipy's
   ``solve_ivp`` (RK45, adaptive) on the same problem as the peer.

The first lines say where it ran (CPU model, numpy's SIMD levels, the CPU
numba compiled for). Times are the best of several ``timeit`` repeats after a warm-up call (which
also loads the compiled kernels). Usage::

    .venv/bin/python benchmarks/bench_kinematics.py [--quick]
"""
import argparse

from _machine import best_seconds, copy_floor, print_machine
import numpy as np
from rotation_node import conversions as rc
from rotation_node import kinematics as rk
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

CONE_HALF_ANGLE, CONE_RATE, DURATION = 0.3, 2.0, 2.0
EVALUATIONS = {'euler': 1, 'midpoint_exp': 1, 'rk4': 3, 'magnus4': 2, 'coning2': 4}


def best_time(function, number, repeat):
    function()
    return best_seconds(function, number, repeat)


# ---------------------------------------------------------------- peers (no validation)

def numpy_hamilton(p, q):
    """Hamilton product, scalar last, written out with numpy."""
    pv, ps, qv, qs = p[..., :3], p[..., 3:], q[..., :3], q[..., 3:]
    return np.concatenate([ps * qv + qs * pv + np.cross(pv, qv),
                           ps * qs - np.sum(pv * qv, -1, keepdims=True)], -1)


def numpy_quaternion_derivative(q, w):
    """``1/2 q (x) (w, 0)`` (body frame)."""
    return 0.5 * numpy_hamilton(q, np.concatenate([w, np.zeros(w.shape[:-1] + (1,))], -1))


def numpy_angular_velocity(q, q_dot):
    """``2 vec(q* (x) qdot)`` (body frame)."""
    return 2.0 * numpy_hamilton(q * [-1.0, -1.0, -1.0, 1.0], q_dot)[..., :3]


def numpy_euler_jacobian_xyz(angles):
    """``J`` with ``w_b = J rates`` for extrinsic xyz (ROS roll, pitch, yaw)."""
    roll, pitch = angles[..., 0], angles[..., 1]
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    zero, one = np.zeros_like(roll), np.ones_like(roll)
    return np.stack([np.stack([one, zero, -sp], -1),
                     np.stack([zero, cr, sr * cp], -1),
                     np.stack([zero, -sr, cr * cp], -1)], -2)


def numpy_euler_rates_xyz(angles, w):
    return np.linalg.solve(numpy_euler_jacobian_xyz(angles), w[..., None])[..., 0]


def numpy_angular_velocity_xyz(angles, rates):
    return (numpy_euler_jacobian_xyz(angles) @ rates[..., None])[..., 0]


def scipy_finite_difference(q, dt):
    r = Rotation.from_quat(q)
    return (r[:-1].inv() * r[1:]).as_rotvec() / dt


# ---------------------------------------------------------------- coning truth

def coning_orientation(t):
    s = np.sin(CONE_HALF_ANGLE / 2)
    return np.stack([s * np.cos(CONE_RATE * t), s * np.sin(CONE_RATE * t), np.zeros_like(t),
                     np.full_like(t, np.cos(CONE_HALF_ANGLE / 2))], -1)


def coning_rate(t):
    a, W = CONE_HALF_ANGLE, CONE_RATE
    return np.stack([-W * np.sin(a) * np.sin(W * t), W * np.sin(a) * np.cos(W * t),
                     np.full_like(t, -W * (1 - np.cos(a)))], -1)


def integration_error(method, steps):
    t = np.linspace(0.0, DURATION, steps + 1)
    q = rk.integrate_angular_velocity(coning_orientation(0.0), coning_rate, t, method=method)
    return rc.quaternion_distance(q, coning_orientation(t)).max()


def scipy_integration():
    def rhs(_, q):
        return numpy_quaternion_derivative(q, coning_rate(np.array(_)))

    t = np.linspace(0.0, DURATION, 101)
    solution = solve_ivp(rhs, (0.0, DURATION), coning_orientation(0.0), t_eval=t,
                         rtol=1e-10, atol=1e-12)
    return rc.quaternion_distance(solution.y.T, coning_orientation(t)).max(), solution.nfev


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer repeats')
    args = parser.parse_args(argv)
    number, repeat = (1000, 3) if args.quick else (5000, 5)
    rng = np.random.default_rng(1)
    print_machine()

    q = rc.canonical_quaternion(rng.normal(size=4))
    q2 = np.stack([q, rc.quaternion_product(q, rc.quaternion_from_rotation_vector([0, 0, 0.01]))])
    w = rng.normal(size=3)
    angles = np.array([0.3, -0.4, 1.2])
    R = rc.matrix_from_quaternion(q)
    single = [
        ('quaternion_derivative', lambda: rk.quaternion_derivative(q, w),
         'numpy formula', lambda: numpy_quaternion_derivative(q, w)),
        ('angular_velocity_from_quaternion_derivative',
         lambda: rk.angular_velocity_from_quaternion_derivative(q, q),
         'numpy formula', lambda: numpy_angular_velocity(q, q)),
        ('matrix_derivative', lambda: rk.matrix_derivative(R, w),
         'numpy R @ skew(w)', lambda: R @ np.cross(w, -np.eye(3))),
        ('euler_rates_from_angular_velocity', lambda: rk.euler_rates_from_angular_velocity(
            angles, w, 'xyz'), 'numpy solve', lambda: numpy_euler_rates_xyz(angles, w)),
        ('angular_velocity_from_euler_rates', lambda: rk.angular_velocity_from_euler_rates(
            angles, w, 'xyz'), 'numpy J @ r', lambda: numpy_angular_velocity_xyz(angles, w)),
        ('angular_velocity_from_quaternions (2)', lambda: rk.angular_velocity_from_quaternions(
            q2, [0.0, 0.01]), 'scipy Rotation', lambda: scipy_finite_difference(q2, 0.01)),
    ]
    print('1. single sample (us per call; package validates, peers do not)')
    print(f'   {"function":46s} {"package":>8s} {"peer":>8s}  ratio  peer')
    for name, ours, peer_name, peer in single:
        t_ours, t_peer = best_time(ours, number, repeat), best_time(peer, number, repeat)
        print(f'   {name:46s} {t_ours * 1e6:8.2f} {t_peer * 1e6:8.2f}  {t_ours / t_peer:5.2f}  '
              f'{peer_name}')

    n = 100_000
    qs = rc.canonical_quaternion(rng.normal(size=(n, 4)))
    ws = rng.normal(size=(n, 3))
    angle_batch = rng.uniform(-1.2, 1.2, size=(n, 3))
    t_series = np.arange(n) * 0.01
    series = rk.integrate_angular_velocity(qs[0], ws * 0.1, t_series, method='euler')
    batch = [   # name, package, peer, the package's inputs
        ('quaternion_derivative', lambda: rk.quaternion_derivative(qs, ws),
         lambda: numpy_quaternion_derivative(qs, ws), (qs, ws)),
        ('euler_rates_from_angular_velocity', lambda: rk.euler_rates_from_angular_velocity(
            angle_batch, ws, 'xyz'), lambda: numpy_euler_rates_xyz(angle_batch, ws),
         (angle_batch, ws)),
        ('angular_velocity_from_quaternions', lambda: rk.angular_velocity_from_quaternions(
            series, t_series), lambda: scipy_finite_difference(series, 0.01), (series, t_series)),
    ]
    print(f'\n2. batch of {n} (ns per sample)')
    print(f'   {"function":46s} {"package":>8s} {"peer":>8s}  speed-up {"floor":>7s} '
          f'{"/floor":>7s}')
    for name, ours, peer, inputs in batch:
        t_ours = best_time(ours, 1, max(3, repeat // 2)) / n
        t_peer = best_time(peer, 1, max(3, repeat // 2)) / n
        t_floor = best_time(copy_floor(inputs, ours().shape), 1, max(3, repeat // 2)) / n
        print(f'   {name:46s} {t_ours * 1e9:8.1f} {t_peer * 1e9:8.1f}  {t_peer / t_ours:6.1f}x '
              f'{t_floor * 1e9:7.2f} {t_ours / t_floor:6.1f}x')

    print(f'\n3. coning motion, {DURATION:g} s (half-angle {CONE_HALF_ANGLE}, {CONE_RATE} rad/s), '
          'rate function')
    print(f'   {"method":14s} {"err 100 steps":>14s} {"err 200 steps":>14s} {"order":>6s} '
          f'{"evals/step":>10s} {"us/step":>8s}')
    q0, t_1000 = coning_orientation(0.0), np.linspace(0.0, DURATION, 1001)
    for method in rk.INTEGRATION_METHODS:
        e100, e200 = integration_error(method, 100), integration_error(method, 200)
        t_step = best_time(lambda: rk.integrate_angular_velocity(
            q0, coning_rate, t_1000, method=method), 1, repeat) / 1000
        print(f'   {method:14s} {e100:14.2e} {e200:14.2e} {np.log2(e100 / e200):6.2f} '
              f'{EVALUATIONS[method]:10d} {t_step * 1e6:8.2f}')
    error, evaluations = scipy_integration()
    t_scipy = best_time(scipy_integration, 1, 3)
    print(f'   peer: scipy solve_ivp RK45 rtol 1e-10: error {error:.2e}, {evaluations} rate '
          f'evaluations, {t_scipy * 1e3:.1f} ms')


if __name__ == '__main__':
    main()
