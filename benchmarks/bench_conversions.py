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
  (target >= 2, >= 3 for Euler angles);
- memory floor: the time numpy takes to read the batch's input bytes and
  write its output bytes once (``_machine.copy_floor``), per rotation, and the
  package's batch time as a multiple of it;
- growth: time per rotation from 10^2 to 10^6 samples for both.

The first lines say where it ran: CPU model, the SIMD levels numpy found
(its ``arctan2``, for one, is SIMD only with AVX-512) and the CPU numba
compiled the kernels for.

Times are the best of several repeats (``timeit``), after a warm-up call that
also loads the compiled kernels. Single samples are timed in turns of 200
calls, the three calls of a row interleaved, in several passes through all
rows: a microsecond call on a shared machine needs many turns, spread over
time, before its best settles. Usage::

    python benchmarks/bench_conversions.py [--quick] [--json results.json]
"""
import argparse
import json
import math
import sys

from _machine import best_seconds, copy_floor, print_machine
import numpy as np
from rotation_node import conversions as rc
from scipy.spatial.transform import Rotation

SEQ = 'xyz'


def _inputs(n, rng):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    rotation = Rotation.from_quat(q)
    v = rotation.as_rotvec()
    return {
        'q': q, 'R': rotation.as_matrix(), 'v': v, 'angles': rotation.as_euler(SEQ),
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
    """Best time per call of each function, measured in turns (so that drifts hit all alike)."""
    best = [math.inf] * len(functions)
    for _ in range(repeat):
        for i, function in enumerate(functions):
            best[i] = min(best[i], _best_time(function, data, number, 1))
    return best


def _reference(data):
    """Return the single-sample yardstick: scipy's quaternion to Euler angles."""
    return Rotation.from_quat(data['q']).as_euler(SEQ)


def _single(data):
    return {key: value[0] for key, value in data.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--quick', action='store_true', help='fewer repeats, batches up to 10^5')
    parser.add_argument('--json', help='also write the results to this JSON file')
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    largest = 5 if args.quick else 6
    sizes = [10 ** k for k in range(2, largest + 1)]
    batches = {n: _inputs(n, rng) for n in sizes}
    single = _single(batches[sizes[0]])
    repeat = 3 if args.quick else 7
    results = {}

    passes, turns = 4, 5 * repeat
    print_machine()
    print(f'rotation_node.conversions vs scipy {__import__("scipy").__version__} '
          f'(numpy {np.__version__}); batches best of {repeat}; single samples best of '
          f'{passes} passes over all rows x {turns} interleaved turns of 200 calls')
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
          f'{"10^%d: ours" % largest:>12s} {"scipy":>9s} {"speed-up":>9s} {"floor":>8s} '
          f'{"/floor":>7s}')
    for name, (ours, theirs, target, keys) in CONVERSIONS.items():
        single_ours, single_scipy, single_reference = single_best[name]
        growth = {}
        for n in sizes:
            number = max(1, 10 ** 5 // n)
            growth[n] = (_best_time(ours, batches[n], number, repeat) / n,
                         _best_time(theirs, batches[n], number, repeat) / n)
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
            'floor_ns': floor * 1e9, 'floor_ratio': batch_ours / floor,
            'growth_ns': {str(n): [o * 1e9, s * 1e9] for n, (o, s) in growth.items()},
        }
        r = results[name]
        print(f'{name:34s} {r["single_us"]:10.2f} us {r["single_scipy_us"]:6.2f} us '
              f'{r["single_reference_us"]:6.2f} us {r["single_ratio"]:7.3f}   '
              f'{r["batch_ns"]:9.1f} ns {r["batch_scipy_ns"]:6.1f} ns '
              f'{r["batch_speedup"]:8.1f}x {r["floor_ns"]:5.1f} ns '
              f'{r["floor_ratio"]:6.1f}x')

    print('\ntime per rotation (ns) as the batch grows, ours / scipy')
    print(f'{"conversion":34s} ' + ' '.join(f'{"10^%d" % int(np.log10(n)):>13s}' for n in sizes))
    for name, r in results.items():
        cells = ' '.join(f'{o:6.1f}/{s:<6.1f}' for o, s in r['growth_ns'].values())
        print(f'{name:34s} {cells}')

    worst_single = max(r['single_ratio'] for r in results.values())
    misses = [n for n, r in results.items() if r['batch_speedup'] < r['batch_target']]
    print(f'\nworst single-sample ratio: {worst_single:.3f} (target <= 0.10)')
    print(f'batch targets missed: {", ".join(misses) if misses else "none"}')
    worst_floor = max(results.items(), key=lambda item: item[1]['floor_ratio'])
    print(f'memory floor: every batch of 10^{largest} within '
          f'{worst_floor[1]["floor_ratio"]:.1f}x of the time to read its input and write its '
          f'output once (numpy copy, one thread), worst {worst_floor[0]}')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
