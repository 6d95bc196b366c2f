"""
The orientation-conversion node (console script ``rotation_node``).

Subscribes the relative topic ``input`` (type chosen by the ``input_type``
parameter; ``input_type: tf`` subscribes ``/tf`` and ``/tf_static`` instead)
and publishes each output listed in ``outputs`` on the relative topic of the
same name; the conversion itself is
:class:`rotation_node.pipeline.ConversionPipeline`, the same code that
``rotation_bag convert`` runs on bags. The subscribed topics and the message
types come from :mod:`rotation_node.messages`.

Parameters are declared from the table in :mod:`rotation_node.parameters`. At
start-up the node reads its ``--params-file`` files itself with the loader
``rotation_bag convert`` uses, so both accept and reject the same files: an
unreadable or malformed file, a file without a section for this node, an
unknown parameter (in a file or ``-p``) or an invalid value ends the process
with one line on stderr and exit status 1.

At runtime, ROS 2 applies parameter changes as its services define: a
``set_parameters`` request with several parameters (``ros2 param set``, ``ros2
param load``) checks and applies each one on its own (some may be applied while
others are rejected), while ``set_parameters_atomically`` applies all of them or
none. Every value is checked against the table before it is accepted; the rule
between parameters (``input_type: tf`` needs both ``tf`` frames) is checked
once a whole request is in, whatever the order of its parameters, and a request
that breaks it is set back entirely. An accepted change takes effect on the next
message. Counters and the current conventions are
published on ``/diagnostics`` once a second.

With ``qos.reliability: auto`` each input subscription adapts to the QoS its
publishers offer, a subscription is replaced (new QoS) without losing or
repeating a message, and messages the publishers sent but the node never got
are counted from their publication sequence numbers (:mod:`rotation_node.reception`;
the numbers of a publisher that left are forgotten, so that a publisher restarting
is counted exactly) and reported as ``lost``. Input types with a fixed CDR layout are taken as
serialized messages and decoded by :mod:`rotation_node.bag.cdr`; outputs are
published as the bytes their encoders give, as ``rotation_bag convert`` writes
them. See docs/node.md.

Run it with, for example::

    rotation_node --ros-args -r input:=/imu/data -p outputs:='[euler, angular_velocity]'
"""
from dataclasses import dataclass
import functools
import gc
import sys
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Set, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.duration import Duration
from rclpy.event_handler import (
    PublisherEventCallbacks, QoSSubscriptionEventType, SubscriptionEventCallbacks,
    UnsupportedEventTypeError)
from rclpy.exceptions import (
    InvalidHandle, InvalidParameterTypeException, InvalidParameterValueException,
    NotInitializedException, ParameterNotDeclaredException)
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import (
    DurabilityPolicy, qos_policy_name_from_kind, qos_profile_parameters, QoSPolicyKind,
    QoSProfile, ReliabilityPolicy)
from rclpy.signals import install_signal_handlers, SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rotation_node import messages
from rotation_node.bag.cdr import fixed_layout_codec
from rotation_node.bag.qos import AUTO, input_qos, qos_profile
from rotation_node.bag.stop_signal import signal_name, StopSignal
from rotation_node.conversions.warm_up import load_in_background
from rotation_node.errors import BagError, ParameterError
from rotation_node.parameters import (
    mounting_frames_problem, NODE_NAME, NodeParameters, PARAMETERS, PARAMETERS_BY_NAME,
    parameters_file_sections, parameters_from_yaml, ParameterSpec, ROS_BUILTIN_PARAMETERS,
    unknown_parameter_error)
from rotation_node.pipeline import (
    CONVERSION_ERROR, ConversionPipeline, SKIP_REASONS)
from rotation_node.reception import Identity, message_identity, Reception
from rotation_node.static_mounting import (
    MOUNTING_UNKNOWN, needs_static_mounting, placeholder, resolved, StaticMountingLookup,
    TF_STATIC_TOPIC)

DIAGNOSTICS_PERIOD_S = 1.0
ISSUE_LOG_PERIOD_S = 5.0
# Replacing a subscription: how often the handoff is checked, how long the old one
# may stay silent once the new one delivers, and how long the old one lives at most.
HANDOFF_CHECK_S = 0.05
HANDOFF_QUIET_S = 0.25
HANDOFF_MAX_S = 2.0
# Replacing an output publisher: how long the new one must have matched the old one's
# subscribers (on its side) before it takes over, so that their readers match it too.
# The old one then lives until its subscribers acknowledged what it sent (HANDOFF_MAX_S
# at most): a reliable writer destroyed earlier takes its unacknowledged messages along.
PUBLISHER_SETTLE_S = 0.5
# Messages taken in one callback at most, beyond the one the executor took.
DRAIN_MAX = 100


# ROS arguments (after --ros-args, up to --) that take a value, and those that do not.
_ROS_FLAGS_WITH_VALUE = frozenset((
    '-r', '--remap', '-p', '--param', '--params-file', '-e', '--enclave', '--log-level',
    '--log-file-name', '--log-config-file'))


def ros_arguments(args: Sequence[str]) -> List[Tuple[str, Optional[str]]]:
    """
    Return the ``(flag, value)`` pairs of the ROS arguments in a command line.

    Parameters
    ----------
    args : sequence of str
        The command line (``sys.argv``); ROS arguments are those after each
        ``--ros-args``, up to the next ``--``.

    Returns
    -------
    list of (str, str or None)
        E.g. ``[('--params-file', 'a.yaml'), ('-p', 'qos.depth:=5')]``; flags
        without a value (``--disable-stdout-logs``) with None.

    """
    pairs: List[Tuple[str, Optional[str]]] = []
    in_ros_args, index = False, 0
    while index < len(args):
        token = args[index]
        if token == '--ros-args':
            in_ros_args = True
        elif token == '--':
            in_ros_args = False
        elif in_ros_args:
            if token in _ROS_FLAGS_WITH_VALUE and index + 1 < len(args):
                pairs.append((token, args[index + 1]))
                index += 1
            else:
                pairs.append((token, None))
        index += 1
    return pairs


def _parameters_files(args: Sequence[str]) -> List[str]:
    # A --params-file without a file is rclpy's to report (as its other malformed arguments).
    return [value for flag, value in ros_arguments(args)
            if flag == '--params-file' and value is not None]


def check_parameter_names(args: Sequence[str]) -> None:
    """Raise ParameterError for a ``-p [NODE:]NAME:=VALUE`` naming no parameter of the node."""
    known = {*PARAMETERS_BY_NAME, *ROS_BUILTIN_PARAMETERS}
    for flag, value in ros_arguments(args):
        if flag in ('-p', '--param') and value is not None:
            node, _, name = value.split(':=', 1)[0].rpartition(':')   # [node:]name:=value
            if node not in ('', NODE_NAME):
                continue   # a parameter of another node of the process
            if name not in known:
                raise unknown_parameter_error(name, f' in {flag} {value}')


def parameter_descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    """Return the ROS descriptor of one row of the parameter table."""
    descriptor = ParameterDescriptor(
        name=spec.name, description=spec.description,
        additional_constraints=spec.constraints)
    if spec.bounds is not None and spec.type is float:
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=spec.bounds[0], to_value=spec.bounds[1])]
    elif spec.bounds is not None:
        descriptor.integer_range = [
            IntegerRange(from_value=spec.bounds[0], to_value=spec.bounds[1], step=1)]
    return descriptor


class _TopicInput:
    """
    One topic of the input type: its subscription, QoS, and what it received.

    While the subscription is being replaced (a new QoS), ``retiring`` is the
    old one, still taken from, and ``pending`` holds the new one's messages
    until the new one has delivered a message the old one delivered too.
    """

    def __init__(self, topic: messages.InputTopic, memory: int):
        self.topic = topic
        self.name = topic.name
        self.subscription: Optional[Subscription] = None   # set when the node subscribes
        self.qos: Optional[QoSProfile] = None
        self.generation = 0
        self.retiring: Optional[Subscription] = None
        self.retiring_heard = 0.0     # monotonic time of the old subscription's last message
        self.handoff_started = 0.0
        # (data, info) of the new subscription during a handoff
        self.pending: List[Tuple[Any, Dict[str, Any]]] = []
        self.pending_identities: Set[Identity] = set()
        self.reception = Reception(memory, on_new_publisher=self._publisher_started)
        self.lost_events = 0          # total_count_change of the rmw's message-lost events

    def matched_publishers(self) -> int:
        """Return how many publishers the topic's subscriptions (current, retiring) match."""
        return max((subscription.get_publisher_count()
                    for subscription in (self.subscription, self.retiring)
                    if subscription is not None), default=0)

    def forget_publishers_that_left(self) -> None:
        """Keep the sequence numbers of the publishers still matched only (see Reception)."""
        self.reception.retain(self.matched_publishers())

    def _publisher_started(self) -> None:
        # A publisher joined or restarted: whose message just came is matched (at least one),
        # and one that left is no longer: a later gap must not be credited to it.
        self.reception.retain(max(self.matched_publishers(), 1))

    def subscribed(self) -> Tuple[Subscription, QoSProfile]:
        """Return the subscription messages are taken from and its QoS (set on configuring)."""
        if self.subscription is None or self.qos is None:
            raise RuntimeError(f'input {self.name}: not subscribed')
        return self.subscription, self.qos


@dataclass
class _PublisherReplacement:
    """An output's new publisher (a new QoS), until it takes over from the old one."""

    publisher: Publisher
    created_at: float                      # monotonic
    matched_since: Optional[float] = None  # since when it has matched the old one's subscribers


class RotationNode(Node):
    """
    Convert orientations and angular velocities from ``input`` to the configured outputs.

    Parameters
    ----------
    parameters_files : sequence of str, optional
        The node's ``--params-file`` files: each must have a section for this
        node, setting only its parameters, to valid values.

    Raises
    ------
    ParameterError
        A parameters file is invalid for this node, or an initial parameter value
        (from ``-p`` or a parameters file) is invalid.

    """

    def __init__(self, parameters_files: Sequence[str] = (), **kwargs: Any):
        # The conversions run interpreted until their compiled kernels, loaded in the
        # background as each is first used, take over (a first run compiles them, and
        # says so on one line): the node converts from its first message.
        load_in_background(get_logger(NODE_NAME).info)
        # input subscription -> its message-lost event (None: the rmw has none); first,
        # as destroy_node reads it, also when a parameters file is refused below
        self._message_lost: Dict[Subscription, Any] = {}
        super().__init__(NODE_NAME, **kwargs)
        try:
            for path in parameters_files:   # as rotation_bag convert reads them
                parameters_from_yaml(path, self.get_fully_qualified_name())
        except ParameterError:
            self.destroy_node()
            raise
        self.params = NodeParameters()
        # Set by _configure, which __init__ calls below, before any callback can run.
        self._pipeline: ConversionPipeline
        self._configured = False   # while declaring, parameter changes only set self.params
        # mounting.tf_*: the lookup until /tf_static connects the frames (input dropped
        # meanwhile), its subscription, and the rotation found (for the same frames)
        self._static_mounting: Optional[StaticMountingLookup] = None
        self._tf_static: Optional[Subscription] = None
        self._mounting_found: Optional[Tuple[Tuple[str, str], Tuple[float, ...]]] = None
        self._inputs: List[_TopicInput] = []   # one per topic of the input type
        # CDR bytes -> view; None: rclpy deserialises
        self._decode: Optional[Callable[[bytes], Any]] = None
        self._output_publishers: Dict[str, Publisher] = {}
        self._publish: Dict[str, Callable[[bytes], None]] = {}   # output name -> publish(bytes)
        # output name -> encode(header, numbers) -> bytes
        self._encoders: Dict[str, Callable[[Any, Sequence[float]], bytes]] = {}
        self._replacing: Dict[str, _PublisherReplacement] = {}   # by output name
        # publishers no longer published on, until acknowledged: (publisher, retired at)
        self._retiring_publishers: List[Tuple[Publisher, float]] = []
        self._handoff_timer: Optional[Timer] = None
        self._next_issue_log: Dict[str, float] = {}   # reason -> time of its next warning
        self._reported = (0, 0, 0)   # dropped, skipped and lost totals at the last diagnostics
        # While a set_parameters request is applied: {ROS name: value} of the node's own
        # parameters it set so far (their combination is checked once all are in).
        self._request: Optional[Dict[str, Any]] = None
        self._serve_set_parameters()
        # Registered before declaring, so the initial values pass the same checks.
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        defaults = self.params.to_ros()
        # rclpy checks each declared parameter on its own, in this order: input_type comes
        # last, so that the parameters of its input type (tf.*) are set when it is checked.
        in_order = sorted(PARAMETERS, key=lambda spec: spec.name == 'input_type')
        try:
            self.declare_parameters('', [
                (spec.name, defaults[spec.name], parameter_descriptor(spec))
                for spec in in_order])
        except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None
        problem = mounting_frames_problem(self.params)
        if problem:   # both frames or neither, once all parameters are set
            self.destroy_node()
            raise ParameterError(problem)
        self._configure(None, self.params)
        self._configured = True
        # No QoS event handlers on the diagnostics publisher: each handler is one more
        # entity that rclpy's executor re-examines at every wake-up, i.e. every message.
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, '/diagnostics', 10,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._on_diagnostics_timer)

    # Parameters --------------------------------------------------------------------

    def _serve_set_parameters(self) -> None:
        """
        Answer the ``set_parameters`` service here instead of in rclpy's parameter service.

        rclpy applies a request's parameters one at a time, each checked on its own:
        ``ros2 param load`` of a file setting ``input_type: tf`` and the frames it
        needs in one request would have ``input_type`` refused for the order alone.
        :meth:`_on_set_parameters` applies them as rclpy does, checks their
        combination once all are in, and takes the request back if it is invalid.
        """
        name = f'{self.get_name()}/set_parameters'
        resolved = self.resolve_service_name(name)
        for service in list(self.services):
            if service.service_name == resolved:
                self.destroy_service(service)
        self.create_service(SetParameters, name, self._on_set_parameters,
                            qos_profile=qos_profile_parameters)

    def _on_set_parameters(self, request: SetParameters.Request,
                           response: SetParameters.Response) -> SetParameters.Response:
        """
        Apply a ``set_parameters`` request: each parameter, then their combination.

        Each parameter is checked and set on its own, as rclpy's service does (one
        may fail while others are set); the node's own parameters are then checked
        together (``input_type: tf`` needs both frames, wherever they stand in the
        request). An invalid combination sets every parameter of the request back:
        each result says why, and the node is left as it was.
        """
        parameters = [Parameter.from_parameter_msg(message) for message in request.parameters]
        before = {p.name: self.get_parameter(p.name) for p in parameters
                  if self.has_parameter(p.name)}
        results = []
        self._request = {}
        try:
            for parameter in parameters:
                try:
                    results.append(self.set_parameters_atomically([parameter]))
                except ParameterNotDeclaredException as exc:
                    results.append(SetParametersResult(successful=False, reason=str(exc)))
            changes = self._request
        finally:
            self._request = None
        try:
            params = self._combined(changes)
        except ParameterError as exc:
            applied = {p.name: before[p.name] for p, result in zip(parameters, results)
                       if result.successful}
            self._request = {}   # set back: the node's state does not change
            try:
                if applied:
                    self.set_parameters_atomically(list(applied.values()))
            finally:
                self._request = None
            reason = f'not applied: {exc}'
            results = [SetParametersResult(successful=False, reason=reason)
                       if result.successful else result for result in results]
        else:
            self._change_to(params)
        response.results = results
        return response

    def _check_parameters(self, parameters: List[Parameter]) -> SetParametersResult:
        """Validate a parameter change (all of it, or none of it, is applied)."""
        try:
            if self._request is None:
                self._combined(_own(parameters))
            else:   # part of a set_parameters request: the combination comes at its end
                NodeParameters.check_each(_own(parameters))
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _combined(self, changes: Dict[str, Any]) -> NodeParameters:
        """
        Return the node's parameters with ``changes``, their combination checked.

        Raises ParameterError for a value, or for a combination (``mounting.tf_*``: both
        frames or neither; not while declaring, when the frames are set one by one).
        """
        params = self.params.replaced(changes)
        problem = mounting_frames_problem(params) if self._configured else ''
        if problem:
            raise ParameterError(problem)
        return params

    def _apply_parameters(self, parameters: List[Parameter]) -> None:
        """Apply a validated change; it takes effect on the next message."""
        if self._request is not None:
            self._request.update(_own(parameters))
            return
        self._change_to(self.params.replaced(_own(parameters)))

    def _change_to(self, params: NodeParameters) -> None:
        previous, self.params = self.params, params
        # Not while declaring (__init__ configures once), nor for others' parameters.
        if self._configured and self.params != previous:
            self._configure(previous, self.params)

    def _configure(self, previous: Optional[NodeParameters], params: NodeParameters) -> None:
        """
        Create or update the pipeline, subscriptions and publishers for ``params``.

        ``previous`` are the parameters configured before; None the first time.
        """
        stats = None if previous is None else self._pipeline.stats
        self._pipeline = ConversionPipeline(self._mounted(params), on_issue=self._log_issue,
                                            stats=stats)
        input_type = messages.INPUTS[params.input_type]
        if previous is None or params.input_type != previous.input_type:
            for state in self._inputs:
                self._finish_handoff(state)
                self._destroy_input_subscription(state, state.subscribed()[0])
            codec = fixed_layout_codec(input_type.type_name)
            self._decode = None if codec is None else codec.decode
            self._inputs = [_TopicInput(topic, _memory(params)) for topic in input_type.topics]
        # A stateful input stream (input_type.stream) starts empty with the new pipeline:
        # its latched topics are subscribed again, so that their publishers deliver what
        # they keep once more, and accepted again.
        replay = previous is not None and input_type.stream is not None
        for state in self._inputs:
            qos = self._input_qos(state, self._offered(state))
            if replay and state.topic.transient_local:
                self._finish_handoff(state)
                state.reception.forget()
                self._subscribe(state, qos)
            elif qos != state.qos:
                self._subscribe(state, qos)
        output_qos = qos_profile(params)
        for name in list(self._output_publishers):
            replacement = self._replacing.pop(name, None)
            if replacement is not None:   # superseded before it took over
                self.destroy_publisher(replacement.publisher)
            if name not in params.outputs:
                self._retire_publisher(self._output_publishers.pop(name))
                del self._publish[name]
            elif self._output_publishers[name].qos_profile != output_qos:
                # The old publisher publishes until the new one has matched its subscribers.
                self._replacing[name] = _PublisherReplacement(
                    self._create_output_publisher(name, output_qos), time.monotonic())
                self._start_handoff_timer()
        for name in params.outputs:
            if name not in self._output_publishers:
                publisher = self._create_output_publisher(name, output_qos)
                self._output_publishers[name] = publisher
                self._publish[name] = publisher.publish
                self._encoders[name] = messages.OUTPUTS[name].message.encoder()
        self.get_logger().info(
            f'converting {params.input_type} messages on {self._input_topic_names()} '
            f'to {", ".join(params.outputs)} (euler.sequence {params.euler_sequence}, '
            f'{"degrees" if params.euler_degrees else "radians"})')

    def _mounted(self, params: NodeParameters) -> NodeParameters:
        """
        Return the parameters for the pipeline: the mounting from /tf_static if asked.

        Until /tf_static connects the two frames: the frames cleared, the lookup
        kept in ``_static_mounting`` (input is dropped, ``mounting_unknown``) and
        /tf_static subscribed (transient local: what static broadcasters latched).
        """
        self._static_mounting = None
        if not needs_static_mounting(params):
            if self._tf_static is not None:
                self.destroy_subscription(self._tf_static)
                self._tf_static = None
            return params
        frames = (params.mounting_tf_sensor_frame, params.mounting_tf_body_frame)
        if self._mounting_found is not None and self._mounting_found[0] == frames:
            return resolved(params, self._mounting_found[1])
        self._static_mounting = StaticMountingLookup(params)
        if self._tf_static is None:
            from rotation_node.bag.message_types import message_class
            self._tf_static = self.create_subscription(
                message_class('tf2_msgs/msg/TFMessage'), TF_STATIC_TOPIC, self._on_tf_static,
                QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL))
        return placeholder(params)

    def _on_tf_static(self, msg: Any) -> None:
        """Add static transforms until the mounting is found; then convert with it."""
        lookup = self._static_mounting
        if lookup is None:
            return
        found = lookup.add(msg)
        if found is None:
            return
        self._static_mounting = None
        self._mounting_found = ((lookup.sensor, lookup.body), found.mounting_body_rotation)
        self._pipeline = ConversionPipeline(found, on_issue=self._log_issue,
                                            stats=self._pipeline.stats)
        self.get_logger().info(
            f'mounting from /tf_static: {lookup.frames} = '
            f'{[round(c, 9) for c in found.mounting_body_rotation]} (x, y, z, w)')

    def _create_output_publisher(self, name: str, qos: QoSProfile) -> Publisher:
        # Without QoS event handlers (as the diagnostics publisher): a subscriber
        # that cannot match reports it itself.
        return self.create_publisher(
            messages.OUTPUTS[name].message_class, name, qos,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

    def _check_publisher_handoffs(self, now: float) -> None:
        """Let new output publishers take over once matched; destroy acknowledged old ones."""
        for name, replacement in list(self._replacing.items()):
            new, old = replacement.publisher, self._output_publishers[name]
            if new.get_subscription_count() < old.get_subscription_count():
                # (a subscriber the new QoS cannot match: HANDOFF_MAX_S)
                replacement.matched_since = None
            elif replacement.matched_since is None:
                # matched on the publisher's side; let readers match too
                replacement.matched_since = now
            settled = (replacement.matched_since is not None
                       and now - replacement.matched_since >= PUBLISHER_SETTLE_S)
            if settled or now - replacement.created_at > HANDOFF_MAX_S:
                del self._replacing[name]
                self._output_publishers[name], self._publish[name] = new, new.publish
                self._retire_publisher(old)
        for retiring in list(self._retiring_publishers):
            publisher, retired_at = retiring
            if (publisher.wait_for_all_acked(Duration())   # a check, without waiting
                    or now - retired_at > HANDOFF_MAX_S):
                self._retiring_publishers.remove(retiring)
                self.destroy_publisher(publisher)

    def _retire_publisher(self, publisher: Publisher) -> None:
        """Stop publishing on ``publisher``; destroy it once what it sent is acknowledged."""
        self._retiring_publishers.append((publisher, time.monotonic()))
        self._start_handoff_timer()

    # Input subscriptions and QoS ------------------------------------------------------

    def _input_qos(self, state: _TopicInput, offered: List[QoSProfile],
                   incompatible_policy: Optional[QoSPolicyKind] = None) -> QoSProfile:
        """
        Return the QoS to subscribe ``state``'s topic with, given the ``offered`` profiles.

        With ``qos.reliability: auto``, adapted to them (kept as they are while no
        publisher is known); ``incompatible_policy`` (a publisher the current
        subscription cannot match offers less of it) lowers that policy even before
        the graph shows the publisher.
        """
        qos = input_qos(self.params, offered, transient_local=state.topic.transient_local)
        if self.params.qos_reliability == AUTO and state.qos is not None:
            if not offered:
                qos.reliability, qos.durability = state.qos.reliability, state.qos.durability
            if incompatible_policy == QoSPolicyKind.RELIABILITY:
                qos.reliability = ReliabilityPolicy.BEST_EFFORT
            elif incompatible_policy == QoSPolicyKind.DURABILITY:
                qos.durability = DurabilityPolicy.VOLATILE
        return qos

    def _offered(self, state: _TopicInput) -> List[QoSProfile]:
        """Return the QoS profiles the publishers of ``state``'s topic offer (auto mode only)."""
        if self.params.qos_reliability != AUTO:
            return []
        name = (state.subscription.topic_name if state.subscription is not None
                else self.resolve_topic_name(state.name))
        return [info.qos_profile for info in self.get_publishers_info_by_topic(name)]

    def _adapt(self, state: _TopicInput,
               incompatible_policy: Optional[QoSPolicyKind] = None) -> None:
        """Subscribe ``state``'s topic again if the publishers need another QoS; log it once."""
        offered = self._offered(state)
        qos = self._input_qos(state, offered, incompatible_policy)
        subscription, current_qos = state.subscribed()
        if qos == current_qos:
            return
        self.get_logger().info(
            f'input {subscription.topic_name}: publishers offer {_policies(offered)}; '
            f'subscribing {_policies([qos])} (was {_policies([current_qos])})')
        self._subscribe(state, qos)

    def _subscribe(self, state: _TopicInput, qos: QoSProfile) -> None:
        """
        Subscribe ``state``'s topic with ``qos``, replacing its subscription without loss.

        The old subscription stays until the new one has delivered a message the old
        one delivered too (or the old one has gone quiet): nothing between them is
        missed, nothing is converted twice.
        """
        if state.retiring is not None:
            self._finish_handoff(state)
        state.generation += 1
        callbacks = SubscriptionEventCallbacks(
            incompatible_qos=functools.partial(self._on_incompatible_qos, state))
        subscription = self.create_subscription(
            self._pipeline.input_type, state.name,
            functools.partial(self._on_input, state, state.generation), qos,
            event_callbacks=callbacks, raw=self._decode is not None)
        # The message-lost status is read once a second, not waited on: an event handler
        # is one more entity the executor examines at every wake-up.
        try:
            with subscription.handle:
                self._message_lost[subscription] = _rclpy.EventHandle(
                    subscription.handle, QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST)
        except UnsupportedEventTypeError:   # a middleware without it: sequence gaps only
            self._message_lost[subscription] = None
        if state.subscription is not None:
            state.retiring = state.subscription
            state.handoff_started = state.retiring_heard = time.monotonic()
            self._start_handoff_timer()
        state.subscription, state.qos = subscription, qos
        state.reception.resize(_memory(self.params))

    def _finish_handoff(self, state: _TopicInput) -> None:
        """Destroy the retiring subscription; accept what the new one delivered meanwhile."""
        if state.retiring is None:
            return
        self._destroy_input_subscription(state, state.retiring)
        state.retiring = None
        pending, state.pending = state.pending, []
        state.pending_identities.clear()
        for data, info in pending:
            self._accept(state, data, info)

    def _start_handoff_timer(self) -> None:
        if self._handoff_timer is None:
            self._handoff_timer = self.create_timer(HANDOFF_CHECK_S, self._check_handoffs)

    def _check_handoffs(self) -> None:
        """Finish the subscription and publisher replacements that are due; then the timer."""
        now = time.monotonic()
        for state in self._inputs:
            if state.retiring is not None and (
                    (state.pending and now - state.retiring_heard > HANDOFF_QUIET_S)
                    or now - state.handoff_started > HANDOFF_MAX_S):
                self._finish_handoff(state)
        self._check_publisher_handoffs(now)
        timer = self._handoff_timer   # this callback's timer
        if (timer is not None and not self._replacing and not self._retiring_publishers
                and all(state.retiring is None for state in self._inputs)):
            self.destroy_timer(timer)
            self._handoff_timer = None

    def _on_incompatible_qos(self, state: _TopicInput, event: Any) -> None:
        if self.params.qos_reliability == AUTO:
            self._adapt(state, event.last_policy_kind)
        else:
            self._log_issue('incompatible_qos', (
                f'input {state.subscribed()[0].topic_name}: a publisher offers a '
                f'{qos_policy_name_from_kind(event.last_policy_kind)} incompatible with '
                f'qos.reliability {self.params.qos_reliability}; its messages are not received '
                f'(qos.reliability auto adapts to it)'))

    def _count_message_lost(self, state: _TopicInput,
                            subscription: Optional[Subscription]) -> None:
        """Add the message-lost events of ``subscription`` (or none) since the last call."""
        event = None if subscription is None else self._message_lost.get(subscription)
        if event is not None:
            with event:
                state.lost_events += event.take_event().total_count_change

    def destroy_node(self) -> None:
        """
        Destroy the node: the message-lost event handles first, then what rclpy destroys.

        Each handle belongs to an input subscription, which ``Node.destroy_node``
        destroys; a handle left alive would be finalised later (at interpreter
        exit, in any order) against a subscription and middleware already gone.
        """
        for event in self._message_lost.values():
            if event is not None:
                event.destroy_when_not_in_use()
        self._message_lost.clear()
        super().destroy_node()

    def _destroy_input_subscription(self, state: _TopicInput,
                                    subscription: Subscription) -> None:
        self._count_message_lost(state, subscription)
        event = self._message_lost.pop(subscription)
        if event is not None:
            event.destroy_when_not_in_use()
        self.destroy_subscription(subscription)

    def _input_topic_names(self) -> str:
        return ', '.join(state.subscribed()[0].topic_name for state in self._inputs)

    # Messages ----------------------------------------------------------------------

    def _on_input(self, state: _TopicInput, generation: int, data: Any,
                  info: Dict[str, Any]) -> None:
        """Take one message of ``state``'s topic from its subscription of ``generation``."""
        if state.retiring is not None:
            if generation != state.generation:   # the old subscription
                state.retiring_heard = time.monotonic()
                self._accept(state, data, info)
                if message_identity(info) in state.pending_identities:
                    self._finish_handoff(state)
                return
            if not state.reception.seen(info):
                state.pending.append((data, info))
                state.pending_identities.add(message_identity(info))
                return
            self._finish_handoff(state)   # the new subscription has caught up
        self._accept(state, data, info)
        if state.retiring is None:
            self._drain(state)

    def _accept(self, state: _TopicInput, data: Any, info: Dict[str, Any]) -> None:
        """Convert a message not seen before and publish its outputs."""
        if not state.reception.accept(info):
            return
        if self._static_mounting is not None:   # the mounting is not known yet
            self._pipeline.stats.received += 1
            self._pipeline.stats.dropped[MOUNTING_UNKNOWN] += 1
            self._log_issue(MOUNTING_UNKNOWN, 'message dropped: no mounting yet, waiting for '
                            f'/tf_static to give {self._static_mounting.frames}: '
                            f'{self._static_mounting.problem}')
            return
        if self._decode is not None:
            try:
                data = self._decode(data)
            except BagError as exc:
                self._pipeline.stats.received += 1
                self._pipeline.stats.dropped[CONVERSION_ERROR] += 1
                self._log_issue(CONVERSION_ERROR, f'message dropped: {exc}')
                return
        publish, encoders = self._publish, self._encoders
        for name, header, numbers in self._pipeline.process_values(data, state.name):
            publish[name](encoders[name](header, numbers))

    def _drain(self, state: _TopicInput) -> None:
        """
        Take and convert what else is queued on ``state``'s subscription, up to a bound.

        One executor wake-up then serves every message that arrived meanwhile; rclpy's
        executor costs more per wake-up than the conversion of a message.
        """
        subscription = state.subscribed()[0]
        take = subscription.handle.take_message
        message_type, raw = subscription.msg_type, subscription.raw
        for _ in range(DRAIN_MAX):
            with subscription.handle:
                taken = take(message_type, raw)
            if taken is None:
                return
            self._accept(state, *taken)

    def _log_issue(self, reason: str, detail: str) -> None:
        # Throttled here, once per ISSUE_LOG_PERIOD_S for each reason (so a flood of one
        # problem cannot hide the first report of another), and not with rclpy's
        # throttle_duration_sec: that looks up the caller on every call, milliseconds
        # each, which a stream of bad messages at 1 kHz cannot afford.
        now = time.monotonic()
        if now < self._next_issue_log.get(reason, now):
            return
        self._next_issue_log[reason] = now + ISSUE_LOG_PERIOD_S
        self.get_logger().warning(f'{detail} [{reason}]')

    # Diagnostics -------------------------------------------------------------------

    def _on_diagnostics_timer(self) -> None:
        if self.params.qos_reliability == AUTO:
            for state in self._inputs:
                self._adapt(state)
        self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        for state in self._inputs:
            for subscription in (state.subscription, state.retiring):
                self._count_message_lost(state, subscription)
            state.forget_publishers_that_left()
        stats = self._pipeline.stats
        gaps = sum(state.reception.lost for state in self._inputs)
        events = sum(state.lost_events for state in self._inputs)
        lost = sum(max(state.reception.lost, state.lost_events) for state in self._inputs)
        totals = (sum(stats.dropped.values()), sum(stats.skipped.values()), lost)
        new_dropped, new_skipped, new_lost = (
            now - before for now, before in zip(totals, self._reported))
        self._reported = totals
        if new_dropped or new_skipped or new_lost:
            level = DiagnosticStatus.WARN
            message = (f'{new_lost} messages lost, {new_dropped} dropped, {new_skipped} partly '
                       f'converted in the last {DIAGNOSTICS_PERIOD_S:g} s')
        else:
            level, message = DiagnosticStatus.OK, 'converting'
        subscribed = [state.subscribed() for state in self._inputs]
        values = {
            'input_topic': self._input_topic_names(),
            'input_qos': '; '.join(f'{subscription.topic_name}: {_policies([qos])}'
                                   for subscription, qos in subscribed),
            'received': stats.received,
            'published': stats.published,
            'lost': lost,
            'lost.sequence_gaps': gaps,
            'lost.message_lost_events': events,
            'duplicates': sum(state.reception.duplicates for state in self._inputs),
            'dropped': totals[0],
            **{f'dropped.{reason}': stats.dropped[reason]
               for reason in (*self._pipeline.drop_reasons, MOUNTING_UNKNOWN)},
            'skipped': totals[1],
            **{f'skipped.{reason}': stats.skipped[reason] for reason in SKIP_REASONS},
            'normalised': stats.normalised,
            'near_singular': stats.near_singular,
            **self.params.to_ros(),
        }
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [DiagnosticStatus(
            level=level, name=f'{self.get_fully_qualified_name()}: orientation conversion',
            message=message, hardware_id='',
            values=[KeyValue(key=key, value=_text(value)) for key, value in values.items()])]
        self._diagnostics_publisher.publish(array)


def _memory(params: NodeParameters) -> int:
    """Messages a topic's Reception remembers: two histories of the deepest subscription."""
    return 2 * params.qos_depth + 100


def _policies(profiles: Sequence[QoSProfile]) -> str:
    """``'reliable, volatile'`` of the profiles, ``'nothing'`` for none."""
    return ' / '.join(sorted({f'{p.reliability.short_key}, {p.durability.short_key}'
                              for p in profiles})) or 'nothing'


def _own(parameters: List[Parameter]) -> Dict[str, Any]:
    """Return ``{name: value}`` of the node's own parameters (not use_sim_time etc.)."""
    return {p.name: p.value for p in parameters if p.name in PARAMETERS_BY_NAME}


def _text(value: Any) -> str:
    if isinstance(value, list):
        return ','.join(map(_text, value))
    if isinstance(value, bool):
        return str(value).lower()
    return str(value)


def _non_ros_arguments(arguments: Sequence[str]) -> List[str]:
    """Return the arguments outside ``--ros-args ... [--]`` (without parsing the ROS ones)."""
    outside, in_ros_args = [], False
    for argument in arguments:
        if argument == '--ros-args':
            in_ros_args = True
        elif argument == '--' and in_ros_args:
            in_ros_args = False
        elif not in_ros_args:
            outside.append(argument)
    return outside


def usage() -> str:
    """Return the text ``rotation_node --help`` prints: how to run it, its parameters."""
    return ('usage: rotation_node [--ros-args [-r input:=TOPIC] [-p NAME:=VALUE]... '
            '[--params-file FILE]]\n\n'
            'Convert the orientations on the topic "input" and publish the outputs listed in '
            'the parameter "outputs".\nParameters: '
            + ', '.join(spec.name for spec in PARAMETERS) + '.\n')


def main(args: Optional[List[str]] = None, stop_signal: Optional[StopSignal] = None) -> int:
    """
    Run the node until Ctrl-C or SIGTERM (``--help``: print its usage).

    Parameters
    ----------
    args : list of str, optional
        The command line (``sys.argv`` by default).
    stop_signal : StopSignal, optional
        The console script's, in force since the program started loading; a
        new one otherwise.

    Returns
    -------
    int
        0 after Ctrl-C, SIGTERM or shutdown, at any moment (during start-up with
        one line on stderr saying so); 1 if a parameters file or an initial
        parameter value is invalid (one line on stderr says which).

    Notes
    -----
    Start-up runs with SIGINT and SIGTERM only setting a flag (:class:`StopSignal`),
    and rclpy initialised without its signal handlers: its handler shuts the
    context down from another thread, which in the middle of the node's
    construction surfaces as whatever rclpy call comes next
    (``NotInitializedException``...). rclpy's handlers are installed once the node
    exists (chained to the flag), so that a signal ends ``spin``.

    """
    if stop_signal is None:
        with StopSignal() as stop:
            return _run(args, stop)
    return _run(args, stop_signal)


def _run(args: Optional[List[str]], stop: StopSignal) -> int:
    """Run :func:`main` with ``stop`` in force."""
    argv = sys.argv if args is None else list(args)
    if {'-h', '--help'} & set(_non_ros_arguments(argv[1:])):
        print(usage(), end='')
        return 0
    files = _parameters_files(argv)
    try:   # before rclpy reads the files, whose own errors are many lines long
        for path in files:
            parameters_file_sections(path)
        check_parameter_names(argv)
    except ParameterError as exc:
        print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
        return 1
    node = None
    spinning = False
    try:
        if not stop.is_set():
            try:
                rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
            except _rclpy.RCLError as exc:   # e.g. a malformed --ros-args remapping
                print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
                return 1
        if not stop.is_set():
            node = RotationNode(parameters_files=files)
            # From here a signal also shuts the context down (rclpy's handler, chained to
            # the flag's), which ends spin; one that came before is seen below.
            install_signal_handlers(SignalHandlerOptions.ALL)
        if not stop.is_set() and node is not None:
            # The ~1e5 objects of rclpy, numpy and numba live as long as the process: keep
            # them out of the cyclic collector, whose full passes over them stall a
            # callback for ~50 ms (50 messages at 1 kHz).
            gc.freeze()
            spinning = True
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (_rclpy.RCLError, NotInitializedException, InvalidHandle):
        if rclpy.ok():
            raise
        # A stop request shut the context down under an rclpy call.
    except ParameterError as exc:
        print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    interrupt = stop.interrupt()
    if interrupt is not None and not spinning:
        print(f'{NODE_NAME}: interrupted while starting ({signal_name(interrupt)})',
              file=sys.stderr)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
