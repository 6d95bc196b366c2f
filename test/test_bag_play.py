"""Tests of rotation_bag play (rotation_node.bag.play) into live subscribers."""
import time

from bag_helpers import imu_messages, stamp_ns
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_harness import RosProcess, script, TestNode
from rotation_node.bag.reading.mcap_reader import BagReader
from rotation_node.bag.records import TopicMetadata
from rotation_node.bag.writing.writer import BagWriter
from rotation_node.wire.qos import qos_profiles_yaml
from sensor_msgs.msg import Imu
from std_msgs.msg import String

pytestmark = pytest.mark.timeout(120)
KEEP_ALL = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL)


def _imu_bag(path, messages, topic='/imu', offered_qos=()):
    with BagWriter(path) as writer:
        writer.add_topic(
            TopicMetadata(topic, 'sensor_msgs/msg/Imu', qos_profiles_yaml(offered_qos)))
        for msg in messages:
            writer.write(topic, msg, stamp_ns(msg))


def _play(path, *args):
    return RosProcess([script('rotation_bag'), 'play', path, *args])


def _raw_collector(client, topic):
    """Subscribe without deserialising: the list of received CDR bytes."""
    received = []
    client.node.create_subscription(Imu, topic, received.append, KEEP_ALL, raw=True)
    return received


@pytest.mark.slow
def test_rate_zero_delivers_every_message_byte_exact(tmp_path, rng):
    count = 3000
    path = tmp_path / 'burst.mcap'
    _imu_bag(path, imu_messages(rng, count))
    with TestNode('subscriber') as client:
        received = _raw_collector(client, '/imu')
        with _play(path, '--rate', '0') as player:
            assert client.spin_until(lambda: len(received) >= count, timeout=60)
            assert client.spin_until(lambda: not player.alive(), timeout=30)
            assert player.stop() == 0, player.output
    with BagReader(path) as reader:
        assert received == [r.data for r in reader.messages()]
    assert f'published {count} messages' in player.output


@pytest.mark.slow
def test_rate_scales_recorded_timing_with_recorded_qos(tmp_path, rng):
    """Gaps between received messages = recorded gaps / rate (first ones may precede discovery)."""
    period_ns, rate = 50_000_000, 2.0
    path = tmp_path / 'timed.mcap'
    messages = imu_messages(rng, 40, period_ns=period_ns)
    _imu_bag(path, messages, offered_qos=[QoSProfile(
        depth=3, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL)])
    index = {stamp_ns(m): i for i, m in enumerate(messages)}
    with TestNode('subscriber') as client:
        arrivals = []
        client.node.create_subscription(
            Imu, '/imu', lambda msg: arrivals.append((time.monotonic(), index[stamp_ns(msg)])),
            KEEP_ALL)
        with _play(path, '--rate', str(rate), '--wait-for-subscribers', '--delay', '1') as player:
            assert client.spin_until(lambda: client.node.count_publishers('/imu') == 1, 30)
            offered, = [info.qos_profile for info in
                        client.node.get_publishers_info_by_topic('/imu')]
            assert client.spin_until(lambda: not player.alive(), timeout=60)
            client.spin_for(0.3)
            assert player.stop() == 0
    assert (offered.reliability, offered.durability) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)
    assert len(arrivals) >= 20
    (t_first, i_first), (t_last, i_last) = arrivals[0], arrivals[-1]
    expected = (i_last - i_first) * period_ns * 1e-9 / rate
    assert t_last - t_first == pytest.approx(expected, abs=0.25)
    assert np.all(np.diff([i for _, i in arrivals]) == 1)   # in order, none skipped


@pytest.mark.slow
def test_topics_filter(tmp_path, rng):
    path = tmp_path / 'two.mcap'
    with BagWriter(path) as writer:
        for i, msg in enumerate(imu_messages(rng, 10)):
            writer.write('/imu', msg, stamp_ns(msg))
            writer.write('/text', String(data=str(i)), stamp_ns(msg))
    with TestNode('subscriber') as client:
        texts = client.collect(String, '/text', KEEP_ALL)
        imus = client.collect(Imu, '/imu', KEEP_ALL)
        with _play(path, '--rate', '0', '--topics', '/text') as player:
            assert client.spin_until(lambda: not player.alive(), timeout=60)
            client.spin_for(0.3)
            assert player.stop() == 0, player.output
            assert client.node.count_publishers('/imu') == 0
    assert [m.data for m in texts] == [str(i) for i in range(10)]
    assert imus == []


@pytest.mark.slow
def test_loop_repeats_until_interrupted(tmp_path, rng):
    path = tmp_path / 'short.mcap'
    _imu_bag(path, imu_messages(rng, 5))
    with TestNode('subscriber') as client:
        received = client.collect(Imu, '/imu', KEEP_ALL)
        with _play(path, '--rate', '0', '--loop') as player:
            assert client.spin_until(lambda: len(received) >= 15, timeout=60)
            assert player.alive()
            assert player.stop() == 0, player.output
    assert [stamp_ns(m) for m in received[:15]] == [stamp_ns(m) for m in received[:5]] * 3


@pytest.mark.slow
def test_wait_for_subscribers_at_recorded_rate_loses_nothing(tmp_path, rng):
    """The player starts first; it waits for the late subscriber, then plays every message."""
    count = 50
    path = tmp_path / 'late.mcap'
    _imu_bag(path, imu_messages(rng, count, period_ns=5_000_000))
    with _play(path, '--wait-for-subscribers', '--delay', '0.5') as player:
        time.sleep(2.0)
        assert player.alive()   # still waiting: nobody subscribed
        with TestNode('late_subscriber') as client:
            received = _raw_collector(client, '/imu')
            assert client.spin_until(lambda: len(received) >= count, timeout=60)
            assert client.spin_until(lambda: not player.alive(), timeout=30)
        assert player.stop() == 0, player.output
    with BagReader(path) as reader:
        assert received == [r.data for r in reader.messages()]


@pytest.mark.slow
def test_negative_delay_is_rejected_before_anything_is_published(tmp_path, rng):
    path = tmp_path / 'some.mcap'
    _imu_bag(path, imu_messages(rng, 3))
    with _play(path, '--delay', '-1') as player:
        player.proc.wait(timeout=60)   # exits by itself
        assert player.stop() == 1
    assert 'delay must be a number of seconds in [0, 9.223e+09], got -1.0' in player.output
