"""
Tests of rotation_node.bag.topic_names: the one rule that maps input topic names to ROS 2.

The oracle is rclpy's own validation of fully qualified topic names (what a
publisher would raise ``InvalidTopicNameException`` for).
"""
from hypothesis import given
from hypothesis import strategies as st
import pytest
from rclpy.exceptions import InvalidTopicNameException
from rclpy.validate_full_topic_name import validate_full_topic_name
from rotation_node.bag.topic_names import is_valid_topic_name, ros2_topic_name, topic_renames


def _rclpy_accepts(name):
    try:
        validate_full_topic_name(name)
    except InvalidTopicNameException:
        return False
    return True


@pytest.mark.parametrize('name, mapped', [
    ('ORB-SLAM', '/ORB_SLAM'),
    ('/imu-raw', '/imu_raw'),
    ('/2d/scan/', '/_2d/scan'),
    ('//a//b', '/a/b'),
    ('/caméra/image', '/cam_ra/image'),
    ('/a b.c~d', '/a_b_c_d'),
    ('', '/_'),
    ('/', '/_'),
    ('/imu', '/imu'),
    ('/tf_static', '/tf_static'),
])
def test_examples(name, mapped):
    assert ros2_topic_name(name) == mapped
    assert _rclpy_accepts(mapped)


@given(st.text(max_size=40))
def test_every_name_maps_to_a_name_rclpy_accepts_and_valid_names_stay(name):
    mapped = ros2_topic_name(name)
    assert _rclpy_accepts(mapped)
    assert is_valid_topic_name(name) == (_rclpy_accepts(name) and name.isascii())
    if is_valid_topic_name(name):
        assert mapped == name


def test_renames_are_distinct_from_every_other_topic():
    names = ['/a-b', '/a_b', '/a.b', '/c', 'c', '/ok/topic']
    renames = topic_renames(names)
    assert renames == {'/a-b': '/a_b_2', '/a.b': '/a_b_3', 'c': '/c_2'}
    final = [renames.get(name, name) for name in names]
    assert len(set(final)) == len(final) and all(map(_rclpy_accepts, final))
