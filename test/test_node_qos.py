"""
Process tests of the node's input QoS and loss accounting: real processes over DDS.

A ``rotation_node`` process on default parameters meets publishers of the
test process: best effort (as sensor drivers publish), reliable, one after
the other; a burst of several kHz; a ``qos.depth`` change in the middle of a
1 kHz stream. What the node received is read from its outputs and from its
/diagnostics counters (``received``, ``lost``, ``duplicates``).
"""
import itertools
import re
import signal
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rcl_interfaces.msg import Log
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from ros_harness import RosProcess, script, TestNode
from rotation_node.registry import OUTPUTS
from sensor_msgs.msg import Imu
from std_msgs.msg import Header

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

START_TIMEOUT_S = 60.0
# Bounds of the waits: far above what a loaded machine takes (the node publishes
# /diagnostics once a second), so that they only end a test where something is broken.
DIAGNOSTICS_TIMEOUT_S = 30.0
OUTPUTS_TIMEOUT_S = 60.0
SERVICE_TIMEOUT_S = 30.0
# Messages sent before the counted ones until the node converts one (lead_in), 20 Hz.
LEAD_IN = 400
STAMP_NS = 1_700_000_000_000_000_000
RELIABLE = QoSProfile(depth=1000)
NAMESPACES = itertools.count()   # one namespace per test: no topic shared across tests


@pytest.fixture(scope='module')
def ros():
    with TestNode('rotation_node_qos_test') as test_node:
        test_node.diagnostics = test_node.collect(DiagnosticArray, '/diagnostics', qos=100)
        test_node.log = test_node.collect(Log, '/rosout', qos=1000)
        yield test_node


class Node:
    """A ``rotation_node`` process on default parameters in its own namespace, and its outputs."""

    def __init__(self, ros, namespace, args=()):
        self.ros = ros
        self.namespace = namespace
        self.fq_name = f'/{namespace}/rotation_node'
        self.process = RosProcess([script('rotation_node'), '--ros-args',
                                   '-r', f'__ns:=/{namespace}', *args])
        self.input_topic = f'/{namespace}/input'
        self.publishers = []
        self.euler = []
        self._stamps, self._stamp_set = [], set()   # of self.euler, kept up to date by stamps()
        # What the middleware reports lost between the node's outputs and this test (a
        # retransmission no longer possible, on a machine too loaded to keep up).
        self.euler_lost = 0
        self.subscription = ros.node.create_subscription(
            OUTPUTS['euler'].message_class, f'/{namespace}/euler', self.euler.append, 10_000,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_euler_lost))
        self.parameters = AsyncParameterClient(ros.node, self.fq_name)
        if not self.parameters.wait_for_services(timeout_sec=START_TIMEOUT_S):
            self.process.stop()
            pytest.fail(f'rotation_node did not start:\n{self.process.output}')

    def _on_euler_lost(self, info):
        self.euler_lost = info.total_count

    def statuses(self):
        """Every /diagnostics status of this node received so far."""
        return [status for array in self.ros.diagnostics for status in array.status
                if status.name.startswith(self.fq_name + ':')]

    def diagnostics(self, condition=lambda values: True, timeout=DIAGNOSTICS_TIMEOUT_S):
        """Return the values (and 'level') of the next /diagnostics status where ``condition``."""
        seen = len(self.statuses())
        found = []

        def arrived():
            for status in self.statuses()[seen:]:
                values = {kv.key: kv.value for kv in status.values}
                if condition(values):
                    found.append(dict(values, level=status.level))
            return bool(found)
        assert self.ros.spin_until(arrived, timeout), (
            'no matching /diagnostics; the last: '
            f'{[{kv.key: kv.value for kv in s.values} for s in self.statuses()[-1:]]}')
        return found[0]

    def warned_lost(self):
        """Whether a /diagnostics status of this node warned of lost messages."""
        return any(status.level == DiagnosticStatus.WARN and 'lost' in status.message
                   and not status.message.startswith('0 messages lost')
                   for status in self.statuses())

    def stamps(self):
        """Stamps (ns) of the euler outputs received so far."""
        for out in self.euler[len(self._stamps):]:   # only those received since the last call
            self._stamps.append(out.header.stamp.sec * 10**9 + out.header.stamp.nanosec)
            self._stamp_set.add(self._stamps[-1])
        return self._stamps

    def stamp_set(self):
        """Return the set of :meth:`stamps`."""
        self.stamps()
        return self._stamp_set

    def logged(self, text):
        return [log.msg for log in self.ros.log
                if log.name.startswith(self.namespace + '.') and text in log.msg]

    def set_parameter(self, name, value):
        future = self.parameters.set_parameters([Parameter(name, value=value)])
        assert self.ros.spin_until(future.done, SERVICE_TIMEOUT_S), 'parameter service timed out'
        assert future.result().results[0].successful

    def publisher(self, qos):
        """Return a new Imu publisher on the node's input (destroyed when the node stops)."""
        publisher = self.ros.node.create_publisher(Imu, self.input_topic, qos)
        self.publishers.append(publisher)
        return publisher

    def stop(self):
        for publisher in self.publishers:
            self.ros.node.destroy_publisher(publisher)
        self.ros.node.destroy_subscription(self.subscription)
        return self.process.stop()


def _namespace(request):
    name = re.sub(r'[\W_]+', '_', request.node.name.removeprefix('test_'))[:30].strip('_')
    return f'{name}_{next(NAMESPACES)}'


@pytest.fixture
def node(ros, request):
    started = Node(ros, _namespace(request))
    yield started
    assert started.stop() == 0, started.process.output


@pytest.fixture
def shallow_node(ros, request):
    """Start a node whose input history holds one message: a burst it cannot take is lost."""
    started = Node(ros, _namespace(request), ['-p', 'qos.depth:=1'])
    yield started
    assert started.stop() == 0, started.process.output


def imu(k):
    """Return the k-th Imu message of a stream: identity orientation, stamped k ms apart."""
    msg = Imu()
    msg.header = Header(frame_id='imu')
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(STAMP_NS + k * 1_000_000, 10**9)
    msg.orientation.w = 1.0
    return msg


def publish(ros, publisher, first, count, rate):
    """Publish messages ``first`` to ``first + count - 1`` at ``rate`` Hz, spinning between."""
    start = time.monotonic()
    for k in range(count):
        while time.monotonic() < start + k / rate:
            ros.executor.spin_once(timeout_sec=max(0.0, start + k / rate - time.monotonic()))
        publisher.publish(imu(first + k))


def stamp(k):
    """Stamp (ns) of the k-th message of a stream (:func:`imu`)."""
    return STAMP_NS + k * 1_000_000


def matched(ros, publisher):
    assert ros.spin_until(lambda: publisher.get_subscription_count() > 0, 30.0), 'no match'
    ros.spin_for(0.5)   # the node's reader has matched the new writer too (most often)


def lead_in(node, publisher, first):
    """
    Publish messages ``first - LEAD_IN`` on at 20 Hz until the node has converted one.

    The writer side's match (:func:`matched`) does not say that the node's reader has
    matched the writer too: on a loaded machine that can take longer, and what a best
    effort writer sends meanwhile is lost unseen (the node counts a publisher's gaps
    from the first message it receives). After this, what the writer sends is counted.
    """
    lead = [stamp(first - LEAD_IN + k) for k in range(LEAD_IN)]
    for k, wanted in enumerate(lead):
        publisher.publish(imu(first - LEAD_IN + k))
        if node.ros.spin_until(lambda: not node.stamp_set().isdisjoint(lead), 0.05):
            return
    assert node.ros.spin_until(lambda: not node.stamp_set().isdisjoint(lead), 10.0), (
        'the node converted none of the lead-in', node.process.alive())


def first_converted(node, first, count):
    """
    Return the first of messages ``first`` to ``first + count - 1`` that the node converted.

    For a best effort stream without :func:`lead_in`: what was sent before the node's
    reader matched the writer is lost unseen, not counted. Waits for the last message's
    output first (it stays in the node's input history until taken); outputs lost on
    their way to this test would show in ``node.euler_lost``.
    """
    assert node.ros.spin_until(lambda: stamp(first + count - 1) in node.stamp_set(),
                               OUTPUTS_TIMEOUT_S), ('last message not converted',
                                                    node.euler_lost)
    stamps = node.stamp_set()
    return min(k for k in range(first, first + count) if stamp(k) in stamps)


def expect_outputs(node, first, count, timeout=OUTPUTS_TIMEOUT_S):
    """
    Check that messages ``first`` to ``first + count - 1`` were converted once, in order.

    Each one arrives, unless the middleware reported it lost on its way from the node to
    this test (counted by the subscription's message-lost events).
    """
    wanted = {stamp(first + k) for k in range(count)}

    def arrived():
        # len(stamp_set) bounds len(wanted & stamp_set): the intersection, a pass over
        # ``count`` stamps, is only taken once enough outputs are in
        stamps = node.stamp_set()
        return (len(stamps) + node.euler_lost >= count
                and len(wanted & stamps) + node.euler_lost >= count)
    assert node.ros.spin_until(arrived, timeout), (
        len(wanted & node.stamp_set()), node.euler_lost)
    stamps = node.stamps()
    assert len(stamps) == len(set(stamps)) and stamps == sorted(stamps)
    assert len(wanted & set(stamps)) + node.euler_lost == count


# QoS adaptation -----------------------------------------------------------------------------

@pytest.mark.parametrize('kind, qos, adaptations', [
    ('best_effort', qos_profile_sensor_data, 1),   # as sensor drivers publish
    ('reliable', RELIABLE, 0),                     # reliable from the start: nothing to adapt
])
def test_a_publisher_of_either_kind_is_received_on_default_parameters(
        ros, node, kind, qos, adaptations):
    publisher = node.publisher(qos)
    matched(ros, publisher)
    lead_in(node, publisher, 0)
    publish(ros, publisher, 0, 100, 200.0)
    expect_outputs(node, 0, 100)
    values = node.diagnostics()
    assert values['input_qos'] == f'{node.input_topic}: {kind}, volatile'
    assert (values['lost'], values['duplicates']) == ('0', '0')
    # said once (/rosout arrives in its own time)
    ros.spin_until(lambda: len(node.logged('subscribing')) >= adaptations, DIAGNOSTICS_TIMEOUT_S)
    assert len(node.logged('subscribing')) == adaptations


def test_publishers_of_either_kind_in_turn(ros, node):
    """Reliable, then best effort, then reliable again: each stream arrives, each change logged."""
    kinds = [('reliable', RELIABLE), ('best_effort', qos_profile_sensor_data),
             ('reliable', RELIABLE)]
    for turn, (kind, qos) in enumerate(kinds):
        publisher = node.publisher(qos)
        matched(ros, publisher)
        # The node re-checks the publishers once a second: give it time to adapt.
        assert ros.spin_until(lambda: node.diagnostics()['input_qos'].endswith(
            f': {kind}, volatile'), DIAGNOSTICS_TIMEOUT_S)
        lead_in(node, publisher, 1000 * turn)
        publish(ros, publisher, 1000 * turn, 100, 200.0)
        expect_outputs(node, 1000 * turn, 100)
        ros.node.destroy_publisher(publisher)
        ros.spin_for(0.5)
    changes = ('subscribing best_effort, volatile',
               'subscribing reliable, volatile (was best_effort')
    ros.spin_until(lambda: all(node.logged(change) for change in changes),
                   DIAGNOSTICS_TIMEOUT_S)   # /rosout arrives in its own time
    assert [len(node.logged(change)) for change in changes] == [1, 1]


def test_an_explicit_reliability_is_kept(ros, node):
    node.set_parameter('qos.reliability', 'reliable')
    publisher = node.publisher(qos_profile_sensor_data)
    ros.spin_for(2.5)
    assert node.diagnostics()['input_qos'] == f'{node.input_topic}: reliable, volatile'
    assert publisher.get_subscription_count() == 0
    assert ros.spin_until(lambda: node.logged('incompatible'), DIAGNOSTICS_TIMEOUT_S)


# Loss ----------------------------------------------------------------------------------------

def test_a_burst_is_received_or_its_loss_reported(ros, node):
    """15000 messages at up to 10 kHz, reliable, depth 1000: received + lost = sent."""
    publisher = node.publisher(RELIABLE)
    matched(ros, publisher)
    publish(ros, publisher, 0, 10, 100.0)    # the node has seen the stream start
    expect_outputs(node, 0, 10)
    count = 15_000
    messages = [imu(10 + k) for k in range(count)]
    start = time.monotonic()
    for k, msg in enumerate(messages):
        if k % 100 == 0:   # at most 10 kHz
            time.sleep(max(0.0, start + k / 10_000 - time.monotonic()))
        publisher.publish(msg)
    rate = count / (time.monotonic() - start)
    publish(ros, publisher, 10 + count, 10, 100.0)   # a loss at the end shows as a gap too
    total = count + 20
    values = node.diagnostics(lambda v: int(v['received']) + int(v['lost']) >= total,
                              OUTPUTS_TIMEOUT_S)
    assert int(values['received']) + int(values['lost']) == total, (rate, values)
    assert int(values['lost.sequence_gaps']) == int(values['lost'])
    assert values['published'] == values['received'] and values['duplicates'] == '0'
    if values['lost'] != '0':
        assert node.warned_lost()


def test_loss_is_counted_exactly_when_the_publisher_restarts(ros, shallow_node):
    """
    A sends 1..100 and leaves; B sends 1..50, 51..150 in a burst the node cannot take, 151..200.

    The burst comes while the node is stopped (SIGSTOP) and its history holds one message:
    most of it is lost, including B's 100, so B's next number above 100 would be credited
    to A (whose last was 100) if A's numbers were still followed. received + lost = 300,
    less what each sent before the node's reader had matched it (lost unseen: a sequence
    is counted from the first message received; none on an idle machine).
    """
    node = shallow_node
    best_effort = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
    first = node.publisher(best_effort)
    matched(ros, first)
    publish(ros, first, 0, 100, 1000.0)
    unseen = first_converted(node, 0, 100)
    node.diagnostics(lambda v: int(v['received']) + int(v['lost']) >= 100 - unseen)
    node.publishers.remove(first)
    ros.node.destroy_publisher(first)
    assert ros.spin_until(lambda: ros.node.count_publishers(node.input_topic) == 0,
                          DIAGNOSTICS_TIMEOUT_S)
    node.diagnostics()   # the node's once-a-second look at the matched publishers
    second = node.publisher(best_effort)
    matched(ros, second)
    publish(ros, second, 100, 50, 1000.0)
    unseen += first_converted(node, 100, 50) - 100   # B followed from its first 50
    node.diagnostics(lambda v: int(v['received']) + int(v['lost']) >= 150 - unseen)
    node.process.proc.send_signal(signal.SIGSTOP)
    try:
        for k in range(150, 250):
            second.publish(imu(k))
        ros.spin_for(0.3)
    finally:
        node.process.proc.send_signal(signal.SIGCONT)
    publish(ros, second, 250, 50, 1000.0)
    values = node.diagnostics(lambda v: int(v['received']) + int(v['lost']) >= 300 - unseen)
    assert int(values['received']) + int(values['lost']) == 300 - unseen, (unseen, values)
    assert int(values['lost']) > 0 and values['lost.sequence_gaps'] == values['lost'], values
    assert values['duplicates'] == '0'


def test_a_depth_change_during_a_stream_loses_nothing(ros, node):
    """qos.depth changed twice during 3 s of a 1 kHz stream: every message converted once."""
    publisher = node.publisher(RELIABLE)
    matched(ros, publisher)
    changes = {1000: 100, 2000: 2000}
    futures = []
    for first in (0, 1000, 2000):
        if first in changes:
            futures.append(node.parameters.set_parameters(
                [Parameter('qos.depth', value=changes[first])]))
        publish(ros, publisher, first, 1000, 1000.0)
    assert ros.spin_until(lambda: all(f.done() for f in futures), SERVICE_TIMEOUT_S)
    assert all(f.result().results[0].successful for f in futures)
    values = node.diagnostics(lambda v: int(v['received']) + int(v['lost']) >= 3000,
                              OUTPUTS_TIMEOUT_S)
    assert values['qos.depth'] == '2000'
    assert int(values['received']) + int(values['lost']) == 3000, [
        (k, v) for k, v in values.items() if k.startswith(('received', 'lost', 'dup'))]
    if values['lost'] == '0':
        expect_outputs(node, 0, 3000)
    else:   # counted, reported, and only what was counted is missing
        assert node.warned_lost()
        # each output received has been published by now: wait until they are all here
        converted = 3000 - int(values['lost'])
        assert ros.spin_until(lambda: len(node.stamp_set()) + node.euler_lost >= converted,
                              OUTPUTS_TIMEOUT_S)
        assert len(node.stamp_set()) == converted - node.euler_lost
    # The replaced publishers are gone once their messages were acknowledged.
    assert ros.spin_until(lambda: ros.node.count_publishers(f'/{node.namespace}/euler') == 1,
                          DIAGNOSTICS_TIMEOUT_S)
