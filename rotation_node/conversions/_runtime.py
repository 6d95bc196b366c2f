"""
The compiled-call machinery of the library: from public arguments to compiled kernels.

A *kernel* is a compiled loop over samples. It takes its array arguments in
one canonical layout, fills a preallocated output and returns the status of
the first bad sample (see :func:`status`), or -1. This module holds what every
kernel shares:

- the JIT policy (:data:`jit`) and the kernel declaration (:func:`kernel`):
  each kernel is compiled for exactly one signature, on its first call or by
  :func:`compile_kernels`, and cached on disk, so no later call compiles,
  whatever the caller's leading shape, dtype, memory layout or writability;
  :class:`KernelCompilation` tells compilations from cache loads;
- the canonical layout (:func:`kernel_layout`) and the compiled views of it
  (:func:`samples`, :func:`matrix_samples`);
- status packing (:func:`status`, :func:`first_status`);
- batch schedules: the chunk size and the thread pool (:func:`set_threads`);
- the one Python-side path from public arguments to kernels
  (:func:`call_unary`, :func:`call_binary`).

The canonical layout: every array argument is a C-contiguous float64 array
holding its samples one after the other along the first axis. Samples of
shape ``()`` or ``(k,)`` are a 1-D array of ``n`` or ``n k`` values; 3 x 3
matrices a 2-D array of shape ``(3 n, 3)``. A single sample in its natural
shape, ``(4,)`` or ``(3, 3)``, is already in that layout, so a single-sample
call passes the caller's array as it is. Arrays are writable: a read-only input
is copied (as is one of another dtype, order or alignment).

Compiled kernels are cached next to the package; where that directory is not
writable (a system-wide ROS install), numba caches them in the user's cache
directory instead (``$XDG_CACHE_HOME/numba``, by default ``~/.cache/numba``),
or wherever ``NUMBA_CACHE_DIR`` says.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import importlib.util
import math
import os
import sys
import threading
import time
from typing import Any, Callable, Optional, Sequence, TYPE_CHECKING, TypeGuard

from numba import njit, types
from numba.core import event
from numba.core.errors import RequireLiteralValue, TypingError
from numba.extending import intrinsic, overload
import numpy as np

from ._validation import broadcast_pair, float_array, raise_sample_error

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray

# Every compiled function is inlined into its callers (numba IR inlining, not
# left to LLVM). A helper that is called rather than inlined costs a call per
# sample and, when an array is live across it (the kernels' inputs and
# outputs always are), an atomic reference-count increment and decrement per
# call: 2-4x the whole per-sample cost of most kernels, measured.
# (Inlined callees cannot be called with ``*args``.) Only kernels are cached
# on disk (:func:`kernel`): an inlined helper is compiled into its callers,
# and a cache would cost each helper a directory probe at import.
jit = njit(nogil=True, error_model='numpy', inline='always')
_cached_jit = njit(cache=True, nogil=True, error_model='numpy', inline='always')


# ------------------------------------------------------------ kernel types

def array_type(ndim: int, dtype: Any = types.float64) -> Any:
    """Return the numba type of a C-contiguous, aligned, writable kernel argument."""
    return types.Array(dtype, ndim, 'C')


# Inputs are typed writable like outputs: numba accepts a writable array for a
# read-only parameter only by converting its type at every call, which costs
# ~20 ns of a ~1 us single-sample call; read-only inputs are copied instead.
#: Inputs in the canonical layout: samples of shape () or (k,), and matrices (3 n, 3).
FLAT_IN, ROWS_IN = array_type(1), array_type(2)
#: Outputs in the canonical layout (the same types; the names say the role).
FLAT_OUT, ROWS_OUT = array_type(1), array_type(2)
#: Scalar arguments and the status that kernels return.
INT, FLOAT, BOOL = types.int64, types.float64, types.boolean
STATUS = types.int64

#: Every kernel declared with :func:`kernel`, in declaration order.
KERNELS: list[Any] = []


_compiling = threading.Lock()


def _import_numba_registries_without_scipy_linalg() -> None:
    """
    Import numba's array-math registry without its import of ``scipy.linalg``.

    The first compilation or cache load in a process makes numba import all
    its lowering registries. One of them, ``numba.np.arraymath``, probes for
    BLAS when it is imported by importing ``scipy.linalg.cython_blas``, which
    imports all of ``scipy.linalg``: 0.15 s of a 0.4 s cold start, measured
    (``benchmarks/bench_cold_start.py``), for kernels that never call BLAS.
    The probe is answered here by whether scipy is installed at all
    (``importlib.util.find_spec``, which imports nothing), the case it tells
    apart in practice. numba's linear algebra (``np.dot`` in a user's function)
    still imports ``scipy.linalg`` itself when such a function is compiled: only
    the module-import-time probe is replaced, and only for that one import.
    """
    if 'numba.np.arraymath' in sys.modules:
        return
    import numba.np.linalg as numba_linalg
    probe = getattr(numba_linalg, 'ensure_blas', None)
    if probe is None:   # another numba: leave its import as it is
        return

    def scipy_installed():
        if importlib.util.find_spec('scipy') is None:
            raise ImportError('scipy is required for linear algebra')

    numba_linalg.ensure_blas = scipy_installed
    try:
        import numba.np.arraymath  # noqa: F401  (runs the probe)
    finally:
        numba_linalg.ensure_blas = probe


def _compile(dispatcher: Any) -> None:
    """Compile ``dispatcher`` for its one signature (or load it from the disk cache), once."""
    with _compiling:   # threads of one large batch may all make the first call
        if not dispatcher.kernel_compiled:
            _import_numba_registries_without_scipy_linalg()
            dispatcher.compile(dispatcher.kernel_signature)
            dispatcher.disable_compile()
            dispatcher.kernel_compiled = True


def typed_first_call(dispatcher: Any) -> Callable[..., Any]:
    """
    Return the first ``call_unchecked`` of a kernel: a typed call that installs the unchecked one.

    ``call_unchecked`` is the kernel's compiled code, called without numba's
    typing of the arguments (~100 ns less per call): the caller guarantees
    that every array argument has exactly the declared type (float64,
    C-contiguous, aligned, writable, the declared number of dimensions), as
    :func:`is_single_sample` checks; a wrong number of dimensions would be
    read out of bounds. Its first call goes through numba's typing instead,
    so that a call site that breaks the contract raises ``TypeError``; then
    the compiled code replaces it.
    """
    def call(*args):
        status_ = dispatcher(*args)
        dispatcher.call_unchecked = (
            dispatcher.overloads[dispatcher.kernel_signature.args].entry_point)
        return status_

    return call


def kernel(*argument_types: Any,
           returns: Any = STATUS) -> Callable[[Callable[..., Any]], Any]:
    """
    Declare a kernel: compiled for exactly one signature, on first use.

    Parameters
    ----------
    *argument_types : numba types
        The kernel's arguments, e.g. ``FLAT_IN, FLAT_OUT, INT``. Arrays are
        C-contiguous, aligned, writable float64 in the canonical layout.
    returns : numba type or None, optional
        The result: the status by default; None for a kernel without one.

    Returns
    -------
    callable
        A decorator returning the numba dispatcher. Its first call compiles
        the declared signature (or loads it from the disk cache) and then
        disables compilation, so a call with other types raises ``TypeError``
        instead of compiling again. Its attribute ``call_unchecked`` runs the
        same compiled code without numba's typing of the arguments (see
        :func:`typed_first_call`), for the single-sample path of a call.

    """
    signature = (types.none if returns is None else returns)(*argument_types)

    def decorate(py_func):
        dispatcher = _cached_jit(py_func)
        dispatcher.kernel_signature = signature
        dispatcher.kernel_compiled = False

        def compile_on_first_call(*args, **kwargs):
            # numba calls this when no compiled signature matches the arguments,
            # and then calls what it returns with them: now the dispatcher
            # itself, which accepts them or raises TypeError.
            _compile(dispatcher)
            return dispatcher

        dispatcher._compile_for_args = compile_on_first_call
        dispatcher.call_unchecked = typed_first_call(dispatcher)
        KERNELS.append(dispatcher)
        return dispatcher

    return decorate


def compile_kernels(kernels: Optional[Sequence[Any]] = None) -> int:
    """
    Compile every kernel (or those given) for its one signature, from the disk cache where cached.

    Returns
    -------
    int
        How many kernels were compiled or loaded.

    """
    kernels = KERNELS if kernels is None else kernels
    for dispatcher in kernels:
        _compile(dispatcher)
    return len(kernels)


class KernelCompilation(event.Listener):
    """
    Kernels compiled, not loaded from the disk cache, within a ``with`` block.

    A start after installation compiles each kernel it uses (seconds to
    minutes); every later one loads them from the cache. ``on_slow()`` is
    called once, from a timer thread, when a kernel is compiling ``after``
    seconds after the first compilation in the block started (or at the next
    start, if none is compiling then), so that a long compilation can be
    announced while it runs; never after the block. Afterwards ``compiled`` says
    how many kernels were compiled and ``seconds`` how long the compilations
    took in all (from the start of the first to the end of the last).
    Compilations of functions that are not kernels (:func:`kernel`) are not
    counted. It listens to numba's ``numba:compile`` event, which numba
    broadcasts only for a compilation, never for a cache load.
    """

    def __init__(self, on_slow: Callable[[], None], after: float = 1.0):
        self.on_slow, self.after = on_slow, after
        self.compiled = 0
        self.seconds = 0.0
        self._lock = threading.Lock()
        self._compiling = 0                    # kernel compilations in progress
        self._first: Optional[float] = None    # monotonic start of the first
        self._due = False                      # on_slow is to be called at the next start
        self._closed = False                   # the block has ended
        self._timer: Optional[threading.Timer] = None
        self._installed: Any = None

    @staticmethod
    def _is_kernel(ev: Any) -> bool:
        return hasattr(ev.data.get('dispatcher'), 'kernel_signature')

    def on_start(self, ev: Any) -> None:
        """Count a kernel compilation starting; start the timer at the first."""
        if not self._is_kernel(ev):
            return
        with self._lock:
            self._compiling += 1
            if self._first is None:
                self._first = time.monotonic()
                self._timer = threading.Timer(self.after, self._elapsed)
                self._timer.daemon = True
                self._timer.start()
            if self._due:
                self._due = False
                self.on_slow()

    def on_end(self, ev: Any) -> None:
        """Count a kernel compilation done."""
        if not self._is_kernel(ev):
            return
        with self._lock:
            self._compiling -= 1
            self.compiled += 1
            assert self._first is not None
            self.seconds = time.monotonic() - self._first

    def _elapsed(self) -> None:
        with self._lock:   # on_slow is called under the lock: never after __exit__
            if self._closed:
                return
            if self._compiling > 0:
                self.on_slow()
            else:   # between two compilations: announce when the next one starts
                self._due = True

    def __enter__(self) -> KernelCompilation:
        self._installed = event.install_listener('numba:compile', self)
        self._installed.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._installed.__exit__(*exc)
        with self._lock:
            self._closed, self._due = True, False
            if self._timer is not None:
                self._timer.cancel()


# ------------------------------------------------------------ sample views

def kernel_layout(a: FloatArray, trailing: tuple[int, ...]) -> FloatArray:
    """Return the canonical layout (a view) of C-contiguous samples ``a`` of shape ``trailing``."""
    if len(trailing) <= 1:
        return a.reshape(-1)
    return a.reshape((-1,) + trailing[1:])


def _rows_per_sample(trailing: tuple[int, ...]) -> int:
    return trailing[0] if trailing else 1


@intrinsic
def _stack_view(typingctx, a, rows, columns):
    """C-contiguous ``a`` viewed as ``(n,)``, ``(n, rows)`` or ``(n, rows, columns)``: no copy."""
    if not (isinstance(a, types.Array) and a.layout == 'C'):
        raise TypingError(f'samples(): expected a C-contiguous array, got {a}.')
    if not (isinstance(rows, types.IntegerLiteral) and isinstance(columns, types.IntegerLiteral)):
        raise RequireLiteralValue('samples(): the sample shape must be constant.')
    trailing = [d for d in (rows.literal_value, columns.literal_value) if d > 0]
    result = a.copy(ndim=1 + len(trailing), layout='C')

    def codegen(context, builder, signature, args):
        # Imported here, when a kernel is compiled: not needed to load one from the cache.
        from numba.core.imputils import impl_ret_borrowed
        from numba.np.arrayobj import make_array, populate_array
        source = make_array(signature.args[0])(context, builder, args[0])
        view = make_array(signature.return_type)(context, builder)
        intp = context.get_value_type(types.intp)
        sizes = [math.prod(trailing[i:]) for i in range(len(trailing) + 1)]
        shape = [builder.sdiv(source.nitems, intp(sizes[0]))] + [intp(d) for d in trailing]
        strides = [builder.mul(source.itemsize, intp(size)) for size in sizes]
        populate_array(view, data=source.data, shape=shape, strides=strides,
                       itemsize=source.itemsize, meminfo=source.meminfo, parent=source.parent)
        return impl_ret_borrowed(context, builder, signature.return_type, view._getvalue())

    return result(a, rows, columns), codegen


def samples(a: FloatArray, width: int) -> FloatArray:
    """
    Return the canonical ``a`` as a stack of samples, shape ``(n, width)`` (``(n,)``: width 0).

    How kernels see their flat arguments. In compiled code (the overload
    below) the view costs nothing: no copy and no call. ``width`` must be a
    constant there; any C-contiguous array of ``n width`` values is viewed.
    """
    return a.reshape(-1, width) if width else a.reshape(-1)


@overload(samples, inline='always', prefer_literal=True)
def _samples_overload(a, width):
    if not isinstance(width, types.IntegerLiteral):
        raise RequireLiteralValue('samples(): `width` must be a constant.')
    k = width.literal_value
    return lambda a, width: _stack_view(a, k, 0)


def matrix_samples(a: FloatArray) -> FloatArray:
    """Return the matrices ``a`` (3 n, 3), or any C-contiguous 9 n values, as (n, 3, 3)."""
    return a.reshape(-1, 3, 3)


@overload(matrix_samples, inline='always')
def _matrix_samples_overload(a):
    return lambda a: _stack_view(a, 3, 3)


# ------------------------------------------------------------ status packing

@jit
def status(sample: int, argument: int, code: int) -> int:
    """Kernel status for a bad sample: ``(sample << 4) | (argument << 3) | code``."""
    return (sample << 4) | (argument << 3) | code


@jit
def first_status(a: int, b: int) -> int:
    """Return the first of two statuses that reports a bad sample (-1 if neither does)."""
    return a if a >= 0 else b


# ------------------------------------------------------------ batch schedules

# Inputs of at least this many samples use a kernel's batch schedule, where
# it has one (the same count for every input type, so that a conversion and
# its route through quaternions agree bit for bit).
BATCH_SAMPLES = 1024


def is_batch(a: FloatArray, trailing: tuple[int, ...]) -> bool:
    """Whether ``a`` (samples of shape ``trailing``) is large enough for a batch schedule."""
    return a.size >= BATCH_SAMPLES * math.prod(trailing)


# Samples per chunk of a batch schedule: the intermediates stay in cache.
STAGE_CHUNK = 4096


# Batches of at least this many samples are split across threads (the kernels
# release the GIL); ROTATION_NODE_THREADS overrides the number of threads.
THREADED_SAMPLES = 1 << 16
_threads = int(os.environ.get('ROTATION_NODE_THREADS', 0)) or len(os.sched_getaffinity(0))
_pool = None


def set_threads(n: int) -> None:
    """
    Set how many threads large batches (>= 65536 samples) are split across.

    Parameters
    ----------
    n : int
        1 runs everything in the calling thread. The default is the number of
        CPUs this process may use, or the environment variable
        ``ROTATION_NODE_THREADS``.

    """
    global _threads, _pool
    if int(n) < 1:
        raise ValueError(f'Expected `n` >= 1 threads, got {n!r}.')
    _threads = int(n)
    if _pool is not None:
        _pool.shutdown()
        _pool = None


def _run(kernel_: Any, inputs: Sequence[FloatArray], trailings: Sequence[tuple[int, ...]],
         out: FloatArray, out_trailing: tuple[int, ...], args: tuple[Any, ...]) -> int:
    """
    Run ``kernel_(*inputs, out, *args)`` on canonical arrays, in threads for large batches.

    The parts are whole samples: rows ``lo r:hi r`` of an argument with ``r``
    rows per sample.
    """
    n = out.shape[0] // _rows_per_sample(out_trailing)
    if _threads == 1 or n < THREADED_SAMPLES:
        return kernel_(*inputs, out, *args)
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(_threads, thread_name_prefix='rotation_node')
    arrays = tuple(inputs) + (out,)
    rows = [_rows_per_sample(t) for t in tuple(trailings) + (out_trailing,)]
    bounds = np.linspace(0, n, _threads + 1).astype(int)
    jobs = [_pool.submit(kernel_, *[a[lo * r:hi * r] for a, r in zip(arrays, rows)], *args)
            for lo, hi in zip(bounds[:-1], bounds[1:])]
    for lo, job in zip(bounds[:-1], jobs):
        bad = job.result()
        if bad >= 0:
            return bad + (int(lo) << 4)
    return -1


# ------------------------------------------------------------ calls

# A single-sample call costs ~1 us in all, and numba's dispatch (typing every
# argument, choosing the compiled signature) would be ~100 ns of it. The
# single-sample path makes the checks that typing would make itself, in
# :func:`is_single_sample`, and calls the compiled code directly
# (``kernel_.call_unchecked``): the caller's array as it is (its natural shape
# is the canonical layout), a scalar result computed into shape (1,), a scalar
# argument as a float. The names it uses are module globals (``np.empty``
# looked up through the module costs ~30 ns).
_FLOAT64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_ONE = (1,)
_NO_SAMPLES = np.empty(0)
new_array = np.empty


def is_single_sample(x: object, trailing: tuple[int, ...]) -> TypeGuard[FloatArray]:
    """
    Whether ``x`` is one sample that needs no conversion: the fast path of a call.

    When it is, ``x`` has exactly the type of a kernel's array argument of
    ``max(1, len(trailing))`` dimensions, and may be passed to the kernel's
    ``call_unchecked``.
    """
    # ``is``: every native float64 array shares numpy's one float64 dtype; an
    # equal but distinct dtype object just takes the general path. ``carray``:
    # C-contiguous, aligned and writable, as kernels take their arguments.
    return (type(x) is _NDARRAY and x.shape == trailing and x.dtype is _FLOAT64
            and x.flags.carray)


def call_unary(kernel_: Any, x: ArrayLike, name: str, trailing: tuple[int, ...],
               out_trailing: tuple[int, ...], convention: Optional[int] = None,
               batch_kernel: Any = None) -> Any:
    """
    Validate ``x``, run ``kernel_(x, out[, convention])``, raise for a bad sample.

    ``out`` gets ``x``'s leading shape followed by ``out_trailing``; a 0-d
    result is returned as a scalar. Both reach the kernel in the canonical
    layout. ``convention`` is the Euler kernels' convention code (a named
    argument: unpacking ``*args`` costs ~50 ns of a ~1 us single-sample call).
    Large inputs go to ``batch_kernel`` (same signature) where one is given,
    and large batches are split across threads. A single float64 sample skips
    straight to the compiled code (``kernel_.call_unchecked``), which checks
    its values.
    """
    if is_single_sample(x, trailing):
        out = new_array(out_trailing or _ONE)
        if convention is None:
            bad = kernel_.call_unchecked(x, out)
        else:
            bad = kernel_.call_unchecked(x, out, convention)
        if bad < 0:
            return out if out_trailing else out[0]
        a = x
    else:
        a = float_array(x, name, trailing)
        out = np.empty(a.shape[:a.ndim - len(trailing)] + out_trailing)
        args = () if convention is None else (convention,)
        chosen = batch_kernel if batch_kernel is not None and is_batch(a, trailing) else kernel_
        bad = _run(chosen, (kernel_layout(a, trailing),), (trailing,),
                   kernel_layout(out, out_trailing), out_trailing, args)
    if bad >= 0:
        raise_sample_error(bad, (name,), (a,), (trailing,))
    return out[()] if out.ndim == 0 else out


def call_binary(kernel_: Any, x: ArrayLike, y: ArrayLike, names: tuple[str, str],
                trailings: tuple[tuple[int, ...], tuple[int, ...]], out_trailing: tuple[int, ...],
                *args: Any, batch_kernel: Any = None) -> Any:
    """
    Validate and broadcast ``x`` and ``y``, run ``kernel_(x, y, out, *args)``, raise if bad.

    ``out`` gets the common leading shape followed by ``out_trailing``; all
    three reach the kernel in the canonical layout. Large inputs go to
    ``batch_kernel`` where one is given, and large batches are split across
    threads; single float64 samples skip the checks that the kernel makes
    anyway.

    A scalar second argument (``trailings[1] == ()``, an angle) reaches the
    kernel twice, as ``kernel_(x, ys, out, y, *args)``: a single sample as the
    float ``y`` with ``ys`` empty, several as the array ``ys`` (``y`` unused),
    so that the kernel has one signature and one sample costs no array.
    """
    scalar_y = trailings[1] == ()
    if scalar_y and (isinstance(y, float) or is_single_sample(y, ())):
        y = float(y)
    if is_single_sample(x, trailings[0]) and (
            type(y) is float if scalar_y else is_single_sample(y, trailings[1])):
        a, b = x, y
        out = new_array(out_trailing or _ONE)
        # One tuple: cheaper than f(a, b, out, *args).
        if scalar_y:
            bad = kernel_.call_unchecked(*((a, _NO_SAMPLES, out, b) + args))
        else:
            bad = kernel_.call_unchecked(*((a, b, out) + args))
        if bad < 0:
            return out if out_trailing else out[0]
    else:
        a, b = broadcast_pair(float_array(x, names[0], trailings[0]),
                              float_array(y, names[1], trailings[1]), *trailings)
        out = np.empty(a.shape[:a.ndim - len(trailings[0])] + out_trailing)
        chosen = (batch_kernel if batch_kernel is not None and is_batch(a, trailings[0])
                  else kernel_)
        bad = _run(chosen, (kernel_layout(a, trailings[0]), kernel_layout(b, trailings[1])),
                   trailings, kernel_layout(out, out_trailing), out_trailing,
                   (0.0,) + args if scalar_y else args)
    if bad >= 0:
        raise_sample_error(bad, names, (a, np.asarray(b)), trailings)
    return out[()] if out.ndim == 0 else out
