"""
Tests of rotation_node.bag.reading.topic_names: the one rule that maps input topic names to ROS 2.

The oracle is rclpy's own validation of topic names, fully qualified or
relative (what a publisher would raise ``InvalidTopicNameException`` for).
"""
from hypothesis import given
from hypothesis import strategies as st
import pytest
from rclpy.exceptions import InvalidTopicNameException
from rclpy.expand_topic_name import expand_topic_name
from rclpy.validate_full_topic_name import validate_full_topic_name
from rclpy.validate_topic_name import validate_topic_name
from rotation_node.bag.reading.topic_names import (
    is_valid_topic_name, ros2_topic_name, topic_renames)


def _rclpy_accepts(name):
    """Whether rclpy accepts ``name`` for a publisher of a node in the root namespace."""
    try:
        validate_topic_name(name)
        validate_full_topic_name(expand_topic_name(name, 'node', '/'))
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
    ('groundtruth', 'groundtruth'),   # relative names stay relative
    ('AAA', 'AAA'),
    ('imu/data', 'imu/data'),
    ('~/imu', '/_/imu'),   # ~ and substitutions only mean something to a node
    ('{node}/imu', '/_node_/imu'),
])
def test_examples(name, mapped):
    assert ros2_topic_name(name) == mapped
    assert _rclpy_accepts(mapped)


@pytest.mark.slow
@given(st.text(max_size=40))
def test_every_name_maps_to_a_name_rclpy_accepts_and_valid_names_stay(name):
    mapped = ros2_topic_name(name)
    assert _rclpy_accepts(mapped)
    node_only = '~' in name or '{' in name or '}' in name
    assert is_valid_topic_name(name) == (_rclpy_accepts(name) and name.isascii()
                                         and not node_only)
    if is_valid_topic_name(name):
        assert mapped == name


def _resolved(name):
    return expand_topic_name(name, 'node', '/')


def test_renames_are_distinct_from_every_other_topic():
    names = ['/a-b', '/a_b', '/a.b', '/c', 'c', '/ok/topic', 'rel', 'imu_raw', '/imu-raw']
    renames = topic_renames(names)
    assert renames == {'/a-b': '/a_b_2', '/a.b': '/a_b_3', 'c': '/c_2',
                       '/imu-raw': '/imu_raw_2'}
    final = [renames.get(name, name) for name in names]
    assert len({_resolved(name) for name in final}) == len(final)
    assert all(map(_rclpy_accepts, final))


def test_relative_names_are_kept_as_relative_names():
    """Keep ``groundtruth`` (evo's example bag), ``AAA`` (rosbag2's tests): rclpy accepts them."""
    assert topic_renames(['groundtruth', '/imu', 'AAA', 'a/b']) == {}
