"""Tests of rotation_node.conversions._runtime: one signature per kernel, sample views, warm-up."""
import importlib
import importlib.util
import inspect
import math
import os
import re
import subprocess
import sys

from numba import njit, typeof, types
from numba.core.errors import TypingError
from numba.core.registry import CPUDispatcher
import numpy as np
import pytest
from rotation_node import conversions as rc
from rotation_node import kinematics as rk
from rotation_node.conversions import _quaternion, _runtime, warm_up
from rotation_node.conversions._runtime import KERNELS, matrix_samples, samples

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
    expected = matrix_samples(a) if width == (3, 3) else samples(a, width)
    assert got.shape == expected.shape
    assert np.array_equal(got, expected)
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


def _checking_unchecked_call(dispatcher, calls):
    """Return a ``call_unchecked`` asserting its contract: arrays of the declared types."""
    declared = dispatcher.kernel_signature.args

    def call(*args):
        assert len(args) == len(declared)
        for argument, expected in zip(args, declared):
            if isinstance(expected, types.Array):
                assert typeof(argument) == expected, (dispatcher.py_func.__qualname__, argument)
        calls.append(dispatcher)
        return dispatcher(*args)

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
    unchecked = kernel.call_unchecked
    try:
        kernel.call_unchecked = typed_first = _runtime.typed_first_call(kernel)
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


def _dispatchers(module):
    return {name: value for name, value in vars(module).items()
            if isinstance(value, CPUDispatcher) and inspect.getmodule(value.py_func) is module}


def test_every_kernel_called_from_python_is_declared():
    """A compiled loop that Python calls (named ..._kernel) has its one declared signature."""
    declared = set(map(id, KERNELS))
    for module_name in _MODULES:
        module = importlib.import_module(module_name)
        for name, dispatcher in _dispatchers(module).items():
            if name.endswith('_kernel') and name not in _COMPILED_ONLY:
                assert id(dispatcher) in declared, f'{module_name}.{name} is not a kernel()'


def test_warm_up_compiles_every_kernel_with_its_signature():
    assert _runtime.compile_kernels() == len(KERNELS)
    for k in KERNELS:
        assert k.signatures == [k.kernel_signature.args], k.py_func.__qualname__


# ------------------------------------------------------------- cold start

def _python(code, env=None):
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=600, env=env)
    assert result.returncode == 0, result.stderr
    return result.stdout


@pytest.mark.slow
def test_importing_conversions_loads_nothing_beyond_numpy_and_numba():
    out = _python('import sys, numpy, numba\n'
                  'before = set(sys.modules)\n'
                  'import rotation_node.conversions\n'
                  'print(sorted(m for m in set(sys.modules) - before\n'
                  '             if m.split(".")[0] not in sys.stdlib_module_names\n'
                  '             and not m.startswith("rotation_node.conversions.")))\n')
    assert out.strip() == "['rotation_node', 'rotation_node.conversions']"


@pytest.mark.slow
def test_the_first_call_does_not_import_scipy_linalg_and_numba_linear_algebra_still_works():
    """The BLAS probe is answered without importing scipy.linalg; np.dot still compiles."""
    out = _python('import importlib.util, sys\n'
                  'import numba, numpy as np\n'
                  'from rotation_node import conversions\n'
                  'conversions.euler_from_quaternion([0.1, 0.2, 0.3, 0.9], "xyz")\n'
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
                  'conversions.quaternion_conjugate([0.0, 0.0, 0.0, 1.0])\n'
                  'print(numba.np.arraymath._HAVE_BLAS == have_blas,\n'
                  '      "scipy.linalg" in sys.modules)\n')
    assert out.split() == ['True', str(importlib.util.find_spec('scipy') is not None)]


@pytest.mark.slow
def test_kernels_are_cached_in_the_user_cache_where_the_package_is_read_only(tmp_path):
    """Where the in-tree cache is unusable (a system install), the user-wide one is used."""
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path))
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
    assert out.startswith(f'rotation_node: {len(KERNELS)} kernels compiled or loaded')
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
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
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
