"""
The kernel machinery of the library: from public arguments to kernels, interpreted or compiled.

A *kernel* is a loop over samples. It takes its array arguments in one
canonical layout, fills a preallocated output and returns the status of the
first bad sample (see :func:`status`), or -1. This module holds what every
kernel shares:

- the declarations (:data:`jit` for helpers, :func:`kernel` for kernels,
  :func:`compiled_form` for a helper whose compiled form differs from its
  Python one): they record Python functions and import nothing of numba;
- when a kernel runs interpreted and when compiled (below);
- the canonical layout (:func:`kernel_layout`) and the views of it
  (:func:`samples`, :func:`matrix_samples`);
- status packing (:func:`status`, :func:`first_status`);
- batch schedules: the chunk size and the thread pool (:func:`set_threads`);
- the one Python-side path from public arguments to kernels
  (:func:`call_unary`, :func:`call_binary`), with its single-sample fast path
  for float64 arrays, lists, tuples, numbers and objects with attributes
  x, y, z(, w) such as ROS messages (:func:`single_sample`, and
  each kernel's tuple form: :meth:`Kernel.load_tuple_form`).

Interpreted or compiled
-----------------------
Importing the library imports numpy only. Every kernel and every helper is a
plain Python function, and the same source is also compiled by numba (with
the helpers inlined), so that a kernel has two runs of one code: interpreted
(the Python function itself, on ``memoryview`` s of its arrays, whose items are
Python floats) and compiled. Both compute every sample with the same IEEE
double operations in the same order, and the library's formulas call only
correctly rounded or exact functions (``sqrt``, ``frexp``, ``ldexp``), the C
library's ``atan2``, ``sin`` and ``cos`` (the same in both), or its own
(``_trigonometry``; the fused multiply-add is exact in both): the results
are the same bit for bit (``test/test_conversions_runtime.py`` checks every
kernel both ways).

The policy, per kernel:

- once the kernel is loaded (compiled, or loaded from numba's disk cache),
  every call runs the compiled code;
- before that, a call with at most :data:`INTERPRETED_VALUES` values in each
  array argument (a few thousand samples) runs interpreted (~5-20 us a
  sample, against ~1 s to import numba and load the kernels: a program
  converting a few samples never pays for it);
- a larger call loads the kernel first (importing numba the first time), as
  does a kernel that has spent :data:`INTERPRETED_SECONDS` interpreted in all
  (a long-running caller of small conversions then pays the load once, after
  at most as much time interpreted as the load costs);
- a loaded kernel called with single samples given as lists or tuples loads
  its tuple form (the same source compiled for tuples of floats, see
  :meth:`Kernel.load_tuple_form`) once it has copied :data:`TUPLE_COPIES`
  of them into arrays: from the disk cache only (``warm_up`` puts it there;
  a call never compiles one unasked), or by the background loader where
  there is one;
- :func:`compile_kernels` loads kernels explicitly (``warm_up`` all of them),
  and ``warm_up.load_in_background`` loads each kernel in a background thread
  as soon as it is first used, while calls run interpreted until it is ready
  (the node: outputs from the first message, the same numbers either way).

Each kernel is compiled for exactly one signature, on its load, and cached on
disk, so no later call compiles, whatever the caller's leading shape, dtype,
memory layout or writability (its tuple form, in a dispatcher of its own, for
one more); :class:`KernelCompilation` tells compilations from cache loads.

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

from array import array as PythonArray
from contextlib import contextmanager
import importlib.util
import math
import os
import sys
import threading
import time
from typing import (
    Any, Callable, Iterator, NamedTuple, Optional, Sequence, TYPE_CHECKING, TypeGuard)

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


# Inputs are typed writable like outputs: numba accepts a writable array for a
# read-only parameter only by converting its type at every call, which costs
# ~20 ns of a ~1 us single-sample call; read-only inputs are copied instead.
#: Inputs in the canonical layout: samples of shape () or (k,), and matrices (3 n, 3).
FLAT_IN, ROWS_IN = array_type(1), array_type(2)
#: Outputs in the canonical layout (the same types; the names say the role).
FLAT_OUT, ROWS_OUT = array_type(1), array_type(2)

#: Every kernel declared with :func:`kernel`, in declaration order.
KERNELS: list[Kernel] = []

# id of a helper declared with jit -> the helper; of a compiled_form's function -> its factory.
_HELPERS: dict[int, Callable[..., Any]] = {}
_COMPILED_FORMS: dict[int, Callable[[], Any]] = {}
# id of a Python function -> what compiled code calls instead (made when a kernel loads),
# and module name -> the namespace the compiled copies of its functions see.
_COMPILED: dict[int, Any] = {}
_NAMESPACES: dict[str, dict[str, Any]] = {}
_numba_loaded = False
# Held while numba is set up and while a kernel loads: the threads of one large
# batch, or a background loader and a large call, may all want the same kernel.
_loading = threading.RLock()


def jit(py_func: Callable[..., Any]) -> Callable[..., Any]:
    """
    Declare a helper of kernels: returned as it is, compiled inlined into the kernels calling it.

    Every compiled helper is inlined into its callers (numba IR inlining, not
    left to LLVM). A helper that is called rather than inlined costs a call per
    sample and, when an array is live across it (the kernels' inputs and
    outputs always are), an atomic reference-count increment and decrement per
    call: 2-4x the whole per-sample cost of most kernels, measured.
    (Inlined callees cannot be called with ``*args``.) In Python the helper is
    the function itself: the interpreted run of a kernel calls it directly.
    """
    _HELPERS[id(py_func)] = py_func
    return py_func


def compiled_form(py_func: Callable[..., Any]) -> Callable[[Callable[[], Any]], Any]:
    """
    Declare the compiled form of helper ``py_func``: ``factory()`` returns it, when numba loads.

    For what Python and numba must do differently to compute the same values
    (an LLVM intrinsic such as the fused multiply-add). Compiled code calls
    what ``factory()`` returns (made once, when the first kernel loads)
    wherever the source calls ``py_func``.
    """
    def decorate(factory):
        _COMPILED_FORMS[id(py_func)] = factory
        return factory

    return decorate


def _compiled_namespace(module_globals: dict[str, Any]) -> dict[str, Any]:
    """
    Return the globals of the compiled copies of a module's functions (helpers compiled).

    numba resolves a function's globals when it compiles it: a copy of each
    declared function with these globals calls the compiled form of every
    helper it names (from its own module or imported), while the Python
    function itself keeps calling the Python helpers.
    """
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


# A call runs interpreted while each of its arrays holds at most this many
# values and the kernel is not loaded: 4096 quaternions, so that the blocks
# of ``rotation_bag convert`` (at most 1023 samples, 9207 values as
# matrices) run interpreted too. Measured (benchmarks/bench_cold_start.py,
# bench_bag_convert.py --whole): one interpreted sample costs 5-20 us where
# importing numba and loading one kernel from the disk cache costs ~0.7 s in
# a new process (~10-30 ms for each further kernel); a bag of 2e4 Imu
# messages converts in 0.75-1.09 s interpreted, 1.34-2.00 s loading kernels.
INTERPRETED_VALUES = 16384
# A kernel that has run interpreted this long in all is loaded at its next call.
INTERPRETED_SECONDS = 0.5
# A loaded kernel that has copied this many single samples given as lists or
# tuples of floats into arrays loads its tuple form (Kernel.load_tuple_form)
# (with ROTATION_NODE_COMPILED=1 at the first such call after its own load).
# Measured (benchmarks/bench_conversions.py --single): the tuple form saves
# 0.1-0.4 us a call, and loading it from the disk cache costs ~10-30 ms: as for
# INTERPRETED_SECONDS, a caller pays the load once its copies have cost about as
# much, and a program converting a few thousand samples never pays for it. Compiling
# it costs seconds: warm_up does (and caches it), a call only where asked (copied).
TUPLE_COPIES = 100_000
_NO_TUPLE_FORM = -(1 << 62)   # tuple_copies of a kernel without a tuple form
# tuple_copies of a kernel whose tuple form was due but not in the disk cache: a call
# never compiles one (seconds) in the calling thread unasked (warm_up caches them); the
# kernel goes on copying.
_TUPLE_FORM_NOT_CACHED = -(1 << 61)


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
    the compiled code replaces it (on the kernel, where the single-sample
    path looks it up).
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
    """
    A declared kernel: its Python function, its one signature, and its compiled form once loaded.

    Calling it runs the compiled code once the kernel is loaded, else
    interpreted or, for a large call, loads it first (the module's policy).
    ``call_unchecked`` is the single-sample path: the compiled code without
    numba's typing of the arguments once loaded (:func:`typed_first_call`),
    the same policy before.
    """

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
        self.interpreted_seconds = 0.0        # spent interpreted, in all
        self.used = False                     # called at least once
        # The compiled code taking single samples as tuples of floats (load_tuple_form), and
        # how many lists and tuples the loaded kernel has copied into arrays meanwhile.
        self.call_tuple: Optional[Callable[..., Any]] = None
        self.tuple_copies = 0
        self.tuple_form_queued = False        # handed to the background loader

    def __repr__(self) -> str:
        state = 'compiled' if self.dispatcher is not None else 'interpreted'
        return f'<kernel {self.__qualname__} ({state})>'

    def __call__(self, *args: Any) -> Any:
        return self.call(*args)

    @property
    def signatures(self) -> list[tuple[Any, ...]]:
        """Return the compiled signatures: one once loaded, none before."""
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
        Load the kernel's tuple form: its first ``len(widths)`` inputs one sample as floats.

        ``may_compile=False``: only from the disk cache; where it is not there,
        nothing (and ``tuple_copies`` stops counting towards it).

        The same source compiled (or loaded from the disk cache) for another
        signature, in a dispatcher of its own: input ``i`` a tuple of
        ``widths[i]`` floats, which its ``samples()`` view as one sample in an
        array on the stack (no copy in Python, no allocation). numba's entry
        point unboxes the tuple itself: exactly ``widths[i]`` items, each
        converted by ``float()`` (a wrong length or a non-number raises). Once
        loaded, ``call_tuple`` is its compiled code; a kernel whose source
        takes its inputs other than by ``samples()`` has none (stays None).
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
    """
    Whether numba's disk cache holds ``dispatcher``'s code for ``signature`` (loading it once).

    ``dispatcher.compile`` then loads it again (~10 ms, once a kernel), rather
    than this repeating numba's private steps of installing a cached overload.
    The check is numba's own (``Dispatcher.compile`` asks its ``_cache`` so);
    a numba without that private attribute counts as not cached: no compilation.
    """
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
        """Load it (compile it, or load it from the disk cache)."""
        self.kernel.load_tuple_form(self.widths)


# Called with a kernel at its first call, and with a kernel's TupleForm when it is due
# (warm_up.load_in_background's queue: it calls their load()), or None.
_on_first_use: Optional[Callable[[Kernel | TupleForm], None]] = None


def set_first_use_hook(hook: Optional[Callable[[Kernel | TupleForm], None]]) -> None:
    """
    Have ``hook(kernel)`` called at each kernel's first call from now on (None: no hook).

    And ``hook(TupleForm(kernel, widths))`` when a loaded kernel's tuple form
    is due (:func:`copied`), instead of loading it in the calling thread.
    """
    global _on_first_use
    _on_first_use = hook


# Every kernel loads at its first call (ROTATION_NODE_COMPILED=1: no interpreted runs).
_loading_forced = os.environ.get('ROTATION_NODE_COMPILED', '') not in ('', '0')


def kernel(*argument_types: ArgumentType,
           returns: Optional[ArgumentType] = STATUS) -> Callable[[Callable[..., Any]], Kernel]:
    """
    Declare a kernel: one signature, interpreted or compiled as the module says.

    Parameters
    ----------
    *argument_types : ArgumentType
        The kernel's arguments, e.g. ``FLAT_IN, FLAT_OUT, INT``. Arrays are
        C-contiguous, aligned, writable float64 in the canonical layout.
    returns : ArgumentType or None, optional
        The result: the status by default; None for a kernel without one.

    Returns
    -------
    callable
        A decorator returning the :class:`Kernel`. Once loaded, a call with
        other types raises ``TypeError`` instead of compiling again.

    """
    def decorate(py_func):
        declared = Kernel(py_func, argument_types, returns)
        KERNELS.append(declared)
        return declared

    return decorate


def compile_kernels(kernels: Optional[Sequence[Kernel]] = None) -> int:
    """
    Load every kernel (or those given): compiled for its one signature, or from the cache.

    Returns
    -------
    int
        How many kernels were compiled or loaded.

    """
    kernels = KERNELS if kernels is None else kernels
    for declared in kernels:
        declared.load()
    return len(kernels)


#: The explicit form of a large call's load: every kernel compiled or loaded from the cache.
load_kernels = compile_kernels


class KernelCompilation:
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
    broadcasts only for a compilation, never for a cache load (entering the
    block imports numba).
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


def _rows_per_sample(trailing: tuple[int, ...]) -> int:
    return trailing[0] if trailing else 1


def samples(a: FloatArray, width: int) -> Any:
    """
    Return the canonical ``a`` as a stack of samples, shape ``(n, width)`` (``(n,)``: width 0).

    How kernels see their flat arguments. In compiled code (the compiled form
    below) the view costs nothing: no copy and no call; ``width`` must be a
    constant there, and any C-contiguous array of ``n width`` values is viewed.
    Interpreted, the view is a ``memoryview``, whose items are Python floats
    (an ndarray's are numpy scalars, 3-5x slower in arithmetic): a kernel
    reads and writes it by ``[s]`` or ``[s, j]`` and reads its ``shape``, no
    more (sub-views, ``.T``, ``.flat``: :func:`array_samples`). An empty
    array stays an array.
    """
    if a.size == 0:
        return a.reshape(-1, width) if width else a.reshape(-1)
    # numpy's stubs make an ndarray a buffer only for Python >= 3.12 (it is one at run time);
    # typeshed's memoryview.cast takes only the formats it names (a.dtype.char is 'd' here).
    view = memoryview(a)   # type: ignore[arg-type]
    if width == 0 and a.ndim == 1:
        return view
    return view.cast('B').cast(a.dtype.char,  # type: ignore[arg-type]
                               (a.size // width, width) if width else (a.size,))


def matrix_samples(a: FloatArray) -> Any:
    """
    Return the matrices ``a`` (3 n, 3), or any C-contiguous 9 n values, as (n, 3, 3).

    Interpreted, a ``memoryview`` indexed by ``[s, i, j]`` (see :func:`samples`).
    """
    if a.size == 0:
        return a.reshape(-1, 3, 3)
    # An ndarray is a buffer and its char is 'd': stubs as in samples().
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
    """Register the compiled forms of the sample views (:func:`samples` and the others)."""
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

# Inputs of at least this many samples use a kernel's batch schedule, where
# it has one (the same count for every input type, so that a conversion and
# its route through quaternions agree bit for bit).
BATCH_SAMPLES = 1024


def is_batch(a: FloatArray, trailing: tuple[int, ...]) -> bool:
    """Whether ``a`` (samples of shape ``trailing``) is large enough for a batch schedule."""
    return a.size >= BATCH_SAMPLES * math.prod(trailing)


# Samples per chunk of a batch schedule: the intermediates stay in cache.
STAGE_CHUNK = 4096


# Batches of at least this many samples may be split across threads (the kernels
# release the GIL). Measured on the shared 2-core EPYC under load (benchmarks/bench_threads.py,
# docs/performance.md): at 65536 samples two threads were slower than one for 5 of 6
# operations (1.08-1.54x); at 1e6 faster for 5 (0.75-0.99x) but not for the memory-bound
# quaternion_product (1.15x).
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
        1 runs everything in the calling thread. By default (neither this nor
        the environment variable ``ROTATION_NODE_THREADS`` set) a large batch
        is split across the CPUs this process may use only while one of them
        is idle (the 1-minute load average below their number minus a half):
        on a busy machine a second thread only competes for the same CPUs, and
        measured slower. A number set here or by the variable is always used.

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
    """
    Run ``kernel_(*inputs, out, *args)`` on canonical arrays, in threads for large batches.

    The parts are whole samples: rows ``lo r:hi r`` of an argument with ``r``
    rows per sample.
    """
    n = out.shape[0] // _rows_per_sample(out_trailing)
    threads = batch_threads(n)
    if threads == 1:
        return kernel_(*inputs, out, *args)
    global _pool
    if _pool is None:
        from concurrent.futures import ThreadPoolExecutor   # (and logging): for large batches
        _pool = ThreadPoolExecutor(_threads, thread_name_prefix='rotation_node')
    if kernel_.dispatcher is None:
        kernel_.load()   # once, here, rather than in each thread
    arrays = tuple(inputs) + (out,)
    rows = [_rows_per_sample(t) for t in tuple(trailings) + (out_trailing,)]
    bounds = np.linspace(0, n, threads + 1).astype(int)
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
# :func:`single_sample`, and calls the compiled code directly
# (``kernel_.call_unchecked``): the caller's array as it is (its natural shape
# is the canonical layout), a scalar result computed into shape (1,), a
# scalar argument as a float. A single sample given as a list or tuple of
# numbers goes to the kernel's tuple form (``kernel_.call_tuple``, see
# Kernel.load_tuple_form) as a tuple: numba's entry point unboxes it (~20 ns;
# copying it into an array in Python cost ~200 ns, more than checking an
# array), so that lists and tuples cost no more than a float64 array. Before
# the tuple form is loaded they are copied into a float64 array of the
# thread's own (:func:`listed_sample`). An object with attributes x, y, z(, w)
# (a ROS message, ``_messages``) is read into the tuple of them (~0.1 us for a
# rosidl class) and then taken as that tuple. The names the path uses are module
# globals (``np.empty`` looked up through the module costs ~30 ns).
_FLOAT64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_ONE = (1,)
_NO_SAMPLES = np.empty(0)
_NUMBERS = (float, int, np.floating, np.integer)
new_array = np.empty


def is_listed(x: object, kind: type) -> bool:
    """
    Whether ``x`` (of type ``kind``) may be one sample given as Python numbers.

    A list or tuple, or an ``array.array`` of doubles (how rclpy holds a
    message's float64 sequences); their items are then taken as ``float()``
    takes them, which numpy's conversion agrees with.
    """
    return (kind is list or kind is tuple
            or (kind is PythonArray and x.typecode == 'd'))  # type: ignore[attr-defined]


class _Scratch(threading.local):
    """
    Each thread's arrays for single samples given as lists or tuples.

    ``first`` and ``second`` (one per kernel argument) map a sample shape to
    ``(array, view, values)``: a float64 array of that shape, a ``memoryview``
    of its values and how many there are.
    """

    first: dict[tuple[int, ...], tuple[FloatArray, memoryview, int]]
    second: dict[tuple[int, ...], tuple[FloatArray, memoryview, int]]

    def __init__(self) -> None:
        self.first, self.second = {}, {}
        for trailing in ((3,), (4,), (3, 3)):
            for arrays in (self.first, self.second):
                array = np.empty(trailing)
                # An ndarray is a buffer at run time; numpy's stubs say so only for 3.12+.
                arrays[trailing] = (array, memoryview(array.reshape(-1)),  # type: ignore[arg-type]
                                    array.size)


_scratch = _Scratch()
# What a shape without a scratch array (none of the above) gets: no array.
_NO_SCRATCH = (None, None, 0)


def is_single_sample(x: object, trailing: tuple[int, ...]) -> TypeGuard[FloatArray]:
    """
    Whether ``x`` is one sample in a float64 array that needs no conversion.

    When it is, ``x`` has exactly the type of a kernel's array argument of
    ``max(1, len(trailing))`` dimensions, and may be passed to the kernel's
    ``call_unchecked``.
    """
    # ``is``: every native float64 array shares numpy's one float64 dtype; an
    # equal but distinct dtype object just takes the general path. ``carray``:
    # C-contiguous, aligned and writable, as kernels take their arguments.
    return (type(x) is _NDARRAY and x.shape == trailing and x.dtype is _FLOAT64
            and x.flags.carray)


def listed_sample(x: Any, scratch: tuple[Any, Any, int]) -> Any:
    """
    Return the list, tuple or array.array ``x`` of one sample copied into a scratch array, or None.

    ``scratch`` is the ``(array, view, values)`` of the sample's shape in
    ``_scratch.first`` or ``_scratch.second`` (one per argument); the array
    is valid until the thread's next call. A memoryview's item assignment
    takes exactly the Python numbers (floats, ints, numpy scalars) that numpy
    converts alike, and raises for anything else (a string, a wrong length,
    an int too large for a float): then None, and the general path converts
    or refuses ``x`` as any array_like.
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
    Count a single sample that ``kernel_`` took as lists or tuples copied into arrays.

    ``widths``: the sample widths of its list arguments. A loaded kernel
    loads its tuple form when the count says so (:data:`TUPLE_COPIES`), or
    hands it to the background loader, where there is one (the node's:
    a message callback never waits for a compilation). Without one, the
    calling thread loads it only from the disk cache (``warm_up`` puts it
    there), never compiling it unasked: it compiles it only with
    ``ROTATION_NODE_COMPILED=1``, or within :func:`compiling_tuple_forms`.
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


# Within compiling_tuple_forms(): copied() compiles (or loads) each tuple form at once.
_tuple_forms_compiled = False


@contextmanager
def compiling_tuple_forms() -> Iterator[None]:
    """
    Within the block, a loaded kernel taking a list or tuple compiles or loads its tuple form.

    At its first such call (the next, for a kernel loaded by that call):
    how ``warm_up`` compiles and caches the tuple forms that single samples reach.
    """
    global _tuple_forms_compiled
    _tuple_forms_compiled = True
    try:
        yield
    finally:
        _tuple_forms_compiled = False


def single_sample(x: object, trailing: tuple[int, ...], argument: int = 0) -> Optional[FloatArray]:
    """
    Return ``x`` as one sample in a float64 array a kernel's ``call_unchecked`` takes, or None.

    ``x`` itself when :func:`is_single_sample`; numbers (:func:`is_listed`)
    and the tuple of an object's attributes x, y, z(, w)
    (``_messages.message_sample``) copied by :func:`listed_sample`
    (``argument`` 0 or 1: the first or second argument's array); None for
    anything else (the general path).
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

    ``out`` gets ``x``'s leading shape followed by ``out_trailing``; a 0-d
    result is returned as a scalar. Both reach the kernel in the canonical
    layout. ``convention`` is the Euler kernels' convention code (a named
    argument: unpacking ``*args`` costs ~50 ns of a ~1 us single-sample call).
    Large inputs go to ``batch_kernel`` (same signature) where one is given,
    and large batches are split across threads. A single sample (a float64
    array, list, tuple, or object with attributes x, y, z(, w)) skips
    straight to the kernel's single-sample path (``kernel_.call_tuple`` or
    ``kernel_.call_unchecked``), which checks its values.
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

    ``out`` gets the common leading shape followed by ``out_trailing``; all
    three reach the kernel in the canonical layout. Large inputs go to
    ``batch_kernel`` where one is given, and large batches are split across
    threads; single samples (float64 arrays, lists, tuples, numbers, objects
    with attributes x, y, z(, w)) skip the checks that the kernel makes anyway.

    A scalar second argument (``trailings[1] == ()``, an angle) reaches the
    kernel twice, as ``kernel_(x, ys, out, y, *args)``: a single sample as the
    float ``y`` with ``ys`` empty, several as the array ``ys`` (``y`` unused),
    so that the kernel has one signature and one sample costs no array.
    """
    scalar_y = not trailings[1]   # (): an angle
    if scalar_y and type(y) is not float and (isinstance(y, _NUMBERS) or is_single_sample(y, ())):
        y = float(y)
    xv: Any = x   # the arguments as they came; mypy: any object
    yv: Any = y
    kind_x, kind_y = type(xv), type(yv)
    # is_listed, inline for lists and tuples: a call costs ~5 % of a ~1 us single sample
    # (tuples, lists and arrays tested in the order of the original expression: no test more)
    if kind_x is tuple or kind_x is list:
        listed = (kind_y is float if scalar_y else (
            kind_y is tuple or kind_y is list
            or (kind_y is PythonArray and is_listed(yv, kind_y))))
    elif kind_x is _NDARRAY:
        listed = False
    else:   # an array.array of doubles, or an object with attributes x, y, z(, w) (a ROS
        # message), given as its tuple; the same for the second argument
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
