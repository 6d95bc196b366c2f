#!/usr/bin/env python3
"""
Cold start: a new process imports the library and makes its first calls, against scipy's.

Each round starts two fresh Python processes, one after the other: one
imports ``rotation_node.conversions`` and calls a public function once for
each of several shapes (one sample, a (5, 4) batch, a (5, 2, 4) batch, a
read-only batch, a batch of 2000 for the batch schedule); the other imports
``scipy.spatial.transform`` and makes scipy's same calls. Times are measured
inside each process from before its first import (numpy included) to after
its last call; the process start itself is the same for both and not
counted. The kernels must be cached first (``python -m
rotation_node.conversions.warm_up``, which ``./run.sh`` runs after installing):
this measures a warm install, not a first compilation. Target: the package
within 2x of scipy, per conversion (median over rounds).

Usage::

    python benchmarks/bench_cold_start.py [--rounds 5] [--json results.json]
"""
import argparse
import json
import platform
import statistics
import subprocess
import sys

from _machine import cpu_model, print_machine

TARGET = 2.0

# conversion -> (package call, scipy call), both of a float64 array ``x`` of quaternions,
# rotation matrices or Euler angles as the conversion takes (``x`` is built by _PREAMBLE).
CONVERSIONS = {
    'euler_from_quaternion': ('rc.euler_from_quaternion(x, "xyz")',
                              'Rotation.from_quat(x).as_euler("xyz")'),
    'matrix_from_quaternion': ('rc.matrix_from_quaternion(x)',
                               'Rotation.from_quat(x).as_matrix()'),
    'quaternion_from_matrix': ('rc.quaternion_from_matrix(x)',
                               'Rotation.from_matrix(x).as_quat()'),
    'quaternion_from_euler': ('rc.quaternion_from_euler(x, "ZYX")',
                              'Rotation.from_euler("ZYX", x).as_quat()'),
    'rotation_vector_from_quaternion': ('rc.rotation_vector_from_quaternion(x)',
                                        'Rotation.from_quat(x).as_rotvec()'),
}
_SAMPLE = {'euler_from_quaternion': 'q', 'matrix_from_quaternion': 'q',
           'quaternion_from_matrix': 'm', 'quaternion_from_euler': 'a',
           'rotation_vector_from_quaternion': 'q'}

_PROGRAM = """
import time
start = time.perf_counter()
import numpy as np
{import_line}
imported = time.perf_counter()
one = {{'q': [0.1, 0.2, 0.3, 0.9], 'a': [0.3, -0.2, 0.1],
        'm': [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]}}[{kind!r}]
one = np.array(one, dtype=float)
read_only = np.broadcast_to(one, (7,) + one.shape)
for x in (one, np.broadcast_to(one, (5,) + one.shape).copy(),
          np.broadcast_to(one, (5, 2) + one.shape).copy(), read_only,
          np.broadcast_to(one, (2000,) + one.shape).copy()):
    {call}
end = time.perf_counter()
print(imported - start, end - imported)
"""


def _run(kind, import_line, call):
    code = _PROGRAM.format(import_line=import_line, kind=kind, call=call)
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True)
    import_time, calls_time = map(float, out.stdout.split())
    return import_time, calls_time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=5, help='fresh process pairs per conversion')
    parser.add_argument('--json', help='write the results to this file')
    args = parser.parse_args(argv)

    import numba
    import scipy
    print_machine()
    print(f'Python {platform.python_version()}, numba {numba.__version__}, '
          f'scipy {scipy.__version__}')
    check = subprocess.run([sys.executable, '-m', 'rotation_node.conversions.warm_up'],
                           capture_output=True, text=True, check=True)
    print(f'kernels: {check.stdout.strip()}')
    print('\nnew process: import (numpy included) + first calls with 5 shapes, seconds '
          f'(median of {args.rounds} rounds)')
    print(f'{"conversion":34s} {"package":>17s} {"scipy":>17s} {"ratio":>6s}  target <= {TARGET}')
    print(f'{"":34s} {"import":>8s} {"calls":>8s} {"import":>8s} {"calls":>8s}')
    results = {}
    for name, (ours, theirs) in CONVERSIONS.items():
        kind = _SAMPLE[name]
        rounds = []
        for _ in range(args.rounds):
            rounds.append((_run(kind, 'import rotation_node.conversions as rc', ours),
                           _run(kind, 'from scipy.spatial.transform import Rotation', theirs)))
        ours_import = statistics.median(r[0][0] for r in rounds)
        ours_calls = statistics.median(r[0][1] for r in rounds)
        scipy_import = statistics.median(r[1][0] for r in rounds)
        scipy_calls = statistics.median(r[1][1] for r in rounds)
        ratio = statistics.median(sum(r[0]) / sum(r[1]) for r in rounds)
        results[name] = {'package_import_s': ours_import, 'package_calls_s': ours_calls,
                         'scipy_import_s': scipy_import, 'scipy_calls_s': scipy_calls,
                         'ratio': ratio, 'target_met': ratio <= TARGET}
        print(f'{name:34s} {ours_import:8.3f} {ours_calls:8.3f} {scipy_import:8.3f} '
              f'{scipy_calls:8.3f} {ratio:6.2f}  {"yes" if ratio <= TARGET else "NO"}')
    worst = max(r['ratio'] for r in results.values())
    print(f'\nworst ratio package / scipy: {worst:.2f} (target <= {TARGET}: '
          f'{"met" if worst <= TARGET else "not met"})')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump({'cpu': cpu_model(), 'results': results, 'worst_ratio': worst}, f,
                      indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
