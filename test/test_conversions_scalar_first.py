"""Tests of rotation_node.conversions._scalar_first: (w, x, y, z) quaternions on the public API."""
import inspect

import numpy as np
import pytest
from rotation_node import conversions as rc
import transforms3d

# A valid call of each adapted function, quaternions in the library's (x, y, z, w) order.
ROTATIONS = np.array([[0.1, -0.2, 0.3, 0.9], [0.0, 0.0, 1.0, 0.0], [-0.5, 0.5, -0.5, 0.5]])
CALLS = {
    'axis_angle_from_quaternion': ((ROTATIONS,), {}),
    'quaternion_from_axis_angle': (([[1.0, 2.0, 3.0]], [0.7]), {}),
    'quaternion_from_rotation_vector': (([[0.1, 0.2, -0.3]],), {}),
    'rotation_vector_from_quaternion': ((ROTATIONS,), {}),
    'euler_from_quaternion': ((ROTATIONS, 'ZYX'), {'degrees': True}),
    'euler_singularity_margin': ((ROTATIONS,), {'seq': 'xyz'}),
    'quaternion_from_euler': (([[10.0, 20.0, 30.0]], 'xyz'), {'degrees': True}),
    'matrix_from_quaternion': ((ROTATIONS,), {}),
    'quaternion_from_matrix': ((rc.matrix_from_quaternion(ROTATIONS),), {}),
    'canonical_quaternion': ((-3.0 * ROTATIONS,), {}),
    'quaternion_conjugate': ((ROTATIONS,), {}),
    'quaternion_distance': ((ROTATIONS, ROTATIONS[::-1]), {}),
    'quaternion_product': ((ROTATIONS,), {'q': ROTATIONS[::-1]}),
    'rotate_vector': ((ROTATIONS, [1.0, 2.0, 3.0]), {}),
}
QUATERNION_PARAMETERS = {'q', 'p'}


def first(q):
    return np.asarray(q)[..., [3, 0, 1, 2]]


def test_every_function_with_quaternions_has_the_keyword():
    for name in rc.__all__:
        function = getattr(rc, name)
        if not inspect.isfunction(function) or name in ('parse_sequence', 'set_threads'):
            continue
        takes = QUATERNION_PARAMETERS & set(inspect.signature(function).parameters)
        returns = name.startswith(('quaternion_from', 'canonical_quaternion',
                                   'quaternion_conjugate', 'quaternion_product'))
        assert ('scalar_first' in inspect.signature(function).parameters) == bool(
            takes or returns), name
        assert (name in CALLS) == bool(takes or returns), name


@pytest.mark.parametrize('name', sorted(CALLS))
def test_scalar_first_is_the_same_numbers_reordered(name):
    function = getattr(rc, name)
    args, kwargs = CALLS[name]
    parameters = list(inspect.signature(function).parameters)
    reordered_args = [first(a) if parameters[i] in QUATERNION_PARAMETERS else a
                      for i, a in enumerate(args)]
    reordered_kwargs = {k: first(v) if k in QUATERNION_PARAMETERS else v
                        for k, v in kwargs.items()}
    expected = function(*args, **kwargs)
    result = function(*reordered_args, scalar_first=True, **reordered_kwargs)
    returns = name.startswith(('quaternion_from', 'canonical', 'quaternion_conjugate',
                               'quaternion_product'))
    if returns:
        expected = first(expected)
    for ours, theirs in zip(result if isinstance(result, tuple) else (result,),
                            expected if isinstance(expected, tuple) else (expected,)):
        np.testing.assert_array_equal(ours, theirs)


def test_against_transforms3d_which_puts_the_scalar_first(rng):
    angles = rng.uniform(-np.pi, np.pi, (50, 3))
    ours = rc.quaternion_from_euler(angles, 'xyz', scalar_first=True)
    theirs = np.array([transforms3d.euler.euler2quat(*a, 'sxyz') for a in angles])
    theirs *= np.sign(theirs[:, :1])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-15)
    p, q = ours[:25], ours[25:]
    np.testing.assert_allclose(rc.quaternion_product(p, q, scalar_first=True),
                               [transforms3d.quaternions.qmult(a, b) for a, b in zip(p, q)],
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(rc.euler_from_quaternion(ours, 'xyz', scalar_first=True),
                               [transforms3d.euler.quat2euler(w, 'sxyz') for w in ours],
                               rtol=0, atol=1e-13)


def test_bad_input_is_still_named():
    with pytest.raises(ValueError, match='`q`'):
        rc.matrix_from_quaternion([1.0, 0.0, 0.0], scalar_first=True)
    assert 'scalar_first=True' in rc.quaternion_product.__doc__
