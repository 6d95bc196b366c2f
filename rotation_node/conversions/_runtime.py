"""
The kernel machinery: from public arguments to kernels, interpreted or compiled.

A *kernel* is a loop over samples: it takes its arrays in the canonical layout (every
argument C-contiguous, aligned, writable float64, samples one after the other along the
first axis; 3 x 3 matrices as ``(3 n, 3)``), fills a preallocated output and returns the
status of the first bad sample (:func:`status`) or -1. Declarations (:data:`jit`,
:func:`kernel`, :func:`compiled_form`) record Python functions and import nothing of
numba. Each kernel runs interpreted (the Python function on ``memoryview`` s, items
Python floats) until loaded, then compiled for exactly one signature and cached on disk;
both runs do the same IEEE operations in the same order, and kernels call only correctly
rounded or exact functions (``sqrt``, ``frexp``, ``ldexp``), the C library's ``sin``,
``cos`` and ``atan2`` (the same in both runs) or ``_trigonometry`` (its fused multiply-add
exact in both), so the results agree bit for bit; any other math function would break that
(the policy, the cache and the single-sample paths: docs/library.md).
:func:`call_unary` and :func:`call_binary` are the one path from public arguments to
kernels, with single-sample fast paths and threads for large batches.
"""
from __future__ import annotations

from array import array as PythonArray
from contextlib import contextmanager
import importlib.util
import math
import os
import sys
import threading
import time
from typing import (
    Any, Callable, Iterator, NamedTuple, Optional, Sequence, TYPE_CHECKING)

import numpy as np

from ._messages import message_readers, message_sample
from ._validation import broadcast_pair, float_array, raise_sample_error

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..type_aliases import FloatArray


# ------------------------------------------------------------ declarations

class ArgumentType(NamedTuple):
    """A kernel argument's type, named without numba: a scalar, or an array of ``ndim`` of them."""

    scalar: str          # numba's name of the scalar type: 'float64', 'int64', 'boolean'
    ndim: int = 0        # 0: a scalar; else a C-contiguous, aligned, writable array

    def numba_type(self) -> Any:
        """Return the numba type (imports numba)."""
        from numba import types
        scalar = getattr(types, self.scalar)
        return types.Array(scalar, self.ndim, 'C') if self.ndim else scalar


#: Scalar arguments and the status that kernels return.
INT, FLOAT, BOOL = ArgumentType('int64'), ArgumentType('float64'), ArgumentType('boolean')
STATUS = INT


def array_type(ndim: int, dtype: ArgumentType = FLOAT) -> ArgumentType:
    """Return the type of a C-contiguous, aligned, writable kernel argument."""
    return ArgumentType(dtype.scalar, ndim)


# Inputs are typed writable like outputs: numba would convert a writable array to a
# read-only parameter type at every call (~20 ns of ~1 us); read-only inputs are copied.
#: Samples of shape () or (k,), and matrices (3 n, 3); inputs and outputs alike.
FLAT_IN, ROWS_IN = array_type(1), array_type(2)
FLAT_OUT, ROWS_OUT = FLAT_IN, ROWS_IN

#: Every kernel declared with :func:`kernel`, in declaration order.
KERNELS: list[Kernel] = []

# By id: the helpers declared with jit, the factories of compiled_form, and what compiled
# code calls instead of each (made when a kernel loads); by module name, the globals of
# the compiled copies of its functions.
_HELPERS: dict[int, Callable[..., Any]] = {}
_COMPILED_FORMS: dict[int, Callable[[], Any]] = {}
_COMPILED: dict[int, Any] = {}
_NAMESPACES: dict[str, dict[str, Any]] = {}
_numba_loaded = False
# Held while numba is set up and a kernel loads: the threads of one batch, or a background
# loader and a large call, may want the same kernel.
_loading = threading.RLock()


def jit(py_func: Callable[..., Any]) -> Callable[..., Any]:
    """
    Declare a helper of kernels: returned as it is, compiled inlined (numba IR) into its callers.

    A called helper costs a call and an atomic reference count per sample: 2-4x most kernels.
    """
    _HELPERS[id(py_func)] = py_func
    return py_func


def compiled_form(py_func: Callable[..., Any]) -> Callable[[Callable[[], Any]], Any]:
    """
    Declare the compiled form of helper ``py_func``: what ``factory()`` returns (made once).

    For what Python and numba compute alike only by different code (an LLVM intrinsic).
    """
    def decorate(factory):
        _COMPILED_FORMS[id(py_func)] = factory
        return factory

    return decorate


def _compiled_namespace(module_globals: dict[str, Any]) -> dict[str, Any]:
    """Return the globals of the compiled copies of a module's functions: its helpers compiled."""
    name = module_globals['__name__']
    namespace = _NAMESPACES.get(name)
    if namespace is None:
        namespace = _NAMESPACES[name] = dict(module_globals)
        for key, value in module_globals.items():
            if callable(value):
                compiled = _compiled_of(value)
                if compiled is not None:
                    namespace[key] = compiled
    return namespace


def _compiled_of(value: Any) -> Any:
    """Return the compiled stand-in of a helper or compiled form (made once), else None."""
    compiled = _COMPILED.get(id(value))
    if compiled is not None:
        return compiled
    if id(value) in _COMPILED_FORMS:
        compiled = _COMPILED[id(value)] = _COMPILED_FORMS[id(value)]()
    elif id(value) in _HELPERS:
        from numba import njit
        compiled = _COMPILED[id(value)] = njit(nogil=True, error_model='numpy',
                                               inline='always')(_compiled_copy(value))
    return compiled


def _compiled_copy(py_func: Callable[..., Any]) -> Callable[..., Any]:
    """Return ``py_func`` with the globals of :func:`_compiled_namespace` (compiled callees)."""
    import types as python_types
    copy = python_types.FunctionType(py_func.__code__, _compiled_namespace(py_func.__globals__),
                                     py_func.__name__, py_func.__defaults__, py_func.__closure__)
    copy.__qualname__, copy.__doc__ = py_func.__qualname__, py_func.__doc__
    copy.__module__ = py_func.__module__
    copy.__kwdefaults__ = py_func.__kwdefaults__
    return copy


def load_numba() -> None:
    """Import numba and register the compiled views with it, once (~0.6 s)."""
    global _numba_loaded
    with _loading:
        if _numba_loaded:
            return
        _import_numba_registries_without_scipy_linalg()
        _register_views()
        _numba_loaded = True


def _import_numba_registries_without_scipy_linalg() -> None:
    """
    Import ``numba.np.arraymath`` with its BLAS probe answered by whether scipy is installed.

    The probe imports all of ``scipy.linalg`` (0.15 s of a 0.4 s cold start) for kernels
    that never call BLAS; numba's linear algebra still imports it when compiled.
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


# An unloaded kernel runs interpreted while each array holds at most this many values
# (4096 quaternions; convert's blocks of <= 1023 matrices too): one sample costs 5-20 us
# interpreted, importing numba and loading a first kernel ~0.7 s (bench_cold_start.py).
INTERPRETED_VALUES = 16384
# A kernel that has run interpreted this long in all is loaded at its next call.
INTERPRETED_SECONDS = 0.5
# A loaded kernel that has copied this many list or tuple samples into arrays loads its
# tuple form (saves 0.1-0.4 us a call; a cache load costs ~10-30 ms, a compilation seconds).
TUPLE_COPIES = 100_000
_NO_TUPLE_FORM = -(1 << 62)   # tuple_copies of a kernel without a tuple form
_TUPLE_FORM_NOT_CACHED = -(1 << 61)   # ... whose tuple form was due but not in the cache


def typed_first_call(dispatcher: Any) -> Callable[..., Any]:
    """
    Return the first ``call_unchecked`` of a kernel: a typed call that installs the unchecked one.

    The unchecked call (~100 ns less) trusts its caller to pass exactly the declared types
    (float64, C-contiguous, aligned, writable, of the declared ndim); others would read out
    of bounds. The typed first call makes a call site that breaks this raise ``TypeError``.
    """
    def call(*args):
        status_ = dispatcher(*args)
        dispatcher.call_unchecked = (
            dispatcher.overloads[dispatcher.kernel_signature.args].entry_point)
        owner = dispatcher.kernel
        if owner.call_unchecked is call:
            owner.call_unchecked = dispatcher.call_unchecked
        return status_

    return call


class Kernel:
    """A declared kernel: its Python function, its one signature, its compiled form once loaded."""

    def __init__(self, py_func: Callable[..., Any], argument_types: Sequence[ArgumentType],
                 returns: Optional[ArgumentType]):
        self.py_func = py_func
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__doc__ = py_func.__doc__
        self.__module__ = py_func.__module__
        self.argument_types, self.returns = tuple(argument_types), returns
        self.dispatcher: Any = None            # numba's, once loaded
        self.call: Callable[..., Any] = self._interpreted_or_loaded
        self.call_unchecked: Callable[..., Any] = self._interpreted_or_loaded
        self.interpreted_seconds = 0.0
        self.used = False
        self.call_tuple: Optional[Callable[..., Any]] = None   # the tuple form, once loaded
        self.tuple_copies = 0                 # list samples copied into arrays meanwhile
        self.tuple_form_queued = False        # handed to the background loader

    def __repr__(self) -> str:
        state = 'compiled' if self.dispatcher is not None else 'interpreted'
        return f'<kernel {self.__qualname__} ({state})>'

    def __call__(self, *args: Any) -> Any:
        return self.call(*args)

    @property
    def signatures(self) -> list[tuple[Any, ...]]:
        """Return the compiled signatures: one once loaded."""
        return [] if self.dispatcher is None else self.dispatcher.signatures

    def numba_signature(self) -> Any:
        """Return the numba signature (imports numba)."""
        from numba import types
        returns = types.none if self.returns is None else self.returns.numba_type()
        return returns(*(t.numba_type() for t in self.argument_types))

    def load(self) -> None:
        """Compile the kernel for its one signature, or load it from the disk cache, once."""
        with _loading:
            if self.dispatcher is not None:
                return
            load_numba()
            from numba import njit
            dispatcher = njit(cache=True, nogil=True, error_model='numpy')(
                _compiled_copy(self.py_func))
            dispatcher.kernel_signature = self.numba_signature()
            dispatcher.kernel = self
            dispatcher.compile(dispatcher.kernel_signature)
            dispatcher.disable_compile()   # another signature raises TypeError
            dispatcher.call_unchecked = typed_first_call(dispatcher)
            self.dispatcher = dispatcher
            self.call, self.call_unchecked = dispatcher, dispatcher.call_unchecked

    def load_tuple_form(self, widths: tuple[int, ...], may_compile: bool = True) -> None:
        """
        Load the tuple form: the same source for input ``i`` a tuple of ``widths[i]`` floats.

        ``samples()`` views the tuple on the stack and numba's entry point unboxes it (a
        wrong length or a non-number raises). ``may_compile=False``: from the disk cache
        only. A kernel not reading its inputs by ``samples()`` has none.
        """
        with _loading:
            if (self.call_tuple is not None or self.tuple_copies == _NO_TUPLE_FORM
                    or (self.tuple_copies < 0 and not may_compile)):
                return
            self.load()
            from numba import njit, types
            from numba.core.errors import NumbaError
            array_signature = self.numba_signature()
            arguments = list(array_signature.args)
            for i, width in enumerate(widths):
                arguments[i] = types.UniTuple(types.float64, width)
            signature = array_signature.return_type(*arguments)
            dispatcher = njit(cache=True, nogil=True, error_model='numpy')(
                _compiled_copy(self.py_func))
            dispatcher.kernel_signature = signature   # a kernel's compilation (KernelCompilation)
            if not may_compile and not _is_cached(dispatcher, signature):
                self.tuple_copies = _TUPLE_FORM_NOT_CACHED
                return
            try:
                dispatcher.compile(signature)
            except NumbaError:
                self.tuple_copies = _NO_TUPLE_FORM
                return
            dispatcher.disable_compile()
            self.call_tuple = dispatcher.overloads[signature.args].entry_point

    def interpreted(self, *args: Any) -> Any:
        """Run the Python function on ``args`` (the interpreted run of the compiled code)."""
        return self.py_func(*args)

    def _interpreted_or_loaded(self, *args: Any) -> Any:
        if not self.used:
            self.used = True
            if _on_first_use is not None:
                _on_first_use(self)
        if (self.interpreted_seconds > INTERPRETED_SECONDS or _loading_forced
                or any(type(a) is _NDARRAY and a.size > INTERPRETED_VALUES for a in args)):
            self.load()
            return self.call(*args)
        start = time.perf_counter()
        try:
            return self.py_func(*args)
        finally:
            self.interpreted_seconds += time.perf_counter() - start


def _is_cached(dispatcher: Any, signature: Any) -> bool:
    """Whether numba's disk cache (``_cache``) holds ``dispatcher``'s code for ``signature``."""
    from numba.core.compiler_lock import global_compiler_lock
    cache = getattr(dispatcher, '_cache', None)
    if cache is None:
        return False
    with global_compiler_lock:
        return cache.load_overload(signature, dispatcher.targetctx) is not None


class TupleForm(NamedTuple):
    """A kernel's tuple form, due to be loaded (:meth:`Kernel.load_tuple_form`)."""

    kernel: Kernel
    widths: tuple[int, ...]

    def load(self) -> None:
        """Compile it, or load it from the disk cache."""
        self.kernel.load_tuple_form(self.widths)


# warm_up.load_in_background's queue, or None.
_on_first_use: Optional[Callable[[Kernel | TupleForm], None]] = None


def set_first_use_hook(hook: Optional[Callable[[Kernel | TupleForm], None]]) -> None:
    """Call ``hook(kernel)`` at each kernel's first call, ``hook(TupleForm)`` when one is due."""
    global _on_first_use
    _on_first_use = hook


# Every kernel loads at its first call (ROTATION_NODE_COMPILED=1: no interpreted runs).
_loading_forced = os.environ.get('ROTATION_NODE_COMPILED', '') not in ('', '0')


def kernel(*argument_types: ArgumentType,
           returns: Optional[ArgumentType] = STATUS) -> Callable[[Callable[..., Any]], Kernel]:
    """Declare a kernel of one signature (``FLAT_IN, FLAT_OUT, INT``); others raise TypeError."""
    def decorate(py_func):
        declared = Kernel(py_func, argument_types, returns)
        KERNELS.append(declared)
        return declared

    return decorate


def compile_kernels(kernels: Optional[Sequence[Kernel]] = None) -> int:
    """Load every kernel (or those given), compiled or from the cache; return how many."""
    kernels = KERNELS if kernels is None else kernels
    for declared in kernels:
        declared.load()
    return len(kernels)


class KernelCompilation:
    """
    Kernels compiled (not loaded from the disk cache) within a ``with`` block.

    ``on_slow()`` is called once, from a timer thread, if a kernel is compiling ``after``
    seconds after the first compilation began (else at the next start; never after the
    block). ``compiled`` counts them, ``seconds`` spans first start to last end. Listens to
    numba's ``numba:compile`` event, sent for compilations only (entering imports numba).
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
        from numba.core import event
        outer = self

        class Listener(event.Listener):
            def on_start(self, ev):
                outer.on_start(ev)

            def on_end(self, ev):
                outer.on_end(ev)

        self._installed = event.install_listener('numba:compile', Listener())
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


def samples(a: FloatArray, width: int) -> Any:
    """
    Return the canonical ``a`` as a stack of samples, shape ``(n, width)`` (``(n,)``: width 0).

    Compiled, a free view (``width`` a constant). Interpreted, a ``memoryview`` of Python
    floats (numpy scalars are 3-5x slower): index ``[s]``, ``[s, j]`` and ``shape`` only
    (else :func:`array_samples`).
    """
    if a.size == 0:
        return a.reshape(-1, width) if width else a.reshape(-1)
    # numpy's stubs make an ndarray a buffer only for Python >= 3.12; typeshed's
    # memoryview.cast names its formats (a.dtype.char is 'd').
    view = memoryview(a)   # type: ignore[arg-type]
    if width == 0 and a.ndim == 1:
        return view
    return view.cast('B').cast(a.dtype.char,  # type: ignore[arg-type]
                               (a.size // width, width) if width else (a.size,))


def matrix_samples(a: FloatArray) -> Any:
    """Return the matrices ``a`` (3 n, 3) as (n, 3, 3), as :func:`samples` does."""
    if a.size == 0:
        return a.reshape(-1, 3, 3)
    return memoryview(a).cast('B').cast(a.dtype.char,  # type: ignore[arg-type]
                                        (a.size // 9, 3, 3))


def array_samples(a: FloatArray, width: int) -> FloatArray:
    """:func:`samples` as an ndarray view when interpreted too: every numpy operation on it."""
    return a.reshape(-1, width) if width else a.reshape(-1)


def array_matrix_samples(a: FloatArray) -> FloatArray:
    """:func:`matrix_samples` as an ndarray view when interpreted too."""
    return a.reshape(-1, 3, 3)


def _stack_view_intrinsic() -> Any:
    """Return numba's ``_stack_view(a, rows, columns)``: ``a`` as a stack of samples, no copy."""
    from numba import types
    from numba.core.errors import RequireLiteralValue, TypingError
    from numba.extending import intrinsic

    @intrinsic
    def _stack_view(typingctx, a, rows, columns):
        """C-contiguous ``a`` viewed as ``(n,)``, ``(n, rows)`` or ``(n, rows, columns)``."""
        if not (isinstance(a, types.Array) and a.layout == 'C'):
            raise TypingError(f'samples(): expected a C-contiguous array, got {a}.')
        if not (isinstance(rows, types.IntegerLiteral)
                and isinstance(columns, types.IntegerLiteral)):
            raise RequireLiteralValue('samples(): the sample shape must be constant.')
        trailing = [d for d in (rows.literal_value, columns.literal_value) if d > 0]
        result = a.copy(ndim=1 + len(trailing), layout='C')

        def codegen(context, builder, signature, args):
            from numba.core.imputils import impl_ret_borrowed
            from numba.np.arrayobj import make_array, populate_array
            source = make_array(signature.args[0])(context, builder, args[0])
            view = make_array(signature.return_type)(context, builder)
            intp = context.get_value_type(types.intp)
            sizes = [math.prod(trailing[i:]) for i in range(len(trailing) + 1)]
            shape = [builder.sdiv(source.nitems, intp(sizes[0]))] + [intp(d) for d in trailing]
            strides = [builder.mul(source.itemsize, intp(size)) for size in sizes]
            populate_array(view, data=source.data, shape=shape, strides=strides,
                           itemsize=source.itemsize, meminfo=source.meminfo,
                           parent=source.parent)
            return impl_ret_borrowed(context, builder, signature.return_type, view._getvalue())

        return result(a, rows, columns), codegen

    return _stack_view


def _tuple_view_intrinsic() -> Any:
    """Return numba's ``_tuple_view(t, width)``: a tuple of floats as samples ``(n, width)``."""
    from numba import types
    from numba.core.errors import RequireLiteralValue, TypingError
    from numba.extending import intrinsic

    @intrinsic
    def _tuple_view(typingctx, t, width):
        """View the floats of ``t``, copied to the stack, as ``(n,)`` or ``(n, width)``."""
        if not (isinstance(t, types.UniTuple) and t.dtype == types.float64):
            raise TypingError(f'samples(): expected a tuple of floats, got {t}.')
        if not isinstance(width, types.IntegerLiteral):
            raise RequireLiteralValue('samples(): the sample shape must be constant.')
        k, count = width.literal_value, t.count
        result = types.Array(types.float64, 2 if k else 1, 'C')

        def codegen(context, builder, signature, args):
            from numba.core import cgutils
            from numba.np.arrayobj import make_array, populate_array
            item = context.get_data_type(types.float64)
            intp = context.get_value_type(types.intp)
            # In the entry block of the (inlining) kernel: valid for the whole call.
            data = cgutils.alloca_once(builder, item, size=count)
            for i in range(count):
                builder.store(builder.extract_value(args[0], i),
                              builder.gep(data, [intp(i)]))
            itemsize = context.get_abi_sizeof(item)
            shape = [count // k, k] if k else [count]
            strides = [itemsize * k, itemsize] if k else [itemsize]
            view = make_array(result)(context, builder)
            populate_array(view, data=data, shape=[intp(d) for d in shape],
                           strides=[intp(d) for d in strides], itemsize=intp(itemsize),
                           meminfo=None, parent=None)
            return view._getvalue()   # no meminfo: nothing to count or free

        return result(t, width), codegen

    return _tuple_view


def _register_views() -> None:
    """Register the compiled forms of the sample views."""
    from numba import types
    from numba.core.errors import RequireLiteralValue
    from numba.extending import overload
    view = _stack_view_intrinsic()
    tuple_view = _tuple_view_intrinsic()

    def compiled_samples(a, width):
        if not isinstance(width, types.IntegerLiteral):
            raise RequireLiteralValue('samples(): `width` must be a constant.')
        k = width.literal_value
        if isinstance(a, types.UniTuple):
            return lambda a, width: tuple_view(a, k)
        return lambda a, width: view(a, k, 0)

    for function in (samples, array_samples):
        overload(function, inline='always', prefer_literal=True)(compiled_samples)
    for matrix_function in (matrix_samples, array_matrix_samples):
        overload(matrix_function, inline='always')(lambda a: (lambda a: view(a, 3, 3)))


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

# Inputs of at least this many samples use a kernel's batch schedule, where it has one
# (one count for every input type: a conversion and its route through quaternions agree).
BATCH_SAMPLES = 1024


def is_batch(a: FloatArray, trailing: tuple[int, ...]) -> bool:
    """Whether ``a`` (samples of shape ``trailing``) is large enough for a batch schedule."""
    return a.size >= BATCH_SAMPLES * math.prod(trailing)


# Samples per chunk of a batch schedule: the intermediates stay in cache.
STAGE_CHUNK = 4096


# Batches of at least this many samples may be split across threads (the kernels release
# the GIL); below, two threads measured slower than one (bench_threads.py, performance.md).
THREADED_SAMPLES = 1 << 18
_usable_cpus = len(os.sched_getaffinity(0))
_threads_variable = int(os.environ.get('ROTATION_NODE_THREADS', 0))
_threads = _threads_variable or _usable_cpus
_threads_chosen = _threads_variable > 0   # by the variable or set_threads: always used
_pool = None


def set_threads(n: int) -> None:
    """
    Set how many threads large batches (>= 262144 samples) are split across.

    Parameters
    ----------
    n : int
        1 runs everything in the calling thread. By default (neither this nor the
        environment variable ``ROTATION_NODE_THREADS`` set) a large batch is split across
        the CPUs this process may use only while one is idle (1-minute load average below
        their number minus a half: on a busy machine a second thread measured slower). A
        number set here or by the variable is always used.

    """
    global _threads, _pool, _threads_chosen
    if int(n) < 1:
        raise ValueError(f'Expected `n` >= 1 threads, got {n!r}.')
    _threads, _threads_chosen = int(n), True
    if _pool is not None:
        _pool.shutdown()
        _pool = None


def batch_threads(n: int) -> int:
    """Return how many threads a batch of ``n`` samples is split across now (see set_threads)."""
    if _threads == 1 or n < THREADED_SAMPLES:
        return 1
    if _threads_chosen or os.getloadavg()[0] < _usable_cpus - 0.5:
        return _threads
    return 1


def _run(kernel_: Any, inputs: Sequence[FloatArray], trailings: Sequence[tuple[int, ...]],
         out: FloatArray, out_trailing: tuple[int, ...], args: tuple[Any, ...]) -> int:
    """Run ``kernel_(*inputs, out, *args)`` on canonical arrays, in threads for large batches."""
    n = out.shape[0] // (out_trailing[0] if out_trailing else 1)
    threads = batch_threads(n)
    if threads == 1:
        return kernel_(*inputs, out, *args)
    global _pool
    if _pool is None:
        from concurrent.futures import ThreadPoolExecutor   # (and logging): for large batches
        _pool = ThreadPoolExecutor(_threads, thread_name_prefix='rotation_node')
    if kernel_.dispatcher is None:
        kernel_.load()   # once, here, rather than in each thread
    arrays = tuple(inputs) + (out,)   # split into whole samples of r rows each
    rows = [t[0] if t else 1 for t in tuple(trailings) + (out_trailing,)]
    bounds = np.linspace(0, n, threads + 1).astype(int)
    jobs = [_pool.submit(kernel_, *[a[lo * r:hi * r] for a, r in zip(arrays, rows)], *args)
            for lo, hi in zip(bounds[:-1], bounds[1:])]
    for lo, job in zip(bounds[:-1], jobs):
        bad = job.result()
        if bad >= 0:
            return bad + (int(lo) << 4)
    return -1


# ------------------------------------------------------------ calls

# A single-sample call costs ~1 us, numba's dispatch ~100 ns of it: the single-sample path
# checks what typing would and calls the compiled code (``call_unchecked``) with the
# caller's array as it is, or a list, tuple or message (``_messages``) as a tuple to the
# tuple form (``call_tuple``; numba unboxes it in ~20 ns), or before that copied into a
# scratch array of the thread's own. The path's names are module globals (``np.empty``
# looked up through the module costs ~30 ns).
_FLOAT64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_ONE = (1,)
_NO_SAMPLES = np.empty(0)
_NUMBERS = (float, int, np.floating, np.integer)
new_array = np.empty


def is_listed(x: object, kind: type) -> bool:
    """Whether ``x`` is a list, tuple or ``array.array('d')`` (rclpy's float64 sequences)."""
    return (kind is list or kind is tuple
            or (kind is PythonArray and x.typecode == 'd'))  # type: ignore[attr-defined]


class _Scratch(threading.local):
    """Each thread's scratch arrays, per argument: sample shape -> (array, memoryview, size)."""

    first: dict[tuple[int, ...], tuple[FloatArray, memoryview, int]]
    second: dict[tuple[int, ...], tuple[FloatArray, memoryview, int]]

    def __init__(self) -> None:
        self.first, self.second = {}, {}
        for trailing in ((3,), (4,), (3, 3)):
            for arrays in (self.first, self.second):
                array = np.empty(trailing)
                arrays[trailing] = (array, memoryview(array.reshape(-1)),  # type: ignore[arg-type]
                                    array.size)


_scratch = _Scratch()
_NO_SCRATCH = (None, None, 0)


def listed_sample(x: Any, scratch: tuple[Any, Any, int]) -> Any:
    """
    Return the list, tuple or array.array ``x`` of one sample copied into ``scratch``, or None.

    A memoryview's item assignment takes exactly the numbers numpy converts alike and
    raises for anything else: then None, and the general path converts or refuses ``x``.
    """
    array, m, values = scratch
    try:
        if values == 4:
            m[0], m[1], m[2], m[3] = x
        elif values == 3:
            m[0], m[1], m[2] = x
        elif values == 9:
            (m[0], m[1], m[2]), (m[3], m[4], m[5]), (m[6], m[7], m[8]) = x
        else:
            return None
    except (TypeError, ValueError, OverflowError):
        return None
    return array


def copied(kernel_: Any, widths: tuple[int, ...]) -> None:
    """
    Count a list sample ``kernel_`` copied; load its tuple form when due (:data:`TUPLE_COPIES`).

    The background loader loads it where there is one (a callback never waits), else the
    calling thread, from the disk cache only unless asked (``ROTATION_NODE_COMPILED=1``,
    :func:`compiling_tuple_forms`): a call never compiles one unasked.
    """
    kernel_.tuple_copies += 1
    asked = _loading_forced or _tuple_forms_compiled
    if not ((kernel_.tuple_copies >= TUPLE_COPIES or asked) and kernel_.dispatcher is not None):
        return
    if _on_first_use is None or asked:
        kernel_.load_tuple_form(widths, may_compile=asked)
    elif not kernel_.tuple_form_queued:   # a background loader (the node's) loads it
        kernel_.tuple_form_queued = True
        _on_first_use(TupleForm(kernel_, widths))


_tuple_forms_compiled = False


@contextmanager
def compiling_tuple_forms() -> Iterator[None]:
    """Within the block, a loaded kernel given a list sample compiles or loads its tuple form."""
    global _tuple_forms_compiled
    _tuple_forms_compiled = True
    try:
        yield
    finally:
        _tuple_forms_compiled = False


def single_sample(x: object, trailing: tuple[int, ...], argument: int = 0) -> Optional[FloatArray]:
    """
    Return ``x`` as one sample in a float64 array ``call_unchecked`` takes, or None.

    An array of exactly the kernel's type as it is, a list or message copied to scratch.
    """
    kind = type(x)
    if kind is _NDARRAY:
        array: FloatArray = x   # type: ignore[assignment]  # mypy does not narrow x by kind
        if array.shape == trailing and array.dtype is _FLOAT64 and array.flags.carray:
            return array
        return None
    if not is_listed(x, kind):   # an object with attributes x, y, z(, w): the tuple of them
        x = message_sample(x, kind)
        if x is None:
            return None
    return listed_sample(x, (_scratch.second if argument else _scratch.first).get(
        trailing, _NO_SCRATCH))


def call_unary(kernel_: Any, x: ArrayLike, name: str, trailing: tuple[int, ...],
               out_trailing: tuple[int, ...], convention: Optional[int] = None,
               batch_kernel: Any = None) -> Any:
    """
    Validate ``x``, run ``kernel_(x, out[, convention])``, raise for a bad sample.

    ``out``: ``x``'s leading shape and ``out_trailing`` (0-d: a scalar). ``convention`` is
    named, not ``*args`` (~50 ns of a ~1 us call). Large inputs go to ``batch_kernel``.
    """
    kind = type(x)   # single_sample, inline: a call costs ~5 % of a ~1 us single sample
    a: Optional[FloatArray]
    if kind is _NDARRAY:
        array: FloatArray = x   # type: ignore[assignment]  # mypy does not narrow x by kind
        a = (array if (array.shape == trailing and array.dtype is _FLOAT64
                       and array.flags.carray) else None)
    else:
        sample: Any
        if kind is list or kind is tuple or (kind is PythonArray and is_listed(x, kind)):
            sample = x
        else:   # an object with attributes x, y, z(, w) (a ROS message): their tuple, or None
            try:
                sample = message_readers[kind](x)
            except (KeyError, AttributeError):   # a new type, or a slot never set
                sample = message_sample(x, kind)
            kind = tuple
        call_tuple = kernel_.call_tuple
        if sample is None:
            a = None
        elif call_tuple is not None:   # numba unboxes the tuple: no copy, no checks here
            out = new_array(out_trailing or _ONE)
            try:
                if kind is not tuple:
                    sample = tuple(sample)
                bad = (call_tuple(sample, out) if convention is None
                       else call_tuple(sample, out, convention))
            except (TypeError, ValueError, OverflowError):
                bad = 0   # not numbers of the sample's shape: the general path says why
            if bad < 0:
                return out if out_trailing else out[0]
            a = None   # a bad sample: the general path raises its error
        else:
            a = listed_sample(sample, _scratch.first.get(trailing, _NO_SCRATCH))
            if a is not None and len(trailing) == 1:
                copied(kernel_, trailing)
    if a is not None:
        out = new_array(out_trailing or _ONE)
        if convention is None:
            bad = kernel_.call_unchecked(a, out)
        else:
            bad = kernel_.call_unchecked(a, out, convention)
        if bad < 0:
            return out if out_trailing else out[0]
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

    A scalar ``y`` (``trailings[1] == ()``, an angle) reaches the kernel as
    ``kernel_(x, ys, out, y, *args)``: one sample as the float ``y`` (``ys`` empty), several
    as the array ``ys``: one signature, and one sample costs no array.
    """
    scalar_y = not trailings[1]
    if scalar_y and type(y) is not float and (isinstance(y, _NUMBERS) or (
            type(y) is _NDARRAY and y.shape == () and y.dtype is _FLOAT64
            and y.flags.carray)):
        y = float(y)
    xv: Any = x   # the arguments as they came; mypy: any object
    yv: Any = y
    kind_x, kind_y = type(xv), type(yv)
    # is_listed, inline: a call costs ~5 % of a ~1 us single sample
    if kind_x is tuple or kind_x is list:
        listed = (kind_y is float if scalar_y else (
            kind_y is tuple or kind_y is list
            or (kind_y is PythonArray and is_listed(yv, kind_y))))
    elif kind_x is _NDARRAY:
        listed = False
    else:   # an array.array('d'), or a message as its tuple; the same for y
        if kind_x is PythonArray and is_listed(xv, kind_x):
            sx = xv
        else:
            try:
                sx = message_readers[kind_x](xv)
            except (KeyError, AttributeError):   # a new type, or a slot never set
                sx = message_sample(xv, kind_x)
        if (scalar_y or kind_y is tuple or kind_y is list
                or (kind_y is PythonArray and is_listed(yv, kind_y))):
            sy = yv if not scalar_y or kind_y is float else None
        else:
            try:
                sy = message_readers[kind_y](yv)
            except (KeyError, AttributeError):
                sy = message_sample(yv, kind_y)
        listed = sx is not None and sy is not None
        if listed:
            xv, yv, kind_x, kind_y = sx, sy, type(sx), type(sy)
    call_tuple = kernel_.call_tuple
    if listed and call_tuple is not None:   # numba unboxes the tuples: no copies
        out = new_array(out_trailing or _ONE)
        try:
            tx = xv if kind_x is tuple else tuple(xv)
            if scalar_y:   # one tuple of arguments: cheaper than f(a, b, out, *args)
                bad = call_tuple(*((tx, _NO_SAMPLES, out, yv) + args))
            elif args:
                bad = call_tuple(*((tx, yv if kind_y is tuple else tuple(yv), out) + args))
            else:
                bad = call_tuple(tx, yv if kind_y is tuple else tuple(yv), out)
        except (TypeError, ValueError, OverflowError):
            bad = 0   # not numbers of the samples' shapes: the general path says why
        if bad < 0:
            return out if out_trailing else out[0]
    a: Any
    b: Any
    # single_sample, inline for float64 arrays (a call costs ~5 % of a single sample)
    if (kind_x is _NDARRAY and xv.shape == trailings[0] and xv.dtype is _FLOAT64
            and xv.flags.carray):
        a = xv
    else:
        a = single_sample(xv, trailings[0])
    if scalar_y:
        b = yv if kind_y is float else None
    elif (kind_y is _NDARRAY and yv.shape == trailings[1] and yv.dtype is _FLOAT64
            and yv.flags.carray):
        b = yv
    else:
        b = single_sample(yv, trailings[1], 1)
    if a is not None and b is not None:
        if listed and len(trailings[0]) <= 1 and len(trailings[1]) <= 1:
            copied(kernel_, trailings[0] + trailings[1])
        out = new_array(out_trailing or _ONE)
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
