"""Tests of rotation_node.node.qos_adaptation: the QoS of the node's input subscriptions."""
import pytest
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, QoSPolicyKind, QoSProfile, ReliabilityPolicy)
from rotation_node.node.qos_adaptation import input_qos, policies_text
from rotation_node.parameters import NodeParameters

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     lifespan=Duration(seconds=2, nanoseconds=5))
SENSOR = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                    reliability=ReliabilityPolicy.BEST_EFFORT)
AUTO = NodeParameters().replaced({'qos.reliability': 'auto', 'qos.depth': 3})


@pytest.mark.parametrize('reliability, offered, expected', [
    ('auto', [], (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)),
    ('auto', [LATCHED], (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)),
    ('auto', [LATCHED, SENSOR], (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE)),
    ('best_effort', [SENSOR], (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)),
])
def test_latched_input_keeps_all_and_adapts_only_with_auto(reliability, offered, expected):
    params = NodeParameters().replaced({'qos.reliability': reliability, 'qos.depth': 3})
    qos = input_qos(params, offered, transient_local=True)
    assert (qos.history, qos.reliability, qos.durability) == (HistoryPolicy.KEEP_ALL, *expected)


@pytest.mark.parametrize('reliability, offered, expected', [
    ('auto', [SENSOR], ReliabilityPolicy.BEST_EFFORT),
    ('auto', [], ReliabilityPolicy.RELIABLE),
    ('best_effort', [RELIABLE], ReliabilityPolicy.BEST_EFFORT),
])
def test_volatile_input_keeps_last_depth(reliability, offered, expected):
    params = NodeParameters().replaced({'qos.reliability': reliability, 'qos.depth': 3})
    qos = input_qos(params, offered)
    assert (qos.history, qos.depth, qos.reliability, qos.durability) == (
        HistoryPolicy.KEEP_LAST, 3, expected, DurabilityPolicy.VOLATILE)


def test_without_publishers_an_adapted_subscription_keeps_its_policies():
    current = QoSProfile(depth=3, reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE)
    qos = input_qos(AUTO, [], current)
    assert (qos.reliability, qos.durability) == (
        ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE)
    first = input_qos(AUTO, [], None)   # the first subscription: reliable
    assert first.reliability == ReliabilityPolicy.RELIABLE


@pytest.mark.parametrize('policy, expected', [
    (QoSPolicyKind.RELIABILITY, (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.TRANSIENT_LOCAL)),
    (QoSPolicyKind.DURABILITY, (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)),
    (QoSPolicyKind.DEADLINE, (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)),
])
def test_an_incompatible_publisher_lowers_its_policy_before_the_graph_shows_it(policy, expected):
    qos = input_qos(AUTO, [], LATCHED, transient_local=True, incompatible_policy=policy)
    assert (qos.reliability, qos.durability) == expected


def test_an_explicit_reliability_is_not_adapted():
    params = AUTO.replaced({'qos.reliability': 'reliable'})
    qos = input_qos(params, [SENSOR], RELIABLE, incompatible_policy=QoSPolicyKind.RELIABILITY)
    assert qos.reliability == ReliabilityPolicy.RELIABLE


def test_policies_text_names_each_distinct_pair_once():
    assert policies_text([]) == 'nothing'
    assert policies_text([RELIABLE, RELIABLE]) == 'reliable, volatile'
    assert policies_text([SENSOR, LATCHED]) == 'best_effort, volatile / reliable, transient_local'
