#!/usr/bin/env python3
"""
Threads or not: each batch conversion on two threads against one, interleaved and repeated.

For each operation and size, rounds alternate ``set_threads(1)`` and
``set_threads(N)`` (``THREADED_SAMPLES`` lowered so that every size splits)
and time the same call; the printout gives, per operation and size, the
median and range of the per-round ratio ``time(N threads) / time(1 thread)``
(below 1: threads faster), with the machine and its load average. The
library's threshold (``_runtime.THREADED_SAMPLES``) and whether threads start
at all (``_runtime.threads_pay``) are chosen from these figures
(docs/performance.md).

Usage::

    python benchmarks/bench_threads.py [--rounds 7] [--sizes 65536 1000000] [--threads 2]
"""
import argparse
import statistics
import sys
import time

from _machine import print_machine
import numpy as np


def operations(n, rng):
    import rotation_node.conversions as rc
    q = rng.normal(size=(n, 4))
    v = rng.normal(size=(n, 3))
    m = rc.matrix_from_quaternion(q)
    return {
        'matrix_from_quaternion': lambda: rc.matrix_from_quaternion(q),
        'euler_from_quaternion': lambda: rc.euler_from_quaternion(q, 'xyz'),
        'quaternion_from_matrix': lambda: rc.quaternion_from_matrix(m),
        'quaternion_product': lambda: rc.quaternion_product(q, q),
        'rotate_vector': lambda: rc.rotate_vector(q, v),
        'quaternion_from_rotation_vector': lambda: rc.quaternion_from_rotation_vector(v),
    }


def _best(call, repeat=3):
    best = float('inf')
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - start)
    return best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=7)
    parser.add_argument('--sizes', type=int, nargs='+', default=[65536, 1_000_000])
    parser.add_argument('--threads', type=int, default=2)
    args = parser.parse_args(argv)
    from rotation_node.conversions import _runtime
    print_machine()
    _runtime.compile_kernels()
    saved = _runtime.THREADED_SAMPLES
    _runtime.THREADED_SAMPLES = 1
    rng = np.random.default_rng(0)
    print(f'\ntime({args.threads} threads) / time(1 thread), median [min-max] of '
          f'{args.rounds} interleaved rounds; ns per sample with 1 thread')
    try:
        for n in args.sizes:
            for name, call in operations(n, rng).items():
                ratios, single = [], []
                for _ in range(args.rounds):
                    _runtime.set_threads(1)
                    one = _best(call)
                    _runtime.set_threads(args.threads)
                    many = _best(call)
                    ratios.append(many / one)
                    single.append(one / n * 1e9)
                print(f'{name:34s} n={n:>9,d}  {statistics.median(ratios):5.2f} '
                      f'[{min(ratios):.2f}-{max(ratios):.2f}]  '
                      f'{statistics.median(single):6.1f} ns')
    finally:
        _runtime.THREADED_SAMPLES = saved
    return 0


if __name__ == '__main__':
    sys.exit(main())
