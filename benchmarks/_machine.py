"""
Where a benchmark ran, and the memory floor of a batch: shared by the benchmark scripts.

Speed ratios depend on the machine: numpy's ufuncs (``arctan2``, ``sin``...)
take SIMD paths only where the CPU has the instructions (some only with
AVX-512), and numba compiles the package's kernels for the CPU it runs on.
:func:`print_machine` prints the CPU model, the SIMD levels numpy found and
the CPU LLVM targets, at the top of each benchmark's output.
"""
import os
import platform
import sys
import timeit

import numpy as np

# The benchmarks time the compiled kernels: every kernel loads at its first call, never
# runs interpreted (conversions/_runtime.py). Set before the package is imported;
# tree_environment removes it from the processes measured as users start them.
os.environ.setdefault('ROTATION_NODE_COMPILED', '1')


def tree_environment(tree=None, **extra):
    """
    Return the environment of a process that runs as a user's would, from source ``tree``.

    This process's environment with ``extra``, without ``ROTATION_NODE_COMPILED`` (set
    above for the benchmarks' own calls), and ``tree`` (if given) first on ``PYTHONPATH``.
    """
    env = dict(os.environ, **extra)
    env.pop('ROTATION_NODE_COMPILED', None)
    if tree is not None:
        env['PYTHONPATH'] = os.pathsep.join(
            [os.path.abspath(tree)] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep)
                                       if p])
    return env


def cpu_model():
    """Return the CPU's model name (``/proc/cpuinfo``, else what ``platform`` knows)."""
    try:
        with open('/proc/cpuinfo') as cpuinfo:
            for line in cpuinfo:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or 'unknown CPU'


def numpy_simd_levels():
    """
    Return numpy's SIMD extensions ``(baseline, found, not_found)`` (``numpy.show_runtime``'s).

    ``baseline`` is what numpy was compiled for; ``found`` the dispatch targets
    this CPU supports (their kernels are the ones that run), ``not_found``
    those it lacks (e.g. ``X86_V4``/``AVX512_*`` on an AVX2-only x86).
    Honours ``NPY_DISABLE_CPU_FEATURES``.
    """
    try:
        from numpy._core import _multiarray_umath as umath   # numpy >= 2
    except ImportError:   # pragma: no cover - numpy 1.x
        from numpy.core import _multiarray_umath as umath
    features = umath.__cpu_features__
    dispatch = list(umath.__cpu_dispatch__)
    return (list(umath.__cpu_baseline__), [f for f in dispatch if features.get(f)],
            [f for f in dispatch if not features.get(f)])


def llvm_target_cpu():
    """Return the CPU numba compiles the kernels for (``NUMBA_CPU_NAME``, else the host's)."""
    import numba
    from llvmlite import binding
    return numba.config.CPU_NAME or binding.get_host_cpu_name()


def machine_lines():
    """Lines that say where a benchmark ran: CPU, SIMD levels, LLVM target."""
    baseline, found, not_found = numpy_simd_levels()
    return [
        f'machine: {cpu_model()} ({platform.machine()}, {len(os.sched_getaffinity(0))} usable '
        f'CPUs, Python {platform.python_version()})',
        f'numpy {np.__version__} SIMD: baseline {" ".join(baseline) or "-"}; found '
        f'{" ".join(found) or "-"}; not found {" ".join(not_found) or "-"}',
        f'numba kernels compiled for: {llvm_target_cpu()}',
    ]


def load_line():
    """
    Line: the load average now and the threads rotation_node splits large batches across.

    The threads are the library's setting where it is loaded, else its
    default (``ROTATION_NODE_THREADS``, else the usable CPUs).
    """
    runtime = sys.modules.get('rotation_node.conversions._runtime')
    threads = getattr(runtime, '_threads', None) or (
        int(os.environ.get('ROTATION_NODE_THREADS', 0)) or len(os.sched_getaffinity(0)))
    return (f'load average {" ".join(f"{x:.2f}" for x in os.getloadavg())} (1, 5, 15 min); '
            f'rotation_node batch threads: {threads}')


def print_machine():
    """Print :func:`machine_lines` and :func:`load_line`, the first lines of a benchmark."""
    for line in machine_lines() + [load_line()]:
        print(line)


def copy_floor(inputs, out_shape):
    """
    Return a call that moves the bytes a batch conversion must: read inputs, write an output.

    It allocates an output of ``out_shape`` (as a conversion does), copies
    the inputs' values into it as flat float64 and, where the inputs are
    larger than the output, reads the rest (a sum); where they are smaller,
    it fills the rest. numpy's contiguous copies and sums run at memory
    speed, so its best time is the floor below which no conversion of these
    arrays can go (on one thread).
    """
    flat = [np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in inputs]
    size = int(np.prod(out_shape))

    def move():
        out = np.empty(size)
        filled = 0
        for a in flat:
            k = min(a.size, size - filled)
            out[filled:filled + k] = a[:k]
            filled += k
            if k < a.size:
                a[k:].sum()
        out[filled:] = 0.0
        return out

    return move


def best_seconds(function, number, repeat):
    """Best time per call of ``function()`` over ``repeat`` runs of ``number`` calls."""
    return min(timeit.repeat(function, number=number, repeat=repeat)) / number
