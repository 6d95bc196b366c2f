"""Tests of rotation_node.conversions._validation: bad input raises ValueError naming the fault."""
import numpy as np
import pytest

from rotation_node import conversions as rc

Q = np.array([0.1, 0.2, 0.3, 0.9])
R = rc.matrix_from_quaternion(Q)
V = np.array([0.1, -0.2, 0.3])

# (function, good arguments, index of the array argument under test, its name, per-sample shape)
CASES = [
    (rc.matrix_from_quaternion, (Q,), 0, 'q', (4,)),
    (rc.quaternion_from_matrix, (R,), 0, 'R', (3, 3)),
    (rc.axis_angle_from_quaternion, (Q,), 0, 'q', (4,)),
    (rc.axis_angle_from_matrix, (R,), 0, 'R', (3, 3)),
    (rc.quaternion_from_axis_angle, (V, 0.5), 0, 'axis', (3,)),
    (rc.matrix_from_axis_angle, (V, 0.5), 0, 'axis', (3,)),
    (rc.quaternion_from_rotation_vector, (V,), 0, 'v', (3,)),
    (rc.matrix_from_rotation_vector, (V,), 0, 'v', (3,)),
    (rc.rotation_vector_from_quaternion, (Q,), 0, 'q', (4,)),
    (rc.rotation_vector_from_matrix, (R,), 0, 'R', (3, 3)),
    (rc.quaternion_from_euler, (V, 'xyz'), 0, 'angles', (3,)),
    (rc.matrix_from_euler, (V, 'ZYX'), 0, 'angles', (3,)),
    (rc.euler_from_quaternion, (Q, 'zxz'), 0, 'q', (4,)),
    (rc.euler_from_matrix, (R, 'XYX'), 0, 'R', (3, 3)),
    (rc.euler_singularity_margin, (Q, 'xyz'), 0, 'q', (4,)),
    (rc.quaternion_product, (Q, Q), 1, 'q', (4,)),
    (rc.quaternion_conjugate, (Q,), 0, 'q', (4,)),
    (rc.canonical_quaternion, (Q,), 0, 'q', (4,)),
    (rc.quaternion_distance, (Q, Q), 0, 'p', (4,)),
    (rc.rotate_vector, (Q, V), 1, 'v', (3,)),
]
IDS = [c[0].__name__ for c in CASES]
QUATERNION_CASES = [c for c in CASES if c[4] == (4,)]


def _with(args, index, value):
    args = list(args)
    args[index] = value
    return args


@pytest.mark.parametrize('function, args, index, name, shape', CASES, ids=IDS)
def test_wrong_shape_names_argument_and_shape(function, args, index, name, shape):
    wrong = np.zeros(shape[:-1] + (shape[-1] + 1,))
    expected = {(4,): r'\(\.\.\., 4\)', (3,): r'\(\.\.\., 3\)', (3, 3): r'\(\.\.\., 3, 3\)'}[shape]
    with pytest.raises(ValueError, match=rf'Expected `{name}` to have shape {expected}, got '
                                         + rf'\({wrong.shape[0]},'):
        function(*_with(args, index, wrong))


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize('function, args, index, name, shape', CASES, ids=IDS)
def test_non_finite_names_argument_and_index(function, args, index, name, shape, bad):
    batch = np.stack([np.asarray(args[index], dtype=float)] * 3)
    batch[2].flat[1] = bad
    args = [np.stack([np.asarray(a)] * 3) if isinstance(a, np.ndarray) else a for a in args]
    with pytest.raises(ValueError, match=rf'`{name}` at index \(2,\) has a NaN or Inf component'):
        function(*_with(args, index, batch))


@pytest.mark.parametrize('function, args, index, name, shape', QUATERNION_CASES,
                         ids=[c[0].__name__ for c in QUATERNION_CASES])
def test_zero_quaternion_is_an_error_never_identity(function, args, index, name, shape):
    with pytest.raises(ValueError, match=rf'`{name}` has zero norm'):
        function(*_with(args, index, np.zeros(4)))


@pytest.mark.parametrize('function', [rc.quaternion_from_axis_angle, rc.matrix_from_axis_angle])
def test_zero_axis_is_an_error(function):
    with pytest.raises(ValueError, match='`axis` has zero norm'):
        function([0.0, 0.0, 0.0], 1.0)


@pytest.mark.parametrize('function', [rc.quaternion_from_axis_angle, rc.matrix_from_axis_angle])
def test_non_finite_angle_is_an_error(function):
    with pytest.raises(ValueError, match='`angle` at index \\(1,\\) has a NaN'):
        function([[1.0, 0, 0], [0, 1, 0]], [0.5, np.nan])


@pytest.mark.parametrize('seq, why', [
    ('xxy', 'two consecutive axes are the same'),
    ('XyZ', 'mixed case'),
    ('xy', '2 characters'),
    ('xyzx', '4 characters'),
    ('abc', 'only the letters x, y, z'),
    ('', '0 characters'),
    (3, 'got int'),
    (None, 'got NoneType'),
])
@pytest.mark.parametrize('function, args', [
    (rc.quaternion_from_euler, (V,)), (rc.matrix_from_euler, (V,)),
    (rc.euler_from_quaternion, (Q,)), (rc.euler_from_matrix, (R,)),
    (rc.euler_singularity_margin, (Q,)),
])
def test_bad_sequence_is_a_value_error_with_reason(function, args, seq, why):
    with pytest.raises(ValueError, match=rf'Expected `seq`.*{why}'):
        function(*args, seq)


def test_non_numeric_input():
    with pytest.raises(ValueError, match='Expected `q` to be an array of numbers'):
        rc.matrix_from_quaternion(['a', 'b', 'c', 'd'])


def test_leading_shapes_that_do_not_broadcast():
    with pytest.raises(ValueError, match=r'do not broadcast: \(2,\) and \(3,\)'):
        rc.quaternion_product(np.ones((2, 4)), np.ones((3, 4)))


@pytest.mark.parametrize('options, message', [
    ({'non_orthonormal': 'ignore'}, "'project' or 'raise'"),
    ({'orthonormal_tolerance': -1.0}, 'orthonormal_tolerance'),
    ({'orthonormal_tolerance': np.nan}, 'orthonormal_tolerance'),
])
def test_bad_matrix_options(options, message):
    with pytest.raises(ValueError, match=message):
        rc.quaternion_from_matrix(R, **options)


@pytest.mark.parametrize('function, args, index, name, shape', CASES, ids=IDS)
def test_inputs_are_never_modified(function, args, index, name, shape):
    frozen = []
    for a in args:
        if isinstance(a, np.ndarray):
            a = a.copy()
            a.setflags(write=False)  # writing would raise
        frozen.append(a)
    before = [a.copy() if isinstance(a, np.ndarray) else a for a in frozen]
    function(*frozen)
    for a, b in zip(frozen, before):
        if isinstance(a, np.ndarray):
            assert np.array_equal(a, b)


def test_non_contiguous_and_integer_input(rng):
    q = rng.normal(size=(10, 8))[:, ::2]  # strided view
    assert np.allclose(rc.matrix_from_quaternion(q), rc.matrix_from_quaternion(q.copy()))
    assert np.allclose(rc.matrix_from_quaternion([0, 0, 1, 1]),
                       [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-16)


def test_single_sample_shapes():
    assert rc.euler_from_quaternion(Q, 'xyz').shape == (3,)
    assert rc.matrix_from_quaternion(Q).shape == (3, 3)
    assert rc.quaternion_from_matrix(R).shape == (4,)
    assert np.ndim(rc.euler_singularity_margin(Q, 'xyz')) == 0
    assert np.ndim(rc.quaternion_distance(Q, Q)) == 0
    axis, angle = rc.axis_angle_from_quaternion(Q)
    assert axis.shape == (3,) and np.ndim(angle) == 0


def test_single_samples_equal_their_batch_rows_in_every_form(rng):
    # The single-sample path computes scalar results into shape (1,) and passes
    # a scalar argument as a float; neither may change a bit or a type.
    q = rng.normal(size=(6, 4))
    margins, distances = rc.euler_singularity_margin(q, 'ZXZ'), rc.quaternion_distance(q, q[::-1])
    for s in range(6):
        margin = rc.euler_singularity_margin(q[s], 'ZXZ')
        distance = rc.quaternion_distance(q[s], q[5 - s])
        assert type(margin) is np.float64 and margin == margins[s]
        assert type(distance) is np.float64 and distance == distances[s]
    axis, angle = rng.normal(size=(6, 3)), rng.uniform(-4, 4, 6)
    expected = rc.quaternion_from_axis_angle(axis, angle)
    for s in range(6):
        for form in (float(angle[s]), angle[s], np.array(angle[s]), np.array([angle[s]])[0]):
            assert np.array_equal(rc.quaternion_from_axis_angle(axis[s], form), expected[s])
    with pytest.raises(ValueError, match='angle'):
        rc.quaternion_from_axis_angle(axis[0], np.array(np.nan))
    with pytest.raises(ValueError, match='`v`'):   # a float where a vector belongs
        rc.rotate_vector(q[0], 1.0)


def test_empty_batch():
    assert rc.matrix_from_quaternion(np.zeros((0, 4))).shape == (0, 3, 3)
    assert rc.euler_from_matrix(np.zeros((0, 3, 3)), 'xyz').shape == (0, 3)


@pytest.fixture
def two_threads(monkeypatch):
    from rotation_node.conversions import _runtime
    before = _runtime._threads
    monkeypatch.setattr(_runtime, 'THREADED_SAMPLES', 1 << 16)   # these batches split
    monkeypatch.setattr(_runtime, '_threads_chosen', _runtime._threads_chosen)
    rc.set_threads(2)
    yield
    rc.set_threads(before)


def test_threaded_batches_equal_single_threaded(rng, two_threads):
    q = rng.normal(size=(70000, 4))
    threaded = rc.euler_from_quaternion(q, 'ZYX'), rc.matrix_from_quaternion(q)
    rc.set_threads(1)
    single = rc.euler_from_quaternion(q, 'ZYX'), rc.matrix_from_quaternion(q)
    assert all(np.array_equal(a, b) for a, b in zip(threaded, single))


def test_threaded_batch_reports_the_first_bad_sample(rng, two_threads):
    q = rng.normal(size=(2, 50000, 4))
    q[1, 20000, 2] = np.nan
    q[1, 30000] = 0.0
    with pytest.raises(ValueError, match=r'`q` at index \(1, 20000\) has a NaN'):
        rc.matrix_from_quaternion(q)


def test_set_threads_rejects_zero():
    with pytest.raises(ValueError, match='`n` >= 1'):
        rc.set_threads(0)
