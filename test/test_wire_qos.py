"""Tests of rotation_node.wire.qos: rosbag2's QoS YAML and the record/play profiles."""
import pytest
from rclpy.duration import Duration, Infinite
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy)
from rosbags.rosbag2.metadata import parse_qos
from rotation_node.errors import BagError
from rotation_node.wire.qos import (
    DEEP_QUEUE_DEPTH, playback_qos, qos_profiles_from_yaml, qos_profiles_yaml,
    recording_qos)

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE, deadline=Infinite,
                      lifespan=Infinite, liveliness=LivelinessPolicy.AUTOMATIC,
                      liveliness_lease_duration=Infinite)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     lifespan=Duration(seconds=2, nanoseconds=5))
SENSOR = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                    reliability=ReliabilityPolicy.BEST_EFFORT)


@pytest.mark.parametrize('profiles', [[], [RELIABLE], [LATCHED, SENSOR]])
def test_yaml_round_trip(profiles):
    assert qos_profiles_from_yaml(qos_profiles_yaml(profiles)) == profiles


def test_yaml_is_rosbag2_v9_and_read_by_rosbags():
    text = qos_profiles_yaml([RELIABLE])
    assert text.splitlines()[:4] == [
        '- history: keep_last', '  depth: 10', '  reliability: reliable', '  durability: volatile']
    assert '  deadline:\n    sec: 9223372036\n    nsec: 854775807' in text
    profile, = parse_qos(text)
    assert (profile.history.name, profile.depth, profile.reliability.name,
            profile.deadline.sec, profile.deadline.nsec) == (
        'KEEP_LAST', 10, 'RELIABLE', 9223372036, 854775807)


def test_reads_pre_jazzy_integer_policies():
    text = ('- history: 1\n  depth: 3\n  reliability: 2\n  durability: 1\n'
            '  deadline: {sec: 0, nsec: 0}\n  lifespan: {sec: 0, nsec: 0}\n  liveliness: 1\n'
            '  liveliness_lease_duration: {sec: 0, nsec: 0}\n'
            '  avoid_ros_namespace_conventions: false\n')
    profile, = qos_profiles_from_yaml(text)
    assert (profile.history, profile.depth, profile.reliability, profile.durability) == (
        HistoryPolicy.KEEP_LAST, 3, ReliabilityPolicy.BEST_EFFORT,
        DurabilityPolicy.TRANSIENT_LOCAL)


@pytest.mark.parametrize('text', ['{a: 1}', '- history: keep_last\n', '- [', '- 3'])
def test_invalid_yaml_names_topic(text):
    with pytest.raises(BagError, match="offered_qos_profiles of topic '/imu'"):
        qos_profiles_from_yaml(text, topic='/imu')


def test_empty_metadata_is_no_profiles():
    assert qos_profiles_from_yaml('') == []


@pytest.mark.parametrize('offered, reliability, durability', [
    ([RELIABLE], ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE),
    ([LATCHED], ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL),
    ([RELIABLE, SENSOR], ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE),
    ([], ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE),
])
def test_recording_qos_matches_every_publisher(offered, reliability, durability):
    qos = recording_qos(offered)
    assert (qos.reliability, qos.durability, qos.depth) == (
        reliability, durability, DEEP_QUEUE_DEPTH)


@pytest.mark.parametrize('offered, lossless, expected', [
    ([SENSOR], False, (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, 10)),
    ([LATCHED], False, (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 10)),
    ([LATCHED, SENSOR], False, (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, 10)),
    ([], False, (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, 10)),
    ([SENSOR], True, (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, DEEP_QUEUE_DEPTH)),
])
def test_playback_qos(offered, lossless, expected):
    qos = playback_qos(offered, lossless=lossless)
    assert (qos.reliability, qos.durability, qos.depth) == expected
