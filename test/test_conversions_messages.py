"""How objects with attributes x, y, z(, w) are read (conversions._messages)."""
import types

from geometry_msgs.msg import Point, Quaternion, Vector3
import numpy as np
import pytest
from rotation_node.conversions import _messages
from rotation_node.conversions._messages import message_sample, message_values, refusal


class _Scaled:
    """Slots behind properties that do not just return them: the properties must be read."""

    __slots__ = ('_x', '_y', '_z', '_w')

    def __init__(self, x, y, z, w):
        self._x, self._y, self._z, self._w = x, y, z, w

    x = property(lambda self: 2.0 * self._x)
    y = property(lambda self: self._y)   # a lambda's code is the getter's: still read by x
    z = property(lambda self: self._w)   # another slot
    w = property(lambda self: self._z)


def test_rosidl_classes_are_read_from_their_slots_with_the_values_of_their_fields():
    q, v, p = Quaternion(x=0.1, y=0.2, z=0.3, w=0.9), Vector3(x=1.0, y=2.0), Point(z=3.0)
    assert message_sample(q, Quaternion) == (q.x, q.y, q.z, q.w) == (0.1, 0.2, 0.3, 0.9)
    assert message_sample(v, Vector3) == (1.0, 2.0, 0.0)
    assert message_sample(p, Point) == (0.0, 0.0, 3.0)
    assert _messages.message_readers[Quaternion] is _messages._slot_quaternion
    assert _messages.message_readers[Vector3] is _messages._slot_vector


def test_properties_that_are_not_a_slots_getter_are_read_as_properties():
    assert message_sample(_Scaled(1.0, 2.0, 3.0, 4.0), _Scaled) == (2.0, 2.0, 4.0, 3.0)
    assert _messages.message_readers[_Scaled] is _messages._quaternion


def test_instance_attributes_are_read_object_by_object():
    three, four = types.SimpleNamespace(x=1, y=2, z=3), types.SimpleNamespace(x=1, y=2, z=3, w=4)
    assert message_sample(three, types.SimpleNamespace) == (1, 2, 3)
    assert message_sample(four, types.SimpleNamespace) == (1, 2, 3, 4)
    assert message_sample(types.SimpleNamespace(x=1, y=2), types.SimpleNamespace) is None


@pytest.mark.parametrize('x', [
    [0.1, 0.2, 0.3, 0.9], (1.0, 2.0, 3.0), np.zeros(4), np.float64(1.0), 1.0, 'xyzw', None,
    object(), Quaternion])
def test_sequences_arrays_numbers_and_other_objects_are_no_samples(x):
    assert message_sample(x, type(x)) is None


def test_lists_of_objects_become_lists_of_tuples_of_the_right_width():
    q = Quaternion(w=1.0)
    assert message_values([[q], (q, [0.0, 0.0, 0.0, 1.0])], (4,)) == (
        [[(0.0, 0.0, 0.0, 1.0)], [(0.0, 0.0, 0.0, 1.0), [0.0, 0.0, 0.0, 1.0]]], True)
    assert message_values([q], (3,)) == ([q], False)      # a quaternion is no 3-vector
    assert message_values([Vector3()], (4,))[1] is False  # a 3-vector is no quaternion
    assert message_values(q, (3, 3)) == (q, False)        # matrices never come as objects


def test_refusal_names_the_first_object_without_its_attributes_and_where_it_is():
    q, v = Quaternion(), Vector3()
    assert refusal(v, (4,)) == 'it has no attribute w (a quaternion is x, y, z, w)'
    assert refusal([q, [q, v]], (4,)) == (
        'item [1][1], a Vector3, has no attribute w (a quaternion is x, y, z, w)')
    assert refusal((v, q), (3,)) == (
        'item [1], a Quaternion, has an attribute w: a quaternion where a 3-vector (x, y, z) '
        'is needed')
    assert refusal(types.SimpleNamespace(y=1.0), (3,)) == (
        'it has no attribute x, z (x, y, z)')
    for fine in ([q, q], v, 'text', None, [1.0, 2.0, 3.0, 4.0]):   # nothing to say about these
        assert refusal(fine, (4,) if fine is not v else (3,)) == ''
