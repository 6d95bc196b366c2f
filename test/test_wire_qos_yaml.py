"""Tests of rotation_node.wire.qos_yaml: rosbag2's QoS YAML without rclpy or PyYAML's emitter."""
from bag_helpers import rosbags_qos_yaml
import pytest
from rclpy.duration import Duration, Infinite
from rclpy.qos import DurabilityPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import (
    Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
from rotation_node.parameters import NodeParameters
from rotation_node.wire.qos import qos_profile, qos_profiles_yaml
from rotation_node.wire.qos_yaml import output_qos_yaml, profiles_yaml
import yaml


def _entry(**changes):
    entry = {'history': 'keep_last', 'depth': 10, 'reliability': 'reliable',
             'durability': 'volatile', 'deadline': {'sec': 0, 'nsec': 0},
             'lifespan': {'sec': 9223372036, 'nsec': 854775807}, 'liveliness': 'automatic',
             'liveliness_lease_duration': {'sec': 2, 'nsec': 5},
             'avoid_ros_namespace_conventions': False}
    entry.update(changes)
    return entry


@pytest.mark.parametrize('entries', [
    [],
    [_entry()],
    [_entry(), _entry(history='keep_all', depth=0, avoid_ros_namespace_conventions=True)],
    [_entry(depth=-1, reliability='best_effort', durability='transient_local')],
    [_entry(reliability='yes')],                       # a word YAML quotes
    [_entry(liveliness='Manual')],                     # not a plain lower-case name
    [_entry(depth='10')],                              # a string YAML quotes
    [_entry(deadline={'nsec': 0, 'sec': 0})],          # another key order
    [{**_entry(), 'extra': 1}],                        # another shape
    [_entry(deadline={'sec': True, 'nsec': 0})],       # a bool where a number goes
])
def test_text_is_pyyamls(entries):
    expected = yaml.safe_dump(entries, sort_keys=False, default_flow_style=False).rstrip('\n')
    assert profiles_yaml(entries) == expected
    assert yaml.safe_load(profiles_yaml(entries)) == entries


@pytest.mark.parametrize('reliability', ['auto', 'reliable', 'best_effort'])
@pytest.mark.parametrize('depth', [1, 1000, 10000])
def test_output_qos_is_the_output_publishers_profile(reliability, depth):
    params = NodeParameters().replaced({'qos.reliability': reliability, 'qos.depth': depth})
    assert output_qos_yaml(params) == qos_profiles_yaml([qos_profile(params)])


def test_rclpy_profiles_of_every_policy_and_duration():
    profiles = [QoSProfile(depth=7, reliability=ReliabilityPolicy.BEST_EFFORT,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL, deadline=Infinite,
                           liveliness=LivelinessPolicy.MANUAL_BY_TOPIC,
                           lifespan=Duration(seconds=3, nanoseconds=4))]
    text = qos_profiles_yaml(profiles)
    assert yaml.safe_load(text) == [{
        'history': 'keep_last', 'depth': 7, 'reliability': 'best_effort',
        'durability': 'transient_local', 'deadline': {'sec': 9223372036, 'nsec': 854775807},
        'lifespan': {'sec': 3, 'nsec': 4}, 'liveliness': 'manual_by_topic',
        'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
        'avoid_ros_namespace_conventions': False}]


def test_rosbags_profiles_as_rosbags_dumps_them():
    from rosbags.rosbag2.metadata import dump_qos_v9
    profiles = [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE,
                    QosDurability.TRANSIENT_LOCAL, QosTime(0, 0), QosTime(1, 2),
                    QosLiveliness.AUTOMATIC, QosTime(0, 0), False)]
    assert rosbags_qos_yaml(profiles) == yaml.safe_dump(
        dump_qos_v9(profiles), sort_keys=False, default_flow_style=False).rstrip('\n')
    assert rosbags_qos_yaml([]) == '[]'
