"""
Compile and cache every kernel once: ``python -m rotation_node.conversions.warm_up``.

Each kernel (conversions and kinematics) is compiled for its one signature
and written to numba's disk cache, so that no later process compiles: a first
call then costs a cache load, not seconds of compilation. ``./run.sh`` runs
this after installing.
"""
import argparse
import sys
import time
from typing import List, Optional


def warm_up() -> int:
    """
    Compile every kernel of conversions and kinematics, or load it from the disk cache.

    Returns
    -------
    int
        The number of kernels.

    """
    from .. import kinematics  # noqa: F401  (declares its kernels)
    from ._runtime import compile_kernels
    return compile_kernels()


def main(argv: Optional[List[str]] = None) -> int:
    """Command line entry point: warm up, print one line, return the exit status."""
    parser = argparse.ArgumentParser(
        prog='python -m rotation_node.conversions.warm_up',
        description='Compile and cache every compiled kernel of rotation_node once.')
    parser.add_argument('--quiet', action='store_true', help='print nothing')
    args = parser.parse_args(argv)
    start = time.perf_counter()
    count = warm_up()
    if not args.quiet:
        print(f'rotation_node: {count} kernels compiled or loaded from the cache in '
              f'{time.perf_counter() - start:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
