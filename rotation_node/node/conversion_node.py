"""
The orientation-conversion node: parameters in, the pipeline, outputs out.

Subscribes the relative topic ``input`` (type chosen by the ``input_type``
parameter; ``input_type: tf`` subscribes ``/tf`` and ``/tf_static`` instead)
and publishes each output listed in ``outputs`` on the relative topic of the
same name; the conversion itself is
:class:`rotation_node.pipeline.ConversionPipeline`, the same code that
``rotation_bag convert`` runs on bags. The subscribed topics and the message
types come from :mod:`rotation_node.registry`. The program around it (command
line, start-up, signals) is :mod:`rotation_node.node.program`.

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
message. Counters and the current conventions are published on ``/diagnostics``
once a second (:mod:`.diagnostics`).

With ``qos.reliability: auto`` each input subscription adapts to the QoS its
publishers offer (:mod:`.qos_adaptation`), a subscription is replaced (new QoS)
without losing or repeating a message (:mod:`.handoff`), and messages the
publishers sent but the node never got are counted from their publication
sequence numbers (:mod:`.reception`; the numbers of a publisher that left are
forgotten, so that a publisher restarting is counted exactly) and reported as
``lost``. Input types with a fixed CDR layout are taken as serialized messages
and decoded by :mod:`rotation_node.wire.cdr`; outputs are published as the bytes
their encoders give, as ``rotation_bag convert`` writes them. See docs/node.md.
"""
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
from rcl_interfaces.srv import SetParameters
from rclpy.exceptions import (
    InvalidParameterTypeException, InvalidParameterValueException,
    ParameterNotDeclaredException)
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_service import ParameterService
from rclpy.qos import (
    DurabilityPolicy, qos_policy_name_from_kind, qos_profile_parameters, QoSPolicyKind, QoSProfile,
    ReliabilityPolicy)
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rotation_node import registry
from rotation_node.conversions.warm_up import load_in_background
from rotation_node.errors import BagError, ParameterError
from rotation_node.node.diagnostics import (
    ConversionDiagnostics, DIAGNOSTICS_PERIOD_S, input_topic_names)
from rotation_node.node.handoff import InputTopic, OutputPublishers
from rotation_node.node.qos_adaptation import AUTO, input_qos, policies_text
from rotation_node.parameters import (
    mounting_frames_problem, NODE_NAME, NodeParameters, PARAMETERS, PARAMETERS_BY_NAME,
    parameters_from_yaml, ParameterSpec)
from rotation_node.pipeline import CONVERSION_ERROR, ConversionPipeline
from rotation_node.static_mounting import (
    MOUNTING_UNKNOWN, needs_static_mounting, placeholder, resolved, StaticMountingLookup,
    TF_STATIC_TOPIC)
from rotation_node.wire.cdr import fixed_layout_codec
from rotation_node.wire.qos import qos_profile

ISSUE_LOG_PERIOD_S = 5.0
# How often a subscription or publisher replacement is checked while one is under way.
HANDOFF_CHECK_S = 0.05
# Messages taken in one callback at most, beyond the one the executor took.
DRAIN_MAX = 100
#: What the node says first: it exists, its parameters are read, the conversions load.
STARTING = 'starting: loading the conversions'


def parameter_descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    """Return the ROS descriptor of one row of the parameter table."""
    descriptor = ParameterDescriptor(
        name=spec.name, description=spec.description,
        additional_constraints=spec.constraints)
    if spec.bounds is not None and isinstance(spec.default, float):
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=spec.bounds[0], to_value=spec.bounds[1])]
    elif spec.bounds is not None:
        descriptor.integer_range = [
            IntegerRange(from_value=spec.bounds[0], to_value=spec.bounds[1], step=1)]
    return descriptor


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
        self._inputs: List[InputTopic] = []   # one per topic of the input type; first, as
        # destroy_node reads it, also when a parameters file is refused below
        # The parameter services are started below, once the parameters files are read.
        super().__init__(NODE_NAME, start_parameter_services=False, **kwargs)
        try:
            for path in parameters_files:   # as rotation_bag convert reads them
                parameters_from_yaml(path, self.get_fully_qualified_name())
        except ParameterError:
            self.destroy_node()
            raise
        self.get_logger().info(STARTING)
        # The conversions run interpreted until their compiled kernels, loaded in the
        # background as each is first used, take over (a first run compiles them, and
        # says so on one line): the node converts from its first message.
        load_in_background(self.get_logger().info)
        self._parameter_service = ParameterService(self)
        self.params = NodeParameters()
        # Set by _configure, which __init__ calls below, before any callback can run.
        self._pipeline: ConversionPipeline
        self._configured = False   # while declaring, parameter changes only set self.params
        # mounting.tf_*: the lookup until /tf_static connects the frames (input dropped
        # meanwhile), its subscription, and the rotation found (for the same frames)
        self._static_mounting: Optional[StaticMountingLookup] = None
        self._tf_static: Optional[Subscription] = None
        self._mounting_found: Optional[Tuple[Tuple[str, str], Tuple[float, ...]]] = None
        # CDR bytes -> view; None: rclpy deserialises
        self._decode: Optional[Callable[[bytes], Any]] = None
        self._outputs = OutputPublishers(self)
        self._handoff_timer: Optional[Timer] = None
        self._next_issue_log: Dict[str, float] = {}   # reason -> time of its next warning
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
        self._diagnostics = ConversionDiagnostics(self)
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
        input_type = registry.INPUTS[params.input_type]
        if previous is None or params.input_type != previous.input_type:
            for state in self._inputs:
                state.unsubscribe()
            codec = fixed_layout_codec(input_type.type_name)
            self._decode = None if codec is None else codec.decode
            self._inputs = [InputTopic(self, topic, _memory(params), self._accept, self._drain,
                                       self._on_incompatible_qos)
                            for topic in input_type.topics]
        # A stateful input stream (input_type.stream) starts empty with the new pipeline:
        # its latched topics are subscribed again, so that their publishers deliver what
        # they keep once more, and accepted again.
        replay = previous is not None and input_type.stream is not None
        for state in self._inputs:
            qos = self._input_qos(state, self._offered(state))
            if replay and state.topic.transient_local:
                state.finish_handoff()
                state.reception.forget()
                self._subscribe(state, qos)
            elif qos != state.qos:
                self._subscribe(state, qos)
        if self._outputs.configure(params.outputs, qos_profile(params)):
            self._start_handoff_timer()
        self.get_logger().info(
            f'converting {params.input_type} messages on {input_topic_names(self._inputs)} '
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
            from rotation_node.wire.message_types import message_class
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

    # Input subscriptions and QoS ------------------------------------------------------

    def _input_qos(self, state: InputTopic, offered: List[QoSProfile],
                   incompatible_policy: Optional[QoSPolicyKind] = None) -> QoSProfile:
        """Return the QoS to subscribe ``state``'s topic with (see :func:`input_qos`)."""
        return input_qos(self.params, offered, state.qos,
                         transient_local=state.topic.transient_local,
                         incompatible_policy=incompatible_policy)

    def _offered(self, state: InputTopic) -> List[QoSProfile]:
        """Return the QoS profiles the publishers of ``state``'s topic offer (auto mode only)."""
        if self.params.qos_reliability != AUTO:
            return []
        return state.offered_qos()

    def _adapt(self, state: InputTopic,
               incompatible_policy: Optional[QoSPolicyKind] = None) -> None:
        """Subscribe ``state``'s topic again if the publishers need another QoS; log it once."""
        offered = self._offered(state)
        qos = self._input_qos(state, offered, incompatible_policy)
        subscription, current_qos = state.subscribed()
        if qos == current_qos:
            return
        self.get_logger().info(
            f'input {subscription.topic_name}: publishers offer {policies_text(offered)}; '
            f'subscribing {policies_text([qos])} (was {policies_text([current_qos])})')
        self._subscribe(state, qos)

    def _subscribe(self, state: InputTopic, qos: QoSProfile) -> None:
        """Subscribe ``state``'s topic with ``qos``, replacing its subscription without loss."""
        if state.subscribe(self._pipeline.input_type, qos, raw=self._decode is not None,
                           memory=_memory(self.params)):
            self._start_handoff_timer()

    def _start_handoff_timer(self) -> None:
        if self._handoff_timer is None:
            self._handoff_timer = self.create_timer(HANDOFF_CHECK_S, self._check_handoffs)

    def _check_handoffs(self) -> None:
        """Finish the subscription and publisher replacements that are due; then the timer."""
        now = time.monotonic()
        inputs_busy = [state.check_handoff(now) for state in self._inputs]
        outputs_busy = self._outputs.check_handoffs(now)
        timer = self._handoff_timer   # this callback's timer
        if timer is not None and not outputs_busy and not any(inputs_busy):
            self.destroy_timer(timer)
            self._handoff_timer = None

    def _on_incompatible_qos(self, state: InputTopic, event: Any) -> None:
        if self.params.qos_reliability == AUTO:
            self._adapt(state, event.last_policy_kind)
        else:
            self._log_issue('incompatible_qos', (
                f'input {state.subscribed()[0].topic_name}: a publisher offers a '
                f'{qos_policy_name_from_kind(event.last_policy_kind)} incompatible with '
                f'qos.reliability {self.params.qos_reliability}; its messages are not received '
                f'(qos.reliability auto adapts to it)'))

    def destroy_node(self) -> None:
        """
        Destroy the node: the message-lost event handles first, then what rclpy destroys.

        Each handle belongs to an input subscription, which ``Node.destroy_node``
        destroys (see :meth:`InputTopic.destroy_events`).
        """
        for state in self._inputs:
            state.destroy_events()
        super().destroy_node()

    # Messages ----------------------------------------------------------------------

    def _accept(self, state: InputTopic, data: Any, info: Dict[str, Any]) -> None:
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
                self._pipeline.drop_message(CONVERSION_ERROR, error=exc)
                return
        publish, encoders = self._outputs.publish, self._outputs.encoders
        for name, header, numbers in self._pipeline.process_values(data, state.name):
            publish[name](encoders[name](header, numbers))

    def _drain(self, state: InputTopic) -> None:
        """
        Take and convert what else is queued on ``state``'s subscription, up to a bound.

        One executor wake-up then serves every message that arrived meanwhile; rclpy's
        executor costs more per wake-up than the conversion of a message.
        """
        for data, info in state.waiting(DRAIN_MAX):
            self._accept(state, data, info)

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
        self._diagnostics.publish(self._inputs, self._pipeline, self.params)


def _memory(params: NodeParameters) -> int:
    """Messages a topic's Reception remembers: two histories of the deepest subscription."""
    return 2 * params.qos_depth + 100


def _own(parameters: List[Parameter]) -> Dict[str, Any]:
    """Return ``{name: value}`` of the node's own parameters (not use_sim_time etc.)."""
    return {p.name: p.value for p in parameters if p.name in PARAMETERS_BY_NAME}
