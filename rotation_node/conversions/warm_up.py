"""
Compile and cache every kernel once: ``python -m rotation_node.conversions.warm_up``.

Each kernel (conversions and kinematics) is compiled for its one signature
and written to numba's disk cache, so that no later process compiles: a first
call then costs a cache load, not seconds of compilation. ``./run.sh`` runs
this after installing. :func:`announcing_compilation` is how a program's
start-up (the node's) says that it is compiling, when it is.
"""
import argparse
from contextlib import contextmanager
import sys
import time
from typing import Callable, Iterator, List, Optional

from ._runtime import KernelCompilation

#: What a start that compiles kernels says once it has compiled for a second (measured
#: after `colcon build`: docs/node.md).
COMPILING = ('compiling the numerical kernels, once after installation (about 15 s on an idle '
             'machine, a minute or more on a busy one); later starts load them from the cache')


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


@contextmanager
def announcing_compilation(say: Callable[[str], None],
                           after: float = 1.0) -> Iterator[KernelCompilation]:
    """
    Say on one line when kernels compile for longer than ``after`` seconds, and when they are done.

    For a program's start-up (the first after installation compiles the
    kernels it uses): ``say(COMPILING)`` while they compile, from a timer
    thread, and ``say('kernels compiled in ... s')`` at the end of the block.
    Nothing is said when every kernel is loaded from the disk cache.
    """
    said = []

    def slow():
        said.append(True)
        say(COMPILING)

    with KernelCompilation(slow, after) as compilation:
        yield compilation
    if said:
        say(f'{compilation.compiled} kernels compiled in {compilation.seconds:.1f} s and cached')


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
