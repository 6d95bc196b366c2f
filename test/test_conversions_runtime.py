"""Tests of rotation_node.conversions._runtime: kernels interpreted and compiled, views."""
import importlib
import importlib.util
import inspect
import itertools
import math
import os
import re
import subprocess
import sys

from numba import njit, typeof, types
from numba.core.errors import TypingError
import numpy as np
import pytest
from rotation_dev.hard_cases import (
    hard_angles, hard_matrices, hard_quaternions, hard_rotation_vectors, near_gimbal_lock_angles,
    noisy_matrices)
from rotation_node import conversions as rc
from rotation_node import kinematics as rk
from rotation_node.conversions import _quaternion, _runtime, warm_up
from rotation_node.conversions._runtime import KERNELS, matrix_samples, samples

_runtime.load_numba()   # the compiled views below are compiled here


@pytest.fixture(autouse=True, scope='module')
def _tuple_forms_cached():
    """
    warm_up's tuple forms in the disk cache (seconds once, then cache loads).

    Without a background loader, a call loads a due tuple form only from the
    cache (``_runtime.copied``): the tests that make tuple forms due at once
    (``TUPLE_COPIES`` 1) find them there, as after ``./run.sh``.
    """
    warm_up.warm_up()


@pytest.fixture(autouse=True)
def _no_background_loader():
    """
    Run each test without a background kernel loader, whatever ran before in the process.

    A node made in this process (another module's test on the same worker) leaves its
    loader's hook set for the process's life: kernels and tuple forms would be handed to
    it and load later, instead of in the calling thread as these tests expect. A test
    about the loader sets the hook itself.
    """
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_runtime, '_on_first_use', None)
        yield


_MODULES = ['rotation_node.conversions._quaternion', 'rotation_node.conversions._matrix',
            'rotation_node.conversions._euler', 'rotation_node.conversions._axis_angle',
            'rotation_node.conversions._trigonometry',
            'rotation_node.kinematics._derivatives', 'rotation_node.kinematics._euler_rates',
            'rotation_node.kinematics._finite_difference',
            'rotation_node.kinematics._integration', 'rotation_node.kinematics._validation']


# ----------------------------------------------------------------- views

_VIEWS = {0: njit(lambda a: samples(a, 0)), 3: njit(lambda a: samples(a, 3)),
          4: njit(lambda a: samples(a, 4)), 9: njit(lambda a: samples(a, 9)),
          (3, 3): njit(lambda a: matrix_samples(a))}


@pytest.mark.slow
@pytest.mark.parametrize('shape, width', [
    ((1,), 0), ((7,), 0), ((0,), 0), ((4,), 4), ((24,), 4), ((0,), 4), ((6,), 3),
    ((3, 3), 9), ((12, 3), 9), ((3, 3), (3, 3)), ((15, 3), (3, 3)), ((0, 3), (3, 3))])
def test_compiled_views_are_the_reshape(shape, width):
    a = np.arange(math.prod(shape), dtype=np.float64).reshape(shape)
    got = _VIEWS[width](a)
    expected = matrix_samples(a) if width == (3, 3) else samples(a, width)   # interpreted
    assert got.shape == tuple(expected.shape)
    assert np.array_equal(got, np.asarray(expected))
    got[...] = -1.0   # a view: writing through it writes the array
    assert np.all(a == -1.0)


def test_compiled_views_keep_read_only_read_only():
    a = np.arange(8.0)
    a.flags.writeable = False
    assert not _VIEWS[4](a).flags.writeable


def test_compiled_views_refuse_a_non_contiguous_array():
    with pytest.raises(TypingError, match='C-contiguous'):
        _VIEWS[4](np.zeros(16)[::2])


def test_canonical_layout_of_a_single_sample_is_its_natural_shape():
    for trailing in ((), (3,), (4,), (3, 3)):
        a = np.zeros((2, 5) + trailing)
        flat = _runtime.kernel_layout(a, trailing)
        assert flat.base is a or flat.base is a.base   # a view
        assert flat.ndim == max(1, len(trailing))
        one = np.zeros(trailing or (1,))
        assert _runtime.kernel_layout(one, trailing).shape == one.shape


# ------------------------------------------------------- one signature each

def _variants(sample, lead_shapes=((), (1,), (5,), (5, 2), (2, 1, 3), (1100,))):
    """Return the same samples in every form a caller may pass them."""
    sample = np.asarray(sample, dtype=np.float64)
    for lead in lead_shapes:
        a = np.ascontiguousarray(np.broadcast_to(sample, lead + sample.shape))
        yield a
        yield a.tolist()
        yield a.astype(np.float32)
        yield a.astype('>f8')
        fortran = np.asfortranarray(a)
        yield fortran
        wide = np.zeros(a.shape + (2,))
        wide[..., 0] = a
        yield wide[..., 0]                        # strided
        read_only = a.copy()
        read_only.flags.writeable = False
        yield read_only
        yield np.broadcast_to(sample, lead + sample.shape)   # read-only, zero strides
        raw = np.zeros(a.nbytes + 1, dtype=np.uint8)[1:]
        unaligned = raw.view(np.float64).reshape(a.shape)
        unaligned[...] = a
        yield unaligned
    yield sample.astype(np.int64) if np.all(sample == np.round(sample)) else sample


# float64 arrays: with one of them as the other argument, a single sample takes the fast path.
Q = np.array([0.1, -0.2, 0.3, 0.9])
M = rc.matrix_from_quaternion(Q)
V = np.array([0.3, -0.2, 0.1])
A = np.array([0.3, -0.2, 0.1])


def _public_calls():
    """(name, function of one argument in every form) for every public kernel path."""
    yield 'quaternion_product', lambda x: rc.quaternion_product(x, Q)
    yield 'quaternion_product (second)', lambda x: rc.quaternion_product(Q, x)
    yield 'quaternion_conjugate', rc.quaternion_conjugate
    yield 'canonical_quaternion', rc.canonical_quaternion
    yield 'quaternion_distance', lambda x: rc.quaternion_distance(x, Q)
    yield 'rotate_vector', lambda x: rc.rotate_vector(x, V)
    yield 'matrix_from_quaternion', rc.matrix_from_quaternion
    yield 'euler_from_quaternion', lambda x: rc.euler_from_quaternion(x, 'ZYX')
    yield 'euler_from_quaternion degrees', \
        lambda x: rc.euler_from_quaternion(x, 'xyz', degrees=True)
    yield 'euler_singularity_margin', lambda x: rc.euler_singularity_margin(x, 'zxz')
    yield 'axis_angle_from_quaternion', rc.axis_angle_from_quaternion
    yield 'rotation_vector_from_quaternion', rc.rotation_vector_from_quaternion
    yield 'quaternion_derivative', lambda x: rk.quaternion_derivative(x, V)
    yield 'angular_velocity_from_quaternion_derivative', \
        lambda x: rk.angular_velocity_from_quaternion_derivative(x, Q, 'world')


def _public_matrix_calls():
    yield 'quaternion_from_matrix', rc.quaternion_from_matrix
    yield 'euler_from_matrix', lambda x: rc.euler_from_matrix(x, 'yxz')
    yield 'axis_angle_from_matrix', rc.axis_angle_from_matrix
    yield 'rotation_vector_from_matrix', rc.rotation_vector_from_matrix
    yield 'matrix_derivative', lambda x: rk.matrix_derivative(x, V)
    yield 'angular_velocity_from_matrix_derivative', \
        lambda x: rk.angular_velocity_from_matrix_derivative(x, M)


def _public_vector_calls():
    yield 'quaternion_from_euler', lambda x: rc.quaternion_from_euler(x, 'XYZ')
    yield 'matrix_from_euler', lambda x: rc.matrix_from_euler(x, 'zyz', degrees=True)
    yield 'quaternion_from_rotation_vector', rc.quaternion_from_rotation_vector
    yield 'matrix_from_rotation_vector', rc.matrix_from_rotation_vector
    yield 'quaternion_from_axis_angle', lambda x: rc.quaternion_from_axis_angle(x, 0.5)
    yield 'matrix_from_axis_angle', lambda x: rc.matrix_from_axis_angle(x, 0.5)
    yield 'rotate_vector (vector)', lambda x: rc.rotate_vector(Q, x)
    yield 'angular_velocity_from_euler_rates', \
        lambda x: rk.angular_velocity_from_euler_rates(x, V, 'xyz')
    yield 'euler_rates_from_angular_velocity', \
        lambda x: rk.euler_rates_from_angular_velocity(A, x, 'ZXZ', 'world')


def _public_angle_calls():
    yield 'quaternion_from_axis_angle (angle)', lambda x: rc.quaternion_from_axis_angle(V, x)
    yield 'matrix_from_axis_angle (angle)', lambda x: rc.matrix_from_axis_angle(V, x)


_CASES = ([(name, f, Q) for name, f in _public_calls()]
          + [(name, f, M) for name, f in _public_matrix_calls()]
          + [(name, f, V) for name, f in _public_vector_calls()]
          + [(name, f, 0.7) for name, f in _public_angle_calls()])


def _signature_counts():
    return {k.py_func.__qualname__: len(k.signatures) for k in KERNELS}


@pytest.mark.parametrize('name, call, sample', _CASES, ids=[c[0] for c in _CASES])
def test_no_call_after_the_first_compiles(name, call, sample):
    """Every shape, dtype, layout and writability reaches the same compiled signature."""
    expected = call(np.asarray(sample, dtype=np.float64))
    before = _signature_counts()
    for x in _variants(sample):
        got = call(x)
        one = got[0] if isinstance(got, tuple) else got   # axis-angle: (axis, angle)
        lead = np.shape(x)[:np.ndim(x) - np.ndim(sample)]
        assert np.shape(one)[:len(lead)] == lead
        first = np.asarray(one).reshape((-1,) + np.shape(expected[0] if isinstance(
            expected, tuple) else expected))[0]
        assert np.allclose(first, expected[0] if isinstance(expected, tuple) else expected,
                           rtol=1e-6, atol=1e-6)
    after = _signature_counts()
    grown = {k: (before.get(k, 0), n) for k, n in after.items() if n > max(1, before.get(k, 0))}
    assert not grown, f'{name}: kernels compiled again: {grown}'
    assert all(n <= 1 for n in after.values()), after


def test_integration_and_finite_differences_compile_once(rng):
    t = np.linspace(0.0, 1.0, 11)
    before = None
    for q0 in ([0, 0, 0, 1], np.ones((2, 4)), np.ones((3, 1, 4), dtype=np.float32)):
        for omega in ([0.1, 0.2, 0.3], np.ones((2, 11, 3))):
            w = np.broadcast_to(omega, np.shape(omega)[:-1] + (11, 3)) if np.ndim(omega) == 1 \
                else omega
            q = rk.integrate_angular_velocity(q0, w, t)
            rk.angular_velocity_from_quaternions(q, t)
            rk.angular_velocity_from_quaternions(q[..., ::-1, :], t)   # strided view
            rk.angular_velocity_from_quaternions(q, t[::-1][::-1].copy()[::1])
            counts = _signature_counts()
            assert before is None or counts == before
            before = counts
    assert all(n <= 1 for n in before.values())


def test_a_kernel_called_with_other_types_raises_instead_of_compiling():
    kernel = _runtime.KERNELS[0]
    _runtime.compile_kernels([kernel])
    with pytest.raises(TypeError):
        kernel(np.zeros((2, 4)), np.zeros(4))   # 2-D where the layout is flat
    with pytest.raises(TypeError):
        kernel(np.zeros(4, dtype=np.float32), np.zeros(4))
    assert len(kernel.signatures) == 1


def _checking_unchecked_call(kernel, calls):
    """
    Return a ``call_unchecked`` asserting its contract: arrays of the declared types.

    It runs the kernel as it is (its compiled code once loaded, else its Python
    function) and never loads it: loading installs the kernel's own
    ``call_unchecked`` over this one (as with ROTATION_NODE_COMPILED=1, where a
    kernel loads at its first call), and later calls would go uncounted.
    """
    declared = kernel.numba_signature().args

    def call(*args):
        assert len(args) == len(declared)
        for argument, expected in zip(args, declared):
            if isinstance(expected, types.Array):
                assert typeof(argument) == expected, (kernel.__qualname__, argument)
        calls.append(kernel)
        run = kernel.interpreted if kernel.dispatcher is None else kernel.dispatcher
        return run(*args)

    return call


@pytest.mark.parametrize('name, call, sample', _CASES, ids=[c[0] for c in _CASES])
def test_single_samples_reach_the_compiled_code_with_its_declared_types(
        monkeypatch, name, call, sample):
    """The single-sample path skips numba's typing: its arrays must be the declared ones."""
    calls = []
    for dispatcher in KERNELS:
        monkeypatch.setattr(dispatcher, 'call_unchecked',
                            _checking_unchecked_call(dispatcher, calls))
    x = np.array(sample, dtype=np.float64) if np.ndim(sample) else float(sample)
    expected = call(x)
    assert calls, f'{name}: a single sample did not take the single-sample path'
    bad = np.full(np.shape(sample), np.nan) if np.ndim(sample) else math.nan
    with pytest.raises(ValueError, match='NaN'):
        call(bad)
    monkeypatch.undo()
    got = call(x)
    for a, b in zip(got if isinstance(got, tuple) else (got,),
                    expected if isinstance(expected, tuple) else (expected,)):
        assert np.array_equal(a, b)


def test_the_first_unchecked_call_is_typed():
    """A call site passing arrays of the wrong dimensions gets a TypeError, not a wrong read."""
    kernel = _quaternion._conjugate_kernel
    kernel.load()
    unchecked = kernel.call_unchecked
    try:
        kernel.call_unchecked = typed_first = _runtime.typed_first_call(kernel.dispatcher)
        with pytest.raises(TypeError):
            kernel.call_unchecked(np.zeros((1, 4)), np.zeros(4))
        assert kernel.call_unchecked is typed_first
        out = np.zeros(4)
        assert kernel.call_unchecked(np.array([1.0, 2.0, 3.0, 4.0]), out) == -1
        assert out.tolist() == [-1.0, -2.0, -3.0, 4.0]
        assert kernel.call_unchecked is not typed_first   # now the compiled code itself
        assert kernel.call_unchecked(np.array([0.0, 0.0, math.inf, 1.0]), out) >= 0
    finally:
        kernel.call_unchecked = unchecked


# Loops called only from other compiled code (inlined there), never from Python.
_COMPILED_ONLY = {'sin_cos_in_place_kernel', 'atan2_in_place_kernel'}


def _loops(module):
    return {name: value for name, value in vars(module).items()
            if callable(value) and name.endswith('_kernel')
            and inspect.getmodule(getattr(value, 'py_func', value)) is module}


def test_every_kernel_called_from_python_is_declared():
    """A loop that Python calls (named ..._kernel) is a kernel() with its one signature."""
    declared = set(map(id, KERNELS))
    for module_name in _MODULES:
        module = importlib.import_module(module_name)
        for name, loop in _loops(module).items():
            if name not in _COMPILED_ONLY:
                assert id(loop) in declared, f'{module_name}.{name} is not a kernel()'


def test_warm_up_compiles_every_kernel_with_its_signature():
    assert _runtime.compile_kernels() == len(KERNELS)
    for k in KERNELS:
        assert k.signatures == [k.numba_signature().args], k.__qualname__
        assert k.call == k.dispatcher


# ------------------------------------------------------------- cold start

def _python(code, env=None):
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=600, env=env)
    assert result.returncode == 0, result.stderr
    return result.stdout


@pytest.mark.slow
def test_importing_conversions_loads_nothing_beyond_numpy():
    out = _python('import sys, numpy\n'
                  'before = set(sys.modules)\n'
                  'import rotation_node.conversions\n'
                  'print(sorted(m for m in set(sys.modules) - before\n'
                  '             if m.split(".")[0] not in sys.stdlib_module_names\n'
                  '             and not m.startswith("rotation_node.conversions.")))\n')
    assert out.strip() == "['rotation_node', 'rotation_node.conversions']"


_POLICY = """
import sys
import numpy as np
from rotation_node import conversions, kinematics
from rotation_node.conversions import _euler, _runtime
q = np.tile([0.1, 0.2, 0.3, 0.9], ({n}, 1))
conversions.euler_from_quaternion(q, 'xyz')
kinematics.quaternion_derivative([0.0, 0.0, 0.0, 1.0], [1.0, 2.0, 3.0])
print('numba' in sys.modules, 'llvmlite' in sys.modules,
      sorted(k.__name__ for k in _runtime.KERNELS if k.dispatcher is not None))
"""


@pytest.mark.slow
def test_small_calls_run_interpreted_without_numba_and_a_large_one_loads_its_kernel():
    env = dict(os.environ)
    env.pop('ROTATION_NODE_COMPILED', None)   # the default policy, whatever the caller's
    small = _runtime.INTERPRETED_VALUES // 4
    assert _python(_POLICY.format(n=small), env).split() == ['False', 'False', '[]']
    # the kernel of the call's schedule (a batch schedule from BATCH_SAMPLES samples)
    used = ('_euler_from_quaternion_batch_kernel' if small + 1 >= _runtime.BATCH_SAMPLES
            else '_euler_from_quaternion_kernel')
    assert _python(_POLICY.format(n=small + 1), env).split() == ['True', 'True', f"['{used}']"]


def test_a_kernel_is_loaded_once_it_has_run_interpreted_for_as_long_as_a_load_takes(
        monkeypatch):
    monkeypatch.setattr(_runtime, '_loading_forced', False)   # not ROTATION_NODE_COMPILED=1
    kernel = _runtime.Kernel(_quaternion._conjugate_kernel.py_func, (_runtime.FLAT_IN,
                                                                     _runtime.FLAT_OUT),
                             _runtime.STATUS)
    q, out = np.array([0.1, 0.2, 0.3, 0.9]), np.empty(4)
    assert kernel(q, out) == -1 and kernel.dispatcher is None and kernel.used
    assert kernel.interpreted_seconds > 0.0
    kernel.interpreted_seconds = _runtime.INTERPRETED_SECONDS * 1.01
    assert kernel(q, out) == -1
    assert kernel.dispatcher is not None and kernel.call is kernel.dispatcher
    assert out.tolist() == [-0.1, -0.2, -0.3, 0.9]


@pytest.mark.slow
def test_the_first_call_does_not_import_scipy_linalg_and_numba_linear_algebra_still_works():
    """The BLAS probe is answered without importing scipy.linalg; np.dot still compiles."""
    out = _python('import importlib.util, sys\n'
                  'import numba, numpy as np\n'
                  'from rotation_node import conversions\n'
                  'conversions.euler_from_quaternion(np.tile([0.1, 0.2, 0.3, 0.9], (2000, 1)),'
                  ' "xyz")\n'
                  'print("scipy.linalg" in sys.modules)\n'
                  'import numba.np.arraymath, numba.np.linalg\n'
                  'print(numba.np.arraymath._HAVE_BLAS'
                  ' == (importlib.util.find_spec("scipy") is not None))\n'
                  'print(numba.np.linalg.ensure_blas.__module__)\n'
                  'dot = numba.njit(lambda a, b: np.dot(a, b))\n'
                  'a = np.arange(9.0).reshape(3, 3)\n'
                  'print(np.array_equal(dot(a, a), a @ a))\n')
    assert out.split() == ['False', 'True', 'numba.np.linalg', 'True']


@pytest.mark.slow
def test_numba_registries_loaded_before_the_first_call_are_left_as_they_are():
    out = _python('import sys\n'
                  'import numba.np.arraymath\n'
                  'have_blas = numba.np.arraymath._HAVE_BLAS\n'
                  'from rotation_node import conversions\n'
                  'from rotation_node.conversions import _runtime\n'
                  '_runtime.compile_kernels(_runtime.KERNELS[:1])\n'
                  'print(numba.np.arraymath._HAVE_BLAS == have_blas,\n'
                  '      "scipy.linalg" in sys.modules)\n')
    assert out.split() == ['True', str(importlib.util.find_spec('scipy') is not None)]


@pytest.mark.slow
def test_kernels_are_cached_in_the_user_cache_where_the_package_is_read_only(tmp_path):
    """Where the in-tree cache is unusable (a system install), the user-wide one is used."""
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path), ROTATION_NODE_COMPILED='1')
    env.pop('NUMBA_CACHE_DIR', None)
    code = ('from numba.core import caching\n'
            # _InTreeCacheLocator in older numba releases (0.59, Ubuntu 24.04's, among them)
            'in_tree = getattr(caching, "InTreeCacheLocator", None)'
            ' or caching._InTreeCacheLocator\n'
            'in_tree.from_function = classmethod(lambda cls, f, p: None)\n'
            'from rotation_node import conversions, kinematics\n'
            'conversions.quaternion_conjugate([0.0, 0.0, 0.0, 1.0])\n'
            'kinematics.quaternion_derivative([0.0, 0.0, 0.0, 1.0], [1.0, 2.0, 3.0])\n')
    _python(code, env)
    cached = [p.name for p in (tmp_path / 'numba').rglob('*.nbi')]
    assert any('_conjugate_kernel' in name for name in cached), cached
    assert any('_quaternion_derivative_kernel' in name for name in cached), cached


@pytest.mark.slow
def test_warm_up_entry_point():
    out = _python('from rotation_node.conversions import warm_up; warm_up.main([])')
    # the library's kernels (this process may also hold kernels of modules above it)
    library = [k for k in KERNELS if k.__module__.startswith(
        ('rotation_node.conversions', 'rotation_node.kinematics'))]
    assert out.startswith(f'rotation_node: {len(library)} kernels compiled or loaded')
    assert _python('from rotation_node.conversions import warm_up; '
                   'warm_up.main(["--quiet"])') == ''


ANNOUNCING = """
import numba
from rotation_node import conversions
from rotation_node.conversions import warm_up
lines = []
with warm_up.announcing_compilation(lines.append, after={after}) as compilation:
    numba.njit(lambda x: x + 1.0)(1.0)   # not a kernel: neither counted nor announced
    conversions.quaternion_conjugate([0.0, 0.0, 0.0, 1.0])
    conversions.quaternion_product([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0])
print(compilation.compiled)
for line in lines:
    print(line)
"""


def _announced(cache, after):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), ROTATION_NODE_COMPILED='1')
    compiled, *lines = _python(ANNOUNCING.format(after=after), env).splitlines()
    return int(compiled), lines


@pytest.mark.slow
def test_a_start_that_compiles_kernels_says_so_once_and_a_cached_start_says_nothing(tmp_path):
    compiled, lines = _announced(tmp_path, after=0.0)   # an empty cache: both compile
    assert compiled == 2
    assert lines[0] == warm_up.COMPILING and len(lines) == 2, lines
    assert re.fullmatch(r'2 kernels compiled in [0-9.]+ s and cached', lines[1]), lines
    assert _announced(tmp_path, after=0.0) == (0, [])   # loaded from the cache


@pytest.mark.slow
def test_a_compilation_shorter_than_the_delay_is_not_announced(tmp_path):
    assert _announced(tmp_path, after=600.0) == (2, [])


# ------------------------------------------- interpreted and compiled: the same bits

SEQUENCES = ('xyz', 'ZYX', 'zxz', 'YXY', 'xzy', 'ZXY')


def _corpus_calls(rng, n):
    """Return (name, call) of every public conversion and kinematics function on hard cases."""
    q, p = hard_quaternions(rng, n), hard_quaternions(rng, n)
    m, noisy = hard_matrices(rng, n), noisy_matrices(rng, n, 1e-3)
    v = hard_rotation_vectors(rng, n)
    t = hard_angles(rng, n)
    axis = rng.normal(size=(n, 3))
    r = rng.normal(size=(n, 3))
    yield 'quaternion_product', lambda: rc.quaternion_product(p, q)
    yield 'quaternion_conjugate', lambda: rc.quaternion_conjugate(q)
    yield 'canonical_quaternion', lambda: rc.canonical_quaternion(q)
    yield 'quaternion_distance', lambda: rc.quaternion_distance(p, q)
    yield 'rotate_vector', lambda: rc.rotate_vector(q, r)
    yield 'matrix_from_quaternion', lambda: rc.matrix_from_quaternion(q)
    yield 'axis_angle_from_quaternion', lambda: rc.axis_angle_from_quaternion(q)
    yield 'rotation_vector_from_quaternion', lambda: rc.rotation_vector_from_quaternion(q)
    yield 'quaternion_from_rotation_vector', lambda: rc.quaternion_from_rotation_vector(v)
    yield 'matrix_from_rotation_vector', lambda: rc.matrix_from_rotation_vector(v)
    yield 'quaternion_from_axis_angle', lambda: rc.quaternion_from_axis_angle(axis, t)
    yield 'matrix_from_axis_angle', lambda: rc.matrix_from_axis_angle(axis, t)
    for matrices in (m, noisy):
        yield 'quaternion_from_matrix', lambda: rc.quaternion_from_matrix(matrices)
        yield 'axis_angle_from_matrix', lambda: rc.axis_angle_from_matrix(matrices)
        yield 'rotation_vector_from_matrix', lambda: rc.rotation_vector_from_matrix(matrices)
    for seq in SEQUENCES:
        angles = np.concatenate([near_gimbal_lock_angles(rng, n // 2, seq),
                                 rng.uniform(-4.0, 4.0, (n - n // 2, 3))])
        yield f'euler_from_quaternion {seq}', lambda: rc.euler_from_quaternion(q, seq)
        yield f'euler_from_quaternion {seq} degrees', \
            lambda: rc.euler_from_quaternion(q, seq, degrees=True)
        yield f'euler_singularity_margin {seq}', lambda: rc.euler_singularity_margin(q, seq)
        yield f'euler_from_matrix {seq}', lambda: rc.euler_from_matrix(m, seq)
        yield f'quaternion_from_euler {seq}', lambda: rc.quaternion_from_euler(angles, seq)
        yield f'matrix_from_euler {seq}', lambda: rc.matrix_from_euler(angles, seq)
        yield f'euler_rates_from_angular_velocity {seq}', \
            lambda: rk.euler_rates_from_angular_velocity(angles, r, seq)
        yield f'angular_velocity_from_euler_rates {seq}', \
            lambda: rk.angular_velocity_from_euler_rates(angles, r, seq, 'world')
    for frame in ('body', 'world'):
        yield f'quaternion_derivative {frame}', lambda: rk.quaternion_derivative(q, r, frame)
        yield f'angular_velocity_from_quaternion_derivative {frame}', \
            lambda: rk.angular_velocity_from_quaternion_derivative(q, p, frame)
        yield f'matrix_derivative {frame}', lambda: rk.matrix_derivative(m, r, frame)
        yield f'angular_velocity_from_matrix_derivative {frame}', \
            lambda: rk.angular_velocity_from_matrix_derivative(m, noisy, frame)
    stamps = np.cumsum(rng.uniform(0.001, 0.01, n))
    rates = rng.normal(size=(n, 3))
    yield 'angular_velocity_from_quaternions', \
        lambda: rk.angular_velocity_from_quaternions(q, stamps)
    for method in ('euler', 'midpoint_exp', 'rk4', 'magnus4', 'coning2'):
        yield f'integrate_angular_velocity {method}', \
            lambda: rk.integrate_angular_velocity(q[0], rates, stamps, method=method)


def _recorded_kernel_calls(monkeypatch, calls):
    """Record the arguments of every kernel call (copies), made through either path."""
    recorded = []

    def recorder(kernel, original):
        def call(*args):
            recorded.append((kernel, [a.copy() if isinstance(a, np.ndarray) else a
                                      for a in args]))
            return original(*args)
        return call

    for kernel in KERNELS:
        monkeypatch.setattr(kernel, 'call', recorder(kernel, kernel.call))
        monkeypatch.setattr(kernel, 'call_unchecked', recorder(kernel, kernel.call_unchecked))
    for name, call in calls:
        try:
            call()
        except ValueError:   # a hard case that a function refuses: its kernel ran on it anyway
            pass
    monkeypatch.undo()
    return recorded


def _run_fresh(run, arguments):
    args = [a.copy() if isinstance(a, np.ndarray) else a for a in arguments]
    result = run(*args)
    return result, [a.tobytes() for a in args if isinstance(a, np.ndarray)]


_IGNORE_SINGULAR = 'ignore::rotation_node.kinematics._euler_rates.EulerSingularityWarning'


@pytest.mark.filterwarnings(_IGNORE_SINGULAR)
def test_every_kernel_gives_the_same_bits_interpreted_and_compiled(monkeypatch, rng):
    """Each kernel's Python function and its compiled code: the same outputs, bit for bit."""
    _runtime.compile_kernels()
    calls = [c for n in (1, 7, _runtime.BATCH_SAMPLES + 5) for c in _corpus_calls(rng, n)]
    recorded = _recorded_kernel_calls(monkeypatch, calls)
    ours = {k.__qualname__ for k in KERNELS
            if k.__module__.startswith(('rotation_node.conversions', 'rotation_node.kinematics'))}
    assert {k.__qualname__ for k, _ in recorded} == ours
    for kernel, arguments in recorded:
        compiled = _run_fresh(kernel.dispatcher, arguments)
        interpreted = _run_fresh(kernel.interpreted, arguments)
        assert compiled == interpreted, kernel.__qualname__


def test_random_samples_give_the_same_bits_interpreted_and_compiled(monkeypatch, rng):
    _runtime.compile_kernels()
    q, r = rng.normal(size=(300, 4)), rng.normal(scale=3.0, size=(300, 3))
    calls = [('euler', lambda: rc.euler_from_quaternion(q, 'ZYX')),
             ('matrix', lambda: rc.matrix_from_quaternion(q)),
             ('rotation_vector', lambda: rc.quaternion_from_rotation_vector(r)),
             ('rotate', lambda: rc.rotate_vector(q, r)),
             ('euler_from_matrix', lambda: rc.euler_from_matrix(rc.matrix_from_quaternion(q),
                                                                'zyz'))]
    for kernel, arguments in _recorded_kernel_calls(monkeypatch, calls):
        assert _run_fresh(kernel.dispatcher, arguments) == _run_fresh(kernel.interpreted,
                                                                      arguments)


# ------------------------------------------------------- lists, tuples and numbers

@pytest.mark.parametrize('name, call, sample', _CASES, ids=[c[0] for c in _CASES])
def test_lists_and_tuples_take_the_single_sample_path_with_the_same_results(
        monkeypatch, name, call, sample):
    calls = []
    monkeypatch.setattr(_runtime, 'copied', lambda kernel_, widths: None)   # no tuple forms
    for kernel in KERNELS:
        monkeypatch.setattr(kernel, 'call_unchecked',
                            _checking_unchecked_call(kernel, calls))
        monkeypatch.setattr(kernel, 'call_tuple', None)
    listed = np.asarray(sample).tolist()
    if np.ndim(sample) == 0:   # an angle: Python and numpy numbers
        forms = [listed, np.float64(sample), np.float32(sample), np.int64(2)]
    else:
        forms = [listed, tuple(map(tuple, listed)) if np.ndim(sample) == 2 else tuple(listed)]
    for x in forms:
        got = call(x)
        expected = call(np.asarray(x, dtype=np.float64))   # numpy's conversion of x
        for a, b in zip(got if isinstance(got, tuple) else (got,),
                        expected if isinstance(expected, tuple) else (expected,)):
            assert np.asarray(a).tobytes() == np.asarray(b).tobytes(), name
    assert len(calls) == 2 * len(forms), f'{name}: a list or tuple took the general path'


@pytest.mark.parametrize('bad', [
    [0.1, 0.2, 0.3], [0.1, 0.2, 0.3, 0.4, 0.5], ['a', 0.2, 0.3, 0.9], [0.1, 0.2, 0.3, None],
    [math.nan, 0.2, 0.3, 0.9], [0.0, 0.0, 0.0, 0.0], (0.1, [0.2], 0.3, 0.9),
    [[0.1, 0.2], [0.3, 0.9]],
    [0.1, 0.2, 0.3, math.inf]])
def test_bad_lists_get_the_messages_arrays_get(bad):
    def message(x):
        with pytest.raises(ValueError) as error:
            rc.euler_from_quaternion(x, 'xyz')
        return str(error.value)

    try:
        as_array = np.asarray(bad, dtype=np.float64)
    except (TypeError, ValueError):
        as_array = np.asarray(bad, dtype=object)
    if as_array.dtype == object:   # numpy refuses it too: the message names the list
        assert message(bad).startswith('Expected `q` to be an array of numbers with shape')
    else:
        assert message(bad) == message(as_array)
    assert message(tuple(bad)) == message(bad).replace('got list', 'got tuple')


def test_a_bad_list_as_second_argument_or_matrix_names_it():
    with pytest.raises(ValueError, match='`v` has a NaN or Inf component'):
        rc.rotate_vector([0.0, 0.0, 0.0, 1.0], [0.0, math.nan, 1.0])
    expected = re.escape('Expected `v` to have shape (..., 3), got (2,)')
    with pytest.raises(ValueError, match=expected):
        rc.rotate_vector([0.0, 0.0, 0.0, 1.0], [0.0, 1.0])
    with pytest.raises(ValueError, match='`R` has det <= 0'):
        rc.quaternion_from_matrix([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])


def test_single_samples_from_lists_in_threads_do_not_mix():
    """Each thread copies a list into arrays of its own."""
    from concurrent.futures import ThreadPoolExecutor
    samples_ = [np.array([0.1 * i, -0.2, 0.3, 0.9]) for i in range(40)]
    expected = [rc.euler_from_quaternion(q, 'xyz').tobytes() for q in samples_]

    def convert(i):
        return [rc.euler_from_quaternion(samples_[i].tolist(), 'xyz').tobytes()
                for _ in range(200)]

    with ThreadPoolExecutor(4) as pool:
        for i, results in enumerate(pool.map(convert, range(len(samples_)))):
            assert set(results) == {expected[i]}


# Calls of one sample whose every argument may be Python values: (name, call, samples).
_PYTHON_VALUE_CALLS = [
    ('euler_from_quaternion', lambda q: rc.euler_from_quaternion(q, 'xyz'), ('q',)),
    ('euler_from_quaternion ZXZ degrees',
     lambda q: rc.euler_from_quaternion(q, 'ZXZ', degrees=True), ('q',)),
    ('quaternion_from_euler', lambda a: rc.quaternion_from_euler(a, 'xyz'), ('v',)),
    ('matrix_from_quaternion', rc.matrix_from_quaternion, ('q',)),
    ('rotate_vector', rc.rotate_vector, ('q', 'v')),
    ('quaternion_product', rc.quaternion_product, ('q', 'q')),
    ('quaternion_distance', rc.quaternion_distance, ('q', 'q')),
    ('quaternion_from_axis_angle', rc.quaternion_from_axis_angle, ('v', 'angle')),
]


class _Attributes:
    """A plain duck-typed sample: whatever attributes it is given, in its instance dict."""

    def __init__(self, **attributes):
        self.__dict__.update(attributes)


class _SlotQuaternion:
    """A quaternion of plain slots (no properties, no instance dict): the type decides."""

    __slots__ = ('x', 'y', 'z', 'w')

    def __init__(self, x, y, z, w):
        self.x, self.y, self.z, self.w = x, y, z, w


class _SlotVector:
    __slots__ = ('x', 'y', 'z')

    def __init__(self, x, y, z):
        self.x, self.y, self.z = x, y, z


def _message_objects(values):
    """
    Return a quaternion's or 3-vector's Python floats as objects with attributes x, y, z(, w).

    geometry_msgs Quaternion (alone and as a Pose's field), Vector3 and
    Point, a plain class with instance attributes and one with slots.
    """
    from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
    if len(values) == 4:
        fields = dict(zip('xyzw', values))
        return [Quaternion(**fields), Pose(orientation=Quaternion(**fields)).orientation,
                _Attributes(**fields), _SlotQuaternion(*values)]
    fields = dict(zip('xyz', values))
    return [Vector3(**fields), Point(**fields), _Attributes(**fields), _SlotVector(*values)]


def _message_field_values(sample):
    """
    Return ``sample`` (ndarray (4,) or (3,), or a number) as ROS messages hold it.

    The attributes of a geometry_msgs Quaternion or Vector3 (Python floats, as a
    callback reads them into a tuple), rclpy's array.array of a float64 sequence
    (std_msgs Float64MultiArray), the first values of a fixed-size float64 array
    field (sensor_msgs Imu's covariance, a numpy array), a float64 field, and
    the message objects themselves (:func:`_message_objects`).
    """
    from array import array

    from geometry_msgs.msg import Quaternion, Vector3
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64, Float64MultiArray
    if np.ndim(sample) == 0:
        return [Float64(data=float(sample)).data]
    values = [float(v) for v in sample]
    message = Quaternion(**dict(zip('xyzw', values))) if len(values) == 4 else \
        Vector3(**dict(zip('xyz', values)))
    fields = tuple(getattr(message, name) for name in 'xyzw'[:len(values)])
    sequence = Float64MultiArray(data=values).data
    assert type(sequence) is array
    imu = Imu()
    imu.orientation_covariance[:len(values)] = values
    return [fields, sequence, imu.orientation_covariance[:len(values)].copy()] + \
        _message_objects(values)


def _python_value_forms(sample):
    """Return ``sample`` in every form of Python values a caller may pass (and ROS fields)."""
    if np.ndim(sample) == 0:
        return [float(sample), np.float64(sample)] + _message_field_values(sample)
    listed = np.asarray(sample).tolist()
    return [listed, tuple(listed)] + _message_field_values(sample)


def _python_value_samples(rng):
    """Quaternions and vectors: random ones and hard cases (near 0, pi, gimbal lock, tiny)."""
    q = np.concatenate([rng.normal(size=(6, 4)), hard_quaternions(rng, 16)])
    v = np.concatenate([rng.normal(size=(6, 3)), hard_rotation_vectors(rng, 16)])
    return {'q': q, 'v': v, 'angle': np.concatenate([rng.normal(size=6), v[:16, 0]])}


def _same_result(got, expected):
    for a, b in zip(got if isinstance(got, tuple) else (got,),
                    expected if isinstance(expected, tuple) else (expected,)):
        assert type(a) is type(b) and np.asarray(a).tobytes() == np.asarray(b).tobytes()


def _outcome(call, arguments):
    """Return ``call(*arguments)``, or the message of the ValueError it raises (a bad sample)."""
    try:
        return call(*arguments)
    except ValueError as error:
        return str(error)


def _same_outcome(got, expected):
    if isinstance(expected, str):
        assert got == expected
    else:
        _same_result(got, expected)


@pytest.mark.parametrize('name, call, kinds', _PYTHON_VALUE_CALLS,
                         ids=[c[0] for c in _PYTHON_VALUE_CALLS])
def test_python_values_and_message_fields_give_the_bits_of_float64_arrays(
        monkeypatch, rng, name, call, kinds):
    """
    Lists, tuples, ROS message fields and numbers: the float64 array's result, bit for bit.

    Both before a kernel's tuple form is loaded (lists copied into arrays) and
    after (numba unboxes the tuple), each in the same process.
    """
    _runtime.compile_kernels()
    monkeypatch.setattr(_runtime, 'copied', lambda kernel_, widths: None)
    samples_ = _python_value_samples(rng)
    cases = [tuple(samples_[kind][i] for kind in kinds) for i in range(len(samples_['q']))]
    calls = []
    for loaded in (False, True):
        if loaded:   # the first copy loads the tuple form
            monkeypatch.undo()
            monkeypatch.setattr(_runtime, 'TUPLE_COPIES', 1)
            call(*[_python_value_forms(a)[0] for a in cases[0]])
            _counted_tuple_forms(monkeypatch, calls)
        for arguments in cases:   # a hard case may be bad (a zero axis): the same message
            expected = _outcome(call, [np.asarray(a, dtype=np.float64) if np.ndim(a)
                                       else float(a) for a in arguments])
            form_lists = [_python_value_forms(a) for a in arguments]
            count = max(map(len, form_lists))   # an angle's forms, again for each vector form
            for forms in zip(*[itertools.islice(itertools.cycle(f), count) for f in form_lists]):
                _same_outcome(_outcome(call, forms), expected)
            for i in range(len(arguments)):   # one argument a Python value, the others arrays
                mixed = [np.asarray(a, dtype=np.float64) for a in arguments]
                mixed[i] = _python_value_forms(arguments[i])[0]
                _same_outcome(_outcome(call, mixed), expected)
    assert calls, f'{name}: no call took a tuple form'


def _counted_tuple_forms(monkeypatch, calls):
    for kernel in KERNELS:
        if kernel.call_tuple is not None:
            def counted(*args, kernel=kernel, original=kernel.call_tuple):
                calls.append(kernel)
                return original(*args)
            monkeypatch.setattr(kernel, 'call_tuple', counted)


def test_python_values_take_the_tuple_form_once_loaded(monkeypatch):
    monkeypatch.setattr(_runtime, '_loading_forced', False)   # not ROTATION_NODE_COMPILED=1
    monkeypatch.setattr(_runtime, 'TUPLE_COPIES', 3)
    kernel = _runtime.KERNELS[[k.__name__ for k in KERNELS].index('_rotate_kernel')]
    _runtime.compile_kernels([kernel])   # loaded, whichever tests ran before
    q, v = [0.1, -0.2, 0.3, 0.9], (1.0, 2.0, 3.0)
    expected = rc.rotate_vector(np.array(q), np.array(v))
    monkeypatch.setattr(kernel, 'call_tuple', None)
    monkeypatch.setattr(kernel, 'tuple_copies', 0)
    for _ in range(3):   # copied into arrays, counted
        _same_result(rc.rotate_vector(q, v), expected)
    assert kernel.call_tuple is not None and kernel.tuple_copies == 3
    calls = []
    _counted_tuple_forms(monkeypatch, calls)
    _same_result(rc.rotate_vector(q, v), expected)
    _same_result(rc.rotate_vector(q, np.array(v)), expected)   # an array: the other path
    assert calls == [kernel]


def test_a_background_loader_gets_the_tuple_form_instead_of_the_caller(monkeypatch):
    """With the node's loader, a callback copying tuples never waits for a tuple form to load."""
    kernel = next(k for k in KERNELS if k.__name__ == '_matrix_from_quaternion_kernel')
    _runtime.compile_kernels([kernel])
    handed = []
    monkeypatch.setattr(_runtime, '_on_first_use', handed.append)
    monkeypatch.setattr(_runtime, '_loading_forced', False)
    monkeypatch.setattr(_runtime, 'TUPLE_COPIES', 2)
    monkeypatch.setattr(kernel, 'call_tuple', None)
    monkeypatch.setattr(kernel, 'tuple_copies', 0)
    monkeypatch.setattr(kernel, 'tuple_form_queued', False)
    q = (0.1, -0.2, 0.3, -0.9)
    expected = rc.matrix_from_quaternion(np.array(q))
    for _ in range(4):
        _same_result(rc.matrix_from_quaternion(q), expected)
    assert kernel.call_tuple is None   # not loaded in the calling thread
    assert handed == [_runtime.TupleForm(kernel, (4,))]   # handed over once
    handed[0].load()   # what the loader does
    assert kernel.call_tuple is not None
    calls = []
    _counted_tuple_forms(monkeypatch, calls)
    _same_result(rc.matrix_from_quaternion(q), expected)
    assert calls == [kernel]


_BAD_PYTHON_VALUES = [
    ([0.1, 0.2, 0.3], (1.0, 2.0, 3.0)), ([0.1, 0.2, 0.3, 0.4, 0.5], (1.0, 2.0, 3.0)),
    (['a', 0.2, 0.3, 0.9], (1.0, 2.0, 3.0)), ([0.1, 0.2, 0.3, None], (1.0, 2.0, 3.0)),
    ([math.nan, 0.2, 0.3, 0.9], (1.0, 2.0, 3.0)), ([0.0, 0.0, 0.0, 0.0], (1.0, 2.0, 3.0)),
    ((0.1, [0.2], 0.3, 0.9), (1.0, 2.0, 3.0)), ([0.1, np.array([0.2]), 0.3, 0.9], (1.0, 2.0, 3.0)),
    ([10 ** 400, 0.0, 0.0, 1.0], (1.0, 2.0, 3.0)), ([0.1, 0.2, 0.3, 0.9], (1.0, math.inf, 3.0)),
    ([0.1, 0.2, 0.3, 0.9], (1.0, 2.0)), ([0.1, 0.2, 0.3, 0.9], ('x', 2.0, 3.0)),
    ([[0.1, 0.2], [0.3, 0.9]], (1.0, 2.0, 3.0))]


@pytest.mark.parametrize('loaded', [False, True], ids=['copied', 'tuple form'])
@pytest.mark.parametrize('q, v', _BAD_PYTHON_VALUES)
def test_bad_python_values_get_the_one_line_error_of_their_array(monkeypatch, loaded, q, v):
    """What numpy's conversion of a list refuses or a kernel finds bad: one ValueError line."""
    def message(q, v):
        with pytest.raises(ValueError) as error:
            rc.rotate_vector(q, v)
        return str(error.value)

    if loaded:
        monkeypatch.setattr(_runtime, 'TUPLE_COPIES', 1)
        for _ in range(2):
            rc.rotate_vector([0.1, 0.2, 0.3, 0.9], [1.0, 2.0, 3.0])
        assert _runtime.KERNELS[[k.__name__ for k in KERNELS].index(
            '_rotate_kernel')].call_tuple is not None
    else:
        monkeypatch.setattr(_runtime, 'copied', lambda kernel_, widths: None)
        for kernel in KERNELS:
            monkeypatch.setattr(kernel, 'call_tuple', None)
    q, v = list(q), tuple(v)
    listed = message(q, v)
    assert '\n' not in listed
    assert message(tuple(q), v) == listed.replace('got list', 'got tuple')   # about q
    assert message(q, list(v)) == listed.replace('got tuple', 'got list')    # about v

    def as_array(x):
        try:
            return np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            return None

    if as_array(q) is not None and as_array(v) is not None:   # numpy converts them: the same
        assert listed == message(as_array(q), as_array(v))
    else:   # numpy refuses one: the message names it and what numpy said
        assert listed.startswith('Expected `')


# ------------------------------------------------------- message objects

def _message_calls(q, v):
    """Return calls of every kind of single-sample argument: (name, function, arguments)."""
    return [('euler', lambda a: rc.euler_from_quaternion(a, 'ZYX', degrees=True), (q,)),
            ('matrix', rc.matrix_from_quaternion, (q,)),
            ('rotation_vector', rc.rotation_vector_from_quaternion, (q,)),
            ('from_euler', lambda a: rc.quaternion_from_euler(a, 'xyz'), (v,)),
            ('rotate', rc.rotate_vector, (q, v)), ('product', rc.quaternion_product, (q, q)),
            ('distance', rc.quaternion_distance, (q, q)),
            ('axis_angle', rc.quaternion_from_axis_angle, (v, 0.75)),
            # An object names its components: scalar_first reorders a tuple, never an object.
            ('scalar_first', lambda a: rc.quaternion_conjugate(
                (a[3],) + a[:3] if type(a) is tuple else a, scalar_first=True), (q,))]


def _use_tuple_forms(monkeypatch, loaded):
    """Before kernels' tuple forms load (samples copied into arrays), or after (loaded)."""
    _runtime.compile_kernels()
    if loaded:
        monkeypatch.setattr(_runtime, 'TUPLE_COPIES', 1)
        for _, call, arguments in _message_calls((0.1, 0.2, 0.3, 0.9), (1.0, 2.0, 3.0)):
            for _ in range(2):
                call(*arguments)
    else:
        monkeypatch.setattr(_runtime, 'copied', lambda kernel_, widths: None)
        for kernel in KERNELS:
            monkeypatch.setattr(kernel, 'call_tuple', None)


@pytest.mark.parametrize('loaded', [False, True], ids=['copied', 'tuple form'])
def test_message_objects_take_the_single_sample_path_with_the_bits_of_tuples(
        monkeypatch, loaded):
    """A Quaternion, Vector3 or Point never reaches the general path (float_array)."""
    from geometry_msgs.msg import Point, Quaternion, Vector3
    _use_tuple_forms(monkeypatch, loaded)
    q, v = (0.1, -0.2, 0.3, 0.9), (1.0, -2.0, 3.5)
    expected = [call(*arguments) for _, call, arguments in _message_calls(q, v)]
    messages = [(Quaternion(**dict(zip('xyzw', q))), vector(**dict(zip('xyz', v))))
                for vector in (Vector3, Point)]

    def general_path(*args):
        raise AssertionError(f'the general path took {args}')

    monkeypatch.setattr(_runtime, 'float_array', general_path)
    calls = []
    _counted_tuple_forms(monkeypatch, calls)
    for qm, vm in messages:
        for (name, call, arguments), result in zip(_message_calls(qm, vm), expected):
            _same_result(call(*arguments), result)
    _same_result(rc.rotate_vector(np.array(q), messages[0][1]), expected[4])   # mixed
    _same_result(rc.rotate_vector(messages[0][0], list(v)), expected[4])
    assert bool(calls) == loaded


def _bad_message_objects():
    from geometry_msgs.msg import Quaternion, Vector3
    strings, nones = Quaternion(check_fields=False), Quaternion(check_fields=False)
    strings.y, nones.w = 'a', None
    return [
        (lambda: rc.euler_from_quaternion(Vector3(x=0.1), 'xyz'),
         'Expected `q` to be an array of numbers with shape (..., 4) or objects with attributes '
         'x, y, z, w, got Vector3: it has no attribute w (a quaternion is x, y, z, w)'),
        (lambda: rc.rotate_vector(Quaternion(), Quaternion()),
         'Expected `v` to be an array of numbers with shape (..., 3) or objects with attributes '
         'x, y, z, got Quaternion: it has an attribute w: a quaternion where a 3-vector '
         '(x, y, z) is needed'),
        (lambda: rc.quaternion_product(Quaternion(), _Attributes(x=0.1, y=0.2)),
         'got _Attributes: it has no attribute z, w'),
        (lambda: rc.rotate_vector(Quaternion(), _SlotQuaternion(0.0, 0.0, 0.0, 1.0)),
         'got _SlotQuaternion: it has an attribute w'),
        (lambda: rc.matrix_from_quaternion(strings),
         "got Quaternion: could not convert string to float: 'a'"),
        # numpy takes None as NaN, in a list too (test_bad_lists_get_the_messages_arrays_get)
        (lambda: rc.matrix_from_quaternion(nones), '`q` has a NaN or Inf component.'),
        (lambda: rc.euler_from_quaternion([Quaternion(), [Quaternion(), Vector3()]], 'xyz'),
         'got list: item [1][1], a Vector3, has no attribute w'),
        (lambda: rc.rotate_vector([Quaternion()], (Vector3(), Quaternion())),
         'got tuple: item [1], a Quaternion, has an attribute w'),
        (lambda: rc.euler_from_quaternion(Quaternion(x=math.nan), 'xyz'),
         '`q` has a NaN or Inf component.'),
        (lambda: rc.euler_from_quaternion(Quaternion(x=0.0, w=0.0), 'xyz'),
         '`q` has zero norm'),
        (lambda: rc.euler_from_quaternion([Quaternion(), Quaternion(w=math.inf)], 'xyz'),
         '`q` at index (1,) has a NaN or Inf component.'),
        (lambda: rc.euler_from_quaternion(object(), 'xyz'),
         'Expected `q` to be an array of numbers with shape (..., 4), got object: float()')]


@pytest.mark.parametrize('loaded', [False, True], ids=['copied', 'tuple form'])
@pytest.mark.parametrize('case', range(12))
def test_bad_message_objects_get_one_line_errors_naming_what_is_wrong(monkeypatch, loaded, case):
    _use_tuple_forms(monkeypatch, loaded)
    call, expected = _bad_message_objects()[case]
    with pytest.raises(ValueError) as error:
        call()
    assert '\n' not in str(error.value)
    assert expected in str(error.value)


def test_lists_of_message_objects_give_the_bits_of_their_arrays(rng):
    from geometry_msgs.msg import Point, Quaternion, Vector3
    q, v = rng.normal(size=(6, 4)), rng.normal(size=(6, 3))
    quaternions = [Quaternion(**dict(zip('xyzw', map(float, x)))) for x in q]
    vectors = [(Vector3 if i % 2 else Point)(**dict(zip('xyz', map(float, x))))
               for i, x in enumerate(v)]
    checks = [
        (rc.euler_from_quaternion(quaternions, 'xyz'), rc.euler_from_quaternion(q, 'xyz')),
        (rc.rotate_vector(quaternions, vectors), rc.rotate_vector(q, v)),
        (rc.rotate_vector(quaternions[2], tuple(vectors)), rc.rotate_vector(q[2], v)),
        (rc.quaternion_product(tuple(quaternions), quaternions[::-1]),
         rc.quaternion_product(q, q[::-1])),
        (rc.matrix_from_quaternion([quaternions[:3], quaternions[3:]]),
         rc.matrix_from_quaternion(q.reshape(2, 3, 4))),
        (rc.matrix_from_quaternion([quaternions[0], tuple(q[1]), list(q[2])]),   # mixed
         rc.matrix_from_quaternion(q[:3])),
        (rc.quaternion_from_axis_angle(vectors, v[:, 0]),
         rc.quaternion_from_axis_angle(v, v[:, 0])),
        # Named components: scalar_first reorders arrays, never objects (4 of them here).
        (rc.quaternion_conjugate(quaternions[:4], scalar_first=True),
         rc.quaternion_conjugate(q[:4][:, [3, 0, 1, 2]], scalar_first=True))]
    for got, expected in checks:
        assert got.shape == expected.shape and got.tobytes() == expected.tobytes()


# ------------------------------------------------------------ loading in the background

BACKGROUND = """
import sys, time
import numpy as np
from rotation_node import conversions
from rotation_node.conversions import _euler, _runtime, warm_up
lines = []
warm_up.load_in_background(lines.append, after={after})
q = [0.1, 0.2, 0.3, 0.9]
first = conversions.euler_from_quaternion(q, 'xyz')
kernel = _euler._euler_from_quaternion_kernel
print(kernel.dispatcher is None)
deadline = time.monotonic() + 600
while kernel.dispatcher is None and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.2)
print(kernel.dispatcher is not None,
      conversions.euler_from_quaternion(q, 'xyz').tobytes() == first.tobytes(),
      sorted(k.__name__ for k in _runtime.KERNELS if k.dispatcher is not None))
for line in lines:
    print(line)
"""


@pytest.mark.slow
def test_kernels_load_in_the_background_as_they_are_first_used(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    env.pop('ROTATION_NODE_COMPILED', None)
    out = _python(BACKGROUND.format(after=0.0), env).splitlines()
    assert out[0] == 'True'   # the first call ran interpreted
    assert out[1] == "True True ['_euler_from_quaternion_kernel']"
    assert out[2:4] == [warm_up.COMPILING, out[3]]
    assert re.fullmatch(r'1 kernels compiled in [0-9.]+ s and cached', out[3]), out
    out = _python(BACKGROUND.format(after=0.0), env).splitlines()   # from the cache: silent
    assert out == ['True', "True True ['_euler_from_quaternion_kernel']"]


# ------------------------------------------------------------ threads

def test_large_batches_use_threads_only_while_a_cpu_is_idle_unless_chosen(monkeypatch):
    monkeypatch.setattr(_runtime, '_usable_cpus', 2)
    monkeypatch.setattr(_runtime, '_threads', 2)
    monkeypatch.setattr(_runtime, '_threads_chosen', False)
    large = _runtime.THREADED_SAMPLES
    monkeypatch.setattr(os, 'getloadavg', lambda: (11.9, 11.0, 11.5))   # a busy machine
    assert _runtime.batch_threads(large) == 1
    monkeypatch.setattr(os, 'getloadavg', lambda: (1.2, 1.0, 0.9))   # one CPU idle
    assert _runtime.batch_threads(large) == 2
    assert _runtime.batch_threads(large - 1) == 1
    monkeypatch.setattr(os, 'getloadavg', lambda: (11.9, 11.0, 11.5))
    monkeypatch.setattr(_runtime, '_threads_chosen', True)   # set_threads or the variable
    assert _runtime.batch_threads(large) == 2


# ------------------------------------------------------------ tuple forms and warm_up


def _copied_kernels(monkeypatch):
    """Record each kernel that a single sample copied into arrays reaches, with its widths."""
    reached = {}
    copied = _runtime.copied

    def recording(kernel_, widths):
        reached[kernel_] = widths
        copied(kernel_, widths)

    monkeypatch.setattr(_runtime, 'copied', recording)
    return reached


def _listed(sample):
    return sample.tolist() if isinstance(sample, np.ndarray) else sample


def test_warm_up_leaves_every_tuple_form_that_single_samples_reach_in_the_cache(monkeypatch):
    """After warm_up, each due tuple form loads from the disk cache: nothing compiles."""
    _runtime.compile_kernels()
    monkeypatch.setattr(_runtime, '_loading_forced', False)
    monkeypatch.setattr(_runtime, 'TUPLE_COPIES', 1)
    for kernel in KERNELS:   # as in a new process: no tuple form loaded yet
        monkeypatch.setattr(kernel, 'call_tuple', None)
        monkeypatch.setattr(kernel, 'tuple_copies', 0)
    reached = _copied_kernels(monkeypatch)
    with _runtime.KernelCompilation(lambda: None) as compilation:
        for name, call, sample in _CASES:   # one argument a list
            call(_listed(sample))
        q, v = (0.1, 0.2, 0.3, 0.9), (1.0, 2.0, 3.0)
        for name, call, arguments in _message_calls(q, v):   # every argument a tuple
            call(*arguments)
        rk.quaternion_derivative(q, v)
        rk.angular_velocity_from_euler_rates(v, v, 'xyz')
    assert compilation.compiled == 0
    assert len(reached) >= 15, sorted(k.__name__ for k in reached)
    assert [k.__name__ for k in reached if k.call_tuple is None] == []


def test_a_call_never_compiles_a_tuple_form_that_is_not_cached(monkeypatch, tmp_path):
    """Without warm_up's cache, a due tuple form is left alone: the copies go on, no stall."""
    from numba.core import config
    kernel = next(k for k in KERNELS if k.__name__ == '_euler_from_quaternion_kernel')
    _runtime.compile_kernels([kernel])
    monkeypatch.setattr(config, 'CACHE_DIR', str(tmp_path))   # an empty cache
    monkeypatch.setattr(_runtime, '_loading_forced', False)
    monkeypatch.setattr(_runtime, 'TUPLE_COPIES', 2)
    monkeypatch.setattr(kernel, 'call_tuple', None)
    monkeypatch.setattr(kernel, 'tuple_copies', 0)
    q = [0.1, -0.2, 0.3, 0.9]
    expected = rc.euler_from_quaternion(np.array(q), 'ZYX')
    with _runtime.KernelCompilation(lambda: None) as compilation:
        for _ in range(5):
            _same_result(rc.euler_from_quaternion(q, 'ZYX'), expected)
    assert compilation.compiled == 0 and kernel.call_tuple is None
    assert kernel.tuple_copies < 0   # not counted towards it any more: checked once
    with _runtime.KernelCompilation(lambda: None) as compilation, \
            _runtime.compiling_tuple_forms():   # as warm_up asks: compiled at once
        _same_result(rc.euler_from_quaternion(q, 'ZYX'), expected)
    assert compilation.compiled == 1 and kernel.call_tuple is not None
