"""
Compile and cache every kernel once: ``python -m rotation_node.conversions.warm_up``.

Every kernel of conversions and kinematics, and the tuple form that list samples reach,
goes into numba's disk cache (``./run.sh`` runs this after installing), so no later
process compiles. :func:`announcing_compilation` is how a start says it is compiling;
:func:`load_in_background` how the node starts without waiting for it.
"""
import argparse
from contextlib import contextmanager
import inspect
import queue
import sys
import threading
import time
from typing import Callable, Iterator, List, Optional

from . import _runtime
from ._runtime import KernelCompilation

# A sample for each required argument of the public functions taking tuples: a function
# whose required arguments are all named here is called with them, compiling its tuple form.
_TUPLE_ARGUMENTS = {
    'q': (0.0, 0.0, 0.0, 1.0), 'p': (0.0, 0.0, 0.0, 1.0), 'q_dot': (0.0, 0.0, 0.0, 0.0),
    'v': (0.1, 0.2, 0.3), 'axis': (0.0, 0.0, 1.0), 'angles': (0.1, 0.2, 0.3),
    'rates': (0.1, 0.2, 0.3), 'omega': (0.1, 0.2, 0.3), 'angle': 0.5, 'seq': 'xyz',
}

#: What a start that compiles kernels says once it has compiled for a second (measured
#: after `colcon build`: docs/node.md).
COMPILING = ('compiling the numerical kernels, once after installation (about 15 s on an idle '
             'machine, a minute or more on a busy one); later starts load them from the cache')


def warm_up() -> int:
    """Compile every kernel of conversions and kinematics, or load it from the cache; how many."""
    from .. import conversions, kinematics
    from ._runtime import compile_kernels, compiling_tuple_forms
    count = compile_kernels()
    with compiling_tuple_forms():
        for function in (getattr(module, name) for module in (conversions, kinematics)
                         for name in module.__all__):
            if not inspect.isfunction(function):
                continue
            parameters = inspect.signature(function).parameters.values()
            required = [p.name for p in parameters if p.default is inspect.Parameter.empty]
            if required and all(name in _TUPLE_ARGUMENTS for name in required):
                function(*(_TUPLE_ARGUMENTS[name] for name in required))
    return count


@contextmanager
def announcing_compilation(say: Callable[[str], None],
                           after: float = 1.0) -> Iterator[KernelCompilation]:
    """
    Say on one line when kernels compile for longer than ``after`` seconds, and when they are done.

    ``say(COMPILING)`` from a timer thread, ``say('N kernels compiled in ... s and cached')``
    at the end of the block; nothing when every kernel comes from the disk cache.
    """
    said = []

    def slow():
        said.append(True)
        say(COMPILING)

    with KernelCompilation(slow, after) as compilation:
        yield compilation
    if said:
        say(f'{compilation.compiled} kernels compiled in {compilation.seconds:.1f} s and cached')


def load_in_background(say: Callable[[str], None], after: float = 1.0) -> threading.Thread:
    """
    Load each kernel (and tuple form, when due) in a daemon thread at its first use.

    Calls run interpreted meanwhile, with the same numbers; the thread imports numba at
    once, then loads the kernels in the order of their first calls, announcing slow
    compilations as :func:`announcing_compilation` does. Returns the loader (one per
    process: a second call returns the first one's).
    """
    global _background
    if _background is not None:   # one loader per process
        return _background
    pending: 'queue.SimpleQueue[_runtime.Kernel | _runtime.TupleForm]' = queue.SimpleQueue()
    for declared in _runtime.KERNELS:   # already called: first in line
        if declared.used and declared.dispatcher is None:
            pending.put(declared)
    _runtime.set_first_use_hook(pending.put)

    def load() -> None:
        _runtime.load_numba()
        while True:
            first = pending.get()
            with announcing_compilation(say, after):
                first.load()
                while True:   # the kernels asked for meanwhile, in one announcement
                    try:
                        pending.get_nowait().load()
                    except queue.Empty:
                        break

    _background = threading.Thread(target=load, name='rotation_node kernels', daemon=True)
    _background.start()
    return _background


_background: Optional[threading.Thread] = None


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
