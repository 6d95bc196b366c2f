#!/usr/bin/env python3
"""
Benchmark rotation_node.conversions against scipy.spatial.transform, side by side in one run.

For every conversion it prints, measured in this run on this machine:

- single sample: time per call (shape (4,), (3,) or (3, 3), validation
  included) for the package and for scipy's corresponding call, and the ratio
  of the package's time to the reference, scipy's
  ``Rotation.from_quat(q).as_euler(seq)`` (target <= 0.10 for every
  conversion), measured next to each row;
- batch of 10^6: time per rotation for both and the speed-up scipy / package
  (target >= 2, >= 3 for Euler angles), measured in several rounds (the two
  calls interleaved in each) and printed as the range over the rounds;
- memory floor: the time numpy takes to read the batch's input bytes and
  write its output bytes once (``_machine.copy_floor``), per rotation, and the
  package's batch time as a multiple of it;
- growth: time per rotation from 10^2 to 10^6 samples for both;
- peers beyond scipy, in several rounds, every call of a group interleaved
  in each round, the ratio package / peer printed as the range over the
  rounds: ``quaternion_product`` and ``rotate_vector`` against
  numpy-quaternion (10^6 samples and one), on its own quaternion arrays (no
  conversion counted) and from the package's ``(x, y, z, w)`` float arrays
  (the conversion to its scalar-first layout and, for the product, back
  counted); ``euler_from_quaternion``, ``quaternion_from_euler``,
  ``matrix_from_quaternion``, ``rotate_vector`` and ``quaternion_product`` of
  one sample given as an ndarray, a list and a tuple of Python floats and as
  geometry_msgs Quaternion and Vector3 objects (a ROS message's fields as a
  callback has them), against the plain-Python ``math`` formula, with the
  ratios list / ndarray, tuple / ndarray, message / ndarray and package /
  formula of each round (``--single``: only the
  groups of one sample).

The first lines say where it ran: CPU model, the SIMD levels numpy found
(its ``arctan2``, for one, is SIMD only with AVX-512), the CPU numba
compiled the kernels for, the load average and the threads of large
batches; the load average is printed again at the end.

Times are the best of several repeats (``timeit``), after a warm-up call that
also loads the compiled kernels. Single samples are timed in turns of 200
calls, the three calls of a row interleaved, in several passes through all
rows: a microsecond call on a shared machine needs many turns, spread over
time, before its best settles. Usage::

    python benchmarks/bench_conversions.py [--quick] [--single] [--rounds 5] [--json results.json]
"""
import argparse
import json
import math
import os
import sys

from _machine import best_seconds, copy_floor, load_line, print_machine
import numpy as np
import quaternion
from rotation_node import conversions as rc
from rotation_node.conversions import _runtime
from scipy.spatial.transform import Rotation

SEQ = 'xyz'


def _inputs(n, rng):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q_other = rng.normal(size=(n, 4))
    q_other /= np.linalg.norm(q_other, axis=-1, keepdims=True)
    rotation = Rotation.from_quat(q)
    v = rotation.as_rotvec()
    return {
        'q': q, 'q_other': q_other, 'R': rotation.as_matrix(), 'v': v,
        'angles': rotation.as_euler(SEQ),
        'axis': v / np.linalg.norm(v, axis=-1, keepdims=True), 'angle': np.linalg.norm(v, axis=-1),
    }


# name -> (package call, scipy call, target batch speed-up, the inputs it reads)
CONVERSIONS = {
    'matrix_from_quaternion': (lambda d: rc.matrix_from_quaternion(d['q']),
                               lambda d: Rotation.from_quat(d['q']).as_matrix(), 2.0, ('q',)),
    'quaternion_from_matrix': (lambda d: rc.quaternion_from_matrix(d['R']),
                               lambda d: Rotation.from_matrix(d['R']).as_quat(), 2.0, ('R',)),
    'euler_from_quaternion': (lambda d: rc.euler_from_quaternion(d['q'], SEQ),
                              lambda d: Rotation.from_quat(d['q']).as_euler(SEQ), 3.0, ('q',)),
    'quaternion_from_euler': (lambda d: rc.quaternion_from_euler(d['angles'], SEQ),
                              lambda d: Rotation.from_euler(SEQ, d['angles']).as_quat(),
                              3.0, ('angles',)),
    'euler_from_matrix': (lambda d: rc.euler_from_matrix(d['R'], SEQ),
                          lambda d: Rotation.from_matrix(d['R']).as_euler(SEQ), 3.0, ('R',)),
    'matrix_from_euler': (lambda d: rc.matrix_from_euler(d['angles'], SEQ),
                          lambda d: Rotation.from_euler(SEQ, d['angles']).as_matrix(),
                          3.0, ('angles',)),
    'rotation_vector_from_quaternion': (lambda d: rc.rotation_vector_from_quaternion(d['q']),
                                        lambda d: Rotation.from_quat(d['q']).as_rotvec(),
                                        2.0, ('q',)),
    'quaternion_from_rotation_vector': (lambda d: rc.quaternion_from_rotation_vector(d['v']),
                                        lambda d: Rotation.from_rotvec(d['v']).as_quat(),
                                        2.0, ('v',)),
    'rotation_vector_from_matrix': (lambda d: rc.rotation_vector_from_matrix(d['R']),
                                    lambda d: Rotation.from_matrix(d['R']).as_rotvec(),
                                    2.0, ('R',)),
    'matrix_from_rotation_vector': (lambda d: rc.matrix_from_rotation_vector(d['v']),
                                    lambda d: Rotation.from_rotvec(d['v']).as_matrix(),
                                    2.0, ('v',)),
    'axis_angle_from_quaternion': (lambda d: rc.axis_angle_from_quaternion(d['q']),
                                   lambda d: Rotation.from_quat(d['q']).as_rotvec(), 2.0, ('q',)),
    'quaternion_from_axis_angle': (lambda d: rc.quaternion_from_axis_angle(d['axis'], d['angle']),
                                   lambda d: Rotation.from_rotvec(
                                       d['axis'] * d['angle'][..., None]).as_quat(),
                                   2.0, ('axis', 'angle')),
}


def _best_time(function, data, number, repeat):
    return best_seconds(lambda: function(data), number, repeat)


def _floor_time(function, keys, data, repeat):
    """Best time of :func:`copy_floor` for ``function``'s inputs and outputs."""
    outputs = function(data)
    size = sum(np.size(a) for a in (outputs if isinstance(outputs, tuple) else (outputs,)))
    return best_seconds(copy_floor([data[key] for key in keys], (size,)), 1, repeat)


def _interleaved_best_times(functions, data, number, repeat):
    """
    Best time per call of each function, measured in turns (so that drifts hit all alike).

    Each turn starts with the next function: a large call is slower right
    after one that freed arrays of another size (its output's pages are new
    to the process), so no function keeps the first place.
    """
    best = [math.inf] * len(functions)
    for turn in range(repeat):
        for j in range(len(functions)):
            i = (turn + j) % len(functions)
            best[i] = min(best[i], _best_time(functions[i], data, number, 1))
    return best


def _euler_formula(q):
    """Return roll, pitch, yaw (extrinsic xyz) of a unit ``(x, y, z, w)``: the pasted formula."""
    x, y, z, w = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def _quaternion_formula(angles):
    """Return the unit ``(x, y, z, w)`` of roll, pitch, yaw (extrinsic xyz): the pasted formula."""
    roll, pitch, yaw = angles
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def _matrix_formula(q):
    """Return the rotation matrix (nested lists) of a unit ``(x, y, z, w)``: the pasted formula."""
    x, y, z, w = q
    return [[1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
            [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
            [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)]]


def _rotate_formula(q, v):
    """Return ``v`` rotated by a unit ``(x, y, z, w)`` (``v + w t + u x t``, ``t = 2 u x v``)."""
    x, y, z, w = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    return (vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz,
            vz + w * tz + x * ty - y * tx)


def _product_formula(p, q):
    """Return the Hamilton product of two ``(x, y, z, w)``: the pasted formula."""
    x1, y1, z1, w1 = p
    x2, y2, z2, w2 = q
    return (w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2)


#: The groups of :func:`_python_value_groups`.
_PYTHON_VALUE_GROUPS = tuple(f'{name}, 1 sample from Python values' for name in (
    'euler_from_quaternion', 'quaternion_from_euler', 'matrix_from_quaternion', 'rotate_vector',
    'quaternion_product'))


def _python_value_groups(single):
    """
    Return the groups of one sample from Python values, as :func:`_peer_groups` does.

    Each operation on one sample given as a float64 ndarray, a list and a
    tuple of Python floats (what a ROS message's fields give), geometry_msgs
    Quaternion and Vector3 objects (a message's fields as they come), and
    the plain-Python ``math`` formula on the list (what people paste into a
    callback; exact only where the library is, see accuracy.md).
    """
    from geometry_msgs.msg import Quaternion, Vector3
    p1, q1, v1, angles = single['q'], single['q_other'], single['v'], single['angles']
    operations = {
        'euler_from_quaternion': (lambda q: rc.euler_from_quaternion(q, SEQ), (p1,),
                                  _euler_formula),
        'quaternion_from_euler': (lambda a: rc.quaternion_from_euler(a, SEQ), (angles,),
                                  _quaternion_formula),
        'matrix_from_quaternion': (rc.matrix_from_quaternion, (p1,), _matrix_formula),
        'rotate_vector': (rc.rotate_vector, (q1, v1), _rotate_formula),
        'quaternion_product': (rc.quaternion_product, (p1, q1), _product_formula),
    }
    groups = {}
    assert tuple(f'{name}, 1 sample from Python values'
                 for name in operations) == _PYTHON_VALUE_GROUPS
    for name, (ours, arrays, formula) in operations.items():
        lists = [a.tolist() for a in arrays]
        tuples = [tuple(a) for a in lists]
        messages = [Quaternion(**dict(zip('xyzw', x))) if len(x) == 4 else
                    Vector3(**dict(zip('xyz', x))) for x in lists]
        groups[f'{name}, 1 sample from Python values'] = (1, 200, {
            'rotation_node, ndarray': lambda ours=ours, x=arrays: ours(*x),
            'rotation_node, list': lambda ours=ours, x=lists: ours(*x),
            'rotation_node, tuple': lambda ours=ours, x=tuples: ours(*x),
            'rotation_node, geometry_msgs': lambda ours=ours, x=messages: ours(*x),
            'plain-Python math formula, list': lambda formula=formula, x=lists: formula(*x),
        }, None)
    return groups


def _scalar_first(q):
    """Return numpy-quaternion's array of ``(x, y, z, w)`` float quaternions (scalar first)."""
    return quaternion.from_float_array(q.take((3, 0, 1, 2), axis=-1))


def _quaternion_of(q):
    """Return numpy-quaternion's quaternion of one ``(x, y, z, w)`` ndarray."""
    x, y, z, w = q.tolist()
    return quaternion.quaternion(w, x, y, z)


def _rotated(a, v):
    """Return ``a v a*`` on numpy-quaternion's arrays (``v``: float vectors): pairs rotated."""
    return quaternion.as_vector_part(a * quaternion.from_vector_part(v) * a.conjugate())


def _rotated_one(a, v):
    """Return ``a v a*`` for one numpy-quaternion quaternion and one vector (ndarray (3,))."""
    return (a * quaternion.quaternion(0.0, *v.tolist()) * a.conjugate()).vec


#: The library's default for large batches: ROTATION_NODE_THREADS, else the usable CPUs.
THREADS = int(os.environ.get('ROTATION_NODE_THREADS', 0)) or len(os.sched_getaffinity(0))


def _peer_groups(batch, single):
    """
    Return ``{group: (number of samples, calls per turn, {call name: call}, threads)}``.

    The first call of a group is the package's; ``threads``: ``set_threads``
    for the group (the largest batches again on one thread, after the
    default), None: the default.

    numpy-quaternion's product and rotation ``q v q*`` (``v`` as a pure
    quaternion) on its own quaternions, and from ``(x, y, z, w)`` float
    arrays with the conversions counted (a batch: ``from_float_array``,
    ``as_float_array`` and a column reorder; one sample: its scalar
    ``quaternion`` type from Python floats, the cheapest way measured).
    """
    n = batch['q'].shape[0]
    p, q, v = batch['q'], batch['q_other'], batch['v']
    a, b = _scalar_first(p), _scalar_first(q)
    groups = {
        f'quaternion_product, 10^{len(str(n)) - 1}': (n, 1, {
            'rotation_node (x, y, z, w) arrays': lambda: rc.quaternion_product(p, q),
            'numpy-quaternion, its quaternions': lambda: a * b,
            'numpy-quaternion from (x, y, z, w)': lambda: quaternion.as_float_array(
                _scalar_first(p) * _scalar_first(q)).take((1, 2, 3, 0), axis=-1),
        }),
        f'rotate_vector, 10^{len(str(n)) - 1}': (n, 1, {
            'rotation_node (x, y, z, w) arrays': lambda: rc.rotate_vector(q, v),
            'numpy-quaternion, its quaternions': lambda: _rotated(b, v),
            'numpy-quaternion from (x, y, z, w)': lambda: _rotated(_scalar_first(q), v),
        }),
    }
    for name in list(groups):
        groups[name] += (None,)
        groups[f'{name}, one thread'] = groups[name][:3] + (1,)
    p1, q1, v1 = single['q'], single['q_other'], single['v']
    a1, b1 = _quaternion_of(p1), _quaternion_of(q1)

    def product_from_arrays():
        r = _quaternion_of(p1) * _quaternion_of(q1)
        return np.array([r.x, r.y, r.z, r.w])

    groups['quaternion_product, 1 sample'] = (1, 200, {
        'rotation_node (x, y, z, w) ndarray': lambda: rc.quaternion_product(p1, q1),
        'numpy-quaternion, its quaternions': lambda: a1 * b1,
        'numpy-quaternion from (x, y, z, w)': product_from_arrays,
    }, None)
    groups['rotate_vector, 1 sample'] = (1, 200, {
        'rotation_node (x, y, z, w) ndarray': lambda: rc.rotate_vector(q1, v1),
        'numpy-quaternion, its quaternions': lambda: _rotated_one(b1, v1),
        'numpy-quaternion from (x, y, z, w)': lambda: _rotated_one(_quaternion_of(q1), v1),
    }, None)
    groups.update(_python_value_groups(single))
    return groups


def _check_peers(groups):
    """
    Raise AssertionError unless every call of a group gives the same result (1e-12).

    Quaternions may differ in sign (the package's are canonical, w >= 0);
    the package's own calls of a group must agree bit for bit.
    """
    for name, (_, _, calls, _) in groups.items():
        results = []
        for call in calls.values():
            out = call()
            if isinstance(out, np.quaternion) or getattr(out, 'dtype', None) == np.quaternion:
                out = quaternion.as_float_array(out).take((1, 2, 3, 0), axis=-1)
            results.append(np.asarray(out, dtype=float))
        for call, other in zip(list(calls)[1:], results[1:]):
            if call.startswith('rotation_node'):
                assert results[0].tobytes() == other.tobytes(), (name, call)
            assert (np.allclose(results[0], other, rtol=0, atol=1e-12)
                    or np.allclose(results[0], -other, rtol=0, atol=1e-12)), (name, call)


def _peer_rounds(groups, rounds, turns):
    """
    Return the best time per sample of each call, per round, a group's calls interleaved.

    Returns ``{group: {call: [seconds per sample in each round]}}``.
    """
    times = {name: {call: [] for call in calls} for name, (_, _, calls, _) in groups.items()}
    for _ in range(rounds):
        for name, (size, number, calls, threads) in groups.items():
            rc.set_threads(threads or THREADS)
            best = _interleaved_best_times(
                [lambda _, call=call: call() for call in calls.values()], None, number, turns)
            rc.set_threads(THREADS)
            for call, seconds in zip(calls, best):
                times[name][call].append(seconds / size)
    return times


def _print_peers(groups, times, rounds):
    print(f'\npeers, {rounds} rounds, the calls of a group interleaved in each; time per sample '
          'is the best over the rounds, ratio = first call / this call in each round, min to max')
    print(f'{"operation":52s} {"call":38s} {"best":>10s} {"ratio first/this":>17s}')
    for name, per_call in times.items():
        ours = next(iter(per_call.values()))
        for k, (call, seconds) in enumerate(per_call.items()):
            ratios = [a / b for a, b in zip(ours, seconds)]
            span = '' if k == 0 else f'{min(ratios):6.2f} to {max(ratios):5.2f}'
            best = min(seconds)
            shown = f'{best * 1e9:7.1f} ns' if best < 1e-6 else f'{best * 1e6:7.2f} us'
            print(f'{name if k == 0 else "":52s} {call:38s} {shown:>10s} {span:>17s}')


def _warm_python_values(groups):
    """
    Call the Python-value groups' calls into the steady state of a caller of many samples.

    A loaded kernel loads its tuple form once it has copied ``TUPLE_COPIES``
    single samples given as lists or tuples into arrays (at once with
    ROTATION_NODE_COMPILED=1); that load is not what the rows measure.
    """
    _runtime.compile_kernels()   # loaded (from the cache), as in a long-running caller
    copies = 2 if _runtime._loading_forced else _runtime.TUPLE_COPIES + 2
    for name, (_, _, group_calls, _) in groups.items():
        if name in _PYTHON_VALUE_GROUPS:
            for call in group_calls.values():
                for _ in range(copies):
                    call()


def _print_python_values(times):
    """Print, per operation, list / ndarray, tuple / ndarray and ours / formula, each round."""
    print('\none sample from Python values: time ratios in each round, min to max '
          '(message: geometry_msgs Quaternion and Vector3 objects)')
    print(f'{"operation":52s} {"list/ndarray":>14s} {"tuple/ndarray":>14s} '
          f'{"message/ndarray":>16s} {"ndarray/formula":>16s} {"list/formula":>14s} '
          f'{"tuple/formula":>14s}')
    summary = {}
    for name, per_call in times.items():
        if name not in _PYTHON_VALUE_GROUPS:
            continue
        ndarray, listed, tupled, message, formula = per_call.values()
        ratios = {'list/ndarray': (listed, ndarray), 'tuple/ndarray': (tupled, ndarray),
                  'message/ndarray': (message, ndarray),
                  'ndarray/formula': (ndarray, formula), 'list/formula': (listed, formula),
                  'tuple/formula': (tupled, formula)}
        summary[name] = {key: [a / b for a, b in zip(*pair)] for key, pair in ratios.items()}
        cells = ' '.join(f'{min(r):6.2f}-{max(r):<5.2f}'.rjust(width) for r, width in zip(
            summary[name].values(), (14, 14, 16, 16, 14, 14)))
        print(f'{name:52s} {cells}')
    return summary


def _reference(data):
    """Return the single-sample yardstick: scipy's quaternion to Euler angles."""
    return Rotation.from_quat(data['q']).as_euler(SEQ)


def _single(data):
    return {key: value[0] for key, value in data.items()}


def _main_single(args):
    """``--single``: the groups of one sample only, in rounds; print them and the ratios."""
    rounds = args.rounds or (3 if args.quick else 5)
    data = _inputs(100, np.random.default_rng(0))
    print_machine()
    groups = {name: group for name, group in _peer_groups(data, _single(data)).items()
              if group[0] == 1}
    _check_peers(groups)
    _warm_python_values(groups)
    print(f'one sample, {rounds} rounds of {3 if args.quick else 5} interleaved turns of 200 '
          'calls per group')
    peers = _peer_rounds(groups, rounds, 3 if args.quick else 5)
    _print_peers(groups, peers, rounds)
    ratios = _print_python_values(peers)
    print(load_line().replace('load average', 'at the end: load average'))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump({'peers': {
                group: {call: {'best_ns': min(seconds) * 1e9, 'round_ns': [
                    x * 1e9 for x in seconds]} for call, seconds in per_call.items()}
                for group, per_call in peers.items()}, 'python_values': ratios}, f, indent=1)
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--quick', action='store_true',
                        help='fewer repeats, one pass of the single samples, batches up to 10^5')
    parser.add_argument('--rounds', type=int, default=None,
                        help='rounds of the batch and peer comparisons (5; --quick: 3)')
    parser.add_argument('--json', help='also write the results to this JSON file')
    parser.add_argument('--single', action='store_true',
                        help='only one sample: from Python values (ndarray, list, tuple, the '
                             'plain-Python formula) and against numpy-quaternion')
    args = parser.parse_args(argv)
    if args.single:
        return _main_single(args)
    rng = np.random.default_rng(0)
    largest = 5 if args.quick else 6
    sizes = [10 ** k for k in range(2, largest + 1)]
    batches = {n: _inputs(n, rng) for n in sizes}
    single = _single(batches[sizes[0]])
    repeat = 3 if args.quick else 7
    rounds = args.rounds or (3 if args.quick else 5)
    results = {}

    passes, turns = (1 if args.quick else 4), 5 * repeat
    print_machine()
    print(f'rotation_node.conversions vs scipy {__import__("scipy").__version__} '
          f'(numpy {np.__version__}); batches best of {repeat}; single samples best of '
          f'{passes} passes over all rows x {turns} interleaved turns of 200 calls; '
          f'10^{largest}: {rounds} rounds, best of 2 each, ours and scipy interleaved')
    print('single: ratio = ours / scipy Rotation.from_quat(q).as_euler(seq), the reference '
          'measured next to each row')
    for ours, theirs, *_ in CONVERSIONS.values():
        ours(single), theirs(single), ours(batches[sizes[-1]])  # warm up, load kernels
    # Single samples: many short turns, in several passes through all rows, so
    # that neither a slow second nor a slow phase of the machine decides a row.
    single_best = {name: [math.inf] * 3 for name in CONVERSIONS}
    for _ in range(passes):
        for name, (ours, theirs, *_) in CONVERSIONS.items():
            times = _interleaved_best_times((ours, theirs, _reference), single, 200, turns)
            single_best[name] = [min(a, b) for a, b in zip(single_best[name], times)]

    print(f'\n{"conversion":34s} {"single: ours":>13s} {"scipy":>9s} {"ref.":>9s} {"ratio":>7s}   '
          f'{"10^%d: ours" % largest:>12s} {"scipy":>9s} {"speed-up":>9s} {"rounds":>13s} '
          f'{"floor":>8s} {"/floor":>7s}')
    for name, (ours, theirs, target, keys) in CONVERSIONS.items():
        single_ours, single_scipy, single_reference = single_best[name]
        growth = {}
        for n in sizes[:-1]:
            number = max(1, 10 ** 5 // n)
            growth[n] = (_best_time(ours, batches[n], number, repeat) / n,
                         _best_time(theirs, batches[n], number, repeat) / n)
        # The largest batch: both in turns, in rounds; the speed-up of each round.
        per_round = [_interleaved_best_times((ours, theirs), batches[sizes[-1]], 1, 2)
                     for _ in range(rounds)]
        speedups = [s / o for o, s in per_round]
        growth[sizes[-1]] = (min(o for o, _ in per_round) / sizes[-1],
                             min(s for _, s in per_round) / sizes[-1])
        batch_ours, batch_scipy = growth[sizes[-1]]
        floor = _floor_time(ours, keys, batches[sizes[-1]], repeat) / sizes[-1]
        results[name] = {
            'single_us': single_ours * 1e6, 'single_scipy_us': single_scipy * 1e6,
            'single_reference_us': single_reference * 1e6,
            'single_ratio': single_ours / single_reference,
            'single_ratio_same_call': single_ours / single_scipy,
            'batch_n': sizes[-1], 'batch_ns': batch_ours * 1e9,
            'batch_scipy_ns': batch_scipy * 1e9,
            'batch_speedup': batch_scipy / batch_ours, 'batch_target': target,
            'batch_speedup_rounds': speedups,
            'floor_ns': floor * 1e9, 'floor_ratio': batch_ours / floor,
            'growth_ns': {str(n): [o * 1e9, s * 1e9] for n, (o, s) in growth.items()},
        }
        r = results[name]
        print(f'{name:34s} {r["single_us"]:10.2f} us {r["single_scipy_us"]:6.2f} us '
              f'{r["single_reference_us"]:6.2f} us {r["single_ratio"]:7.3f}   '
              f'{r["batch_ns"]:9.1f} ns {r["batch_scipy_ns"]:6.1f} ns '
              f'{r["batch_speedup"]:8.1f}x {min(speedups):5.1f} to {max(speedups):4.1f}x '
              f'{r["floor_ns"]:5.1f} ns {r["floor_ratio"]:6.1f}x')

    print('\ntime per rotation (ns) as the batch grows, ours / scipy')
    print(f'{"conversion":34s} ' + ' '.join(f'{"10^%d" % int(np.log10(n)):>13s}' for n in sizes))
    for name, r in results.items():
        cells = ' '.join(f'{o:6.1f}/{s:<6.1f}' for o, s in r['growth_ns'].values())
        print(f'{name:52s} {cells}')

    groups = _peer_groups(batches[sizes[-1]], single)
    _check_peers(groups)
    _warm_python_values(groups)
    peers = _peer_rounds(groups, rounds, 3 if args.quick else 5)
    _print_peers(groups, peers, rounds)
    _print_python_values(peers)

    worst_single = max(r['single_ratio'] for r in results.values())
    misses = [n for n, r in results.items() if r['batch_speedup'] < r['batch_target']]
    print(f'\nworst single-sample ratio: {worst_single:.3f} (target <= 0.10)')
    print(f'batch targets missed: {", ".join(misses) if misses else "none"}')
    low = min(results.items(), key=lambda item: min(item[1]['batch_speedup_rounds']))
    high = max(results.items(), key=lambda item: max(item[1]['batch_speedup_rounds']))
    euler = [s for n, r in results.items() if 'euler' in n for s in r['batch_speedup_rounds']]
    print(f'batch speed-ups over scipy, every round: {min(low[1]["batch_speedup_rounds"]):.1f}x '
          f'({low[0]}) to {max(high[1]["batch_speedup_rounds"]):.1f}x ({high[0]}); '
          f'Euler angles {min(euler):.1f}x to {max(euler):.1f}x')
    worst_floor = max(results.items(), key=lambda item: item[1]['floor_ratio'])
    print(f'memory floor: every batch of 10^{largest} within '
          f'{worst_floor[1]["floor_ratio"]:.1f}x of the time to read its input and write its '
          f'output once (numpy copy, one thread), worst {worst_floor[0]}')
    print(load_line().replace('load average', 'at the end: load average'))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump({'conversions': results, 'peers': {
                group: {call: {'best_ns': min(seconds) * 1e9, 'round_ns': [
                    x * 1e9 for x in seconds]} for call, seconds in per_call.items()}
                for group, per_call in peers.items()}}, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
