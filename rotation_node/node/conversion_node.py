"""
The orientation-conversion node: parameters in, the pipeline, outputs out.

Subscribes the input type's topics, converts each message with
:class:`rotation_node.pipeline.ConversionPipeline` (as ``rotation_bag convert``)
and publishes the bytes of each output's encoder on its relative topic;
fixed-layout inputs are taken serialized. docs/node.md describes the QoS,
losses, parameter changes and /diagnostics.
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
HANDOFF_CHECK_S = 0.05   # how often a replacement under way is checked
DRAIN_MAX = 100   # messages taken in one callback at most, beyond the executor's one
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

    ParameterError if one of its ``--params-file`` ``parameters_files`` or an
    initial value is invalid for this node.
    """

    def __init__(self, parameters_files: Sequence[str] = (), **kwargs: Any):
        self._inputs: List[InputTopic] = []   # first: destroy_node reads it
        # The parameter services start once the parameters files are read.
        super().__init__(NODE_NAME, start_parameter_services=False, **kwargs)
        try:
            for path in parameters_files:   # as rotation_bag convert reads them
                parameters_from_yaml(path, self.get_fully_qualified_name())
        except ParameterError:
            self.destroy_node()
            raise
        self.get_logger().info(STARTING)
        # The conversions run interpreted until their compiled kernels, loaded in the
        # background, take over: the node converts from its first message.
        load_in_background(self.get_logger().info)
        self._parameter_service = ParameterService(self)
        self.params = NodeParameters()
        self._pipeline: ConversionPipeline   # set by _configure below
        self._configured = False   # while declaring, parameter changes only set self.params
        # mounting.tf_*: the lookup until /tf_static connects the frames, its subscription,
        # and the rotation found (for the same frames)
        self._static_mounting: Optional[StaticMountingLookup] = None
        self._tf_static: Optional[Subscription] = None
        self._mounting_found: Optional[Tuple[Tuple[str, str], Tuple[float, ...]]] = None
        self._decode: Optional[Callable[[bytes], Any]] = None   # None: rclpy deserialises
        self._outputs = OutputPublishers(self)
        self._handoff_timer: Optional[Timer] = None
        self._next_issue_log: Dict[str, float] = {}   # reason -> time of its next warning
        # While a set_parameters request is applied: the node's own parameters it set so far.
        self._request: Optional[Dict[str, Any]] = None
        self._serve_set_parameters()
        # Registered before declaring, so the initial values pass the same checks.
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        defaults = self.params.to_ros()
        # rclpy checks each declared parameter on its own, in order: input_type last, so
        # that the parameters of its input type (tf.*) are set when it is checked.
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

    def _serve_set_parameters(self) -> None:
        """
        Answer ``set_parameters`` here: rclpy's service checks each parameter alone.

        ``ros2 param load`` of ``input_type: tf`` before its frames would fail for the order.
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
        Apply each parameter of a request as rclpy does, then check their combination.

        An invalid combination sets every parameter of the request back.
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
        """Validate a parameter change (applied whole or not at all)."""
        try:
            if self._request is None:
                self._combined(_own(parameters))
            else:   # part of a set_parameters request: the combination comes at its end
                NodeParameters.check_each(_own(parameters))
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _combined(self, changes: Dict[str, Any]) -> NodeParameters:
        """Return the parameters with ``changes``, combination checked (once declared)."""
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
        """Create or update the pipeline, subscriptions and publishers (``previous``: None)."""
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
        # A stateful input stream starts empty with the new pipeline: its latched topics are
        # subscribed again, so that their publishers deliver what they keep once more.
        replay = previous is not None and input_type.stream is not None
        for state in self._inputs:
            _, qos = self._input_qos(state)
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

        Until /tf_static connects the frames, a placeholder (input dropped) and the lookup.
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

    def _input_qos(self, state: InputTopic, incompatible_policy: Optional[QoSPolicyKind] = None
                   ) -> Tuple[List[QoSProfile], QoSProfile]:
        """Return what ``state``'s publishers offer (auto mode only) and the QoS to take."""
        offered = state.offered_qos() if self.params.qos_reliability == AUTO else []
        return offered, input_qos(self.params, offered, state.qos,
                                  transient_local=state.topic.transient_local,
                                  incompatible_policy=incompatible_policy)

    def _adapt(self, state: InputTopic,
               incompatible_policy: Optional[QoSPolicyKind] = None) -> None:
        """Subscribe ``state``'s topic again if the publishers need another QoS; log it once."""
        offered, qos = self._input_qos(state, incompatible_policy)
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
        """Destroy the node: the message-lost event handles before their subscriptions."""
        for state in self._inputs:
            state.destroy_events()
        super().destroy_node()

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
        """Take what else is queued: an executor wake-up costs more than a conversion."""
        for data, info in state.waiting(DRAIN_MAX):
            self._accept(state, data, info)

    def _log_issue(self, reason: str, detail: str) -> None:
        # Throttled per reason (a flood of one cannot hide another), and not with rclpy's
        # throttle_duration_sec: it looks up the caller on every call, milliseconds each.
        now = time.monotonic()
        if now < self._next_issue_log.get(reason, now):
            return
        self._next_issue_log[reason] = now + ISSUE_LOG_PERIOD_S
        self.get_logger().warning(f'{detail} [{reason}]')

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
