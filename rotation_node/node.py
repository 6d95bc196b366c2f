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
``set_parameters`` request with several parameters checks and applies each
one on its own (some may be applied while others are rejected), while
``set_parameters_atomically`` applies all of them or none. Every value is
checked against the table before it is accepted; an accepted change takes
effect on the next message. Counters and the current conventions are
published on ``/diagnostics`` once a second.

Run it with, for example::

    rotation_node --ros-args -r input:=/imu/data -p outputs:='[euler, angular_velocity]'
"""
import gc
import sys
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
import rclpy
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rotation_node import messages
from rotation_node.bag.qos import qos_profile
from rotation_node.errors import ParameterError
from rotation_node.parameters import (
    NODE_NAME, NodeParameters, PARAMETERS, PARAMETERS_BY_NAME, parameters_file_sections,
    parameters_from_yaml, ParameterSpec, ROS_BUILTIN_PARAMETERS, unknown_parameter_error)
from rotation_node.pipeline import ConversionPipeline, SKIP_REASONS, warm_up_conversions

DIAGNOSTICS_PERIOD_S = 1.0
ISSUE_LOG_PERIOD_S = 5.0


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


def _parameters_files(args):
    return [value for flag, value in ros_arguments(args) if flag == '--params-file']


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
        super().__init__(NODE_NAME, **kwargs)
        try:
            for path in parameters_files:   # as rotation_bag convert reads them
                parameters_from_yaml(path, self.get_fully_qualified_name())
        except ParameterError:
            self.destroy_node()
            raise
        self.params = NodeParameters()
        self._pipeline = None
        self._subscriptions = []
        self._output_publishers: Dict[str, Any] = {}
        self._next_issue_log: Dict[str, float] = {}   # reason -> time of its next warning
        self._reported = (0, 0)   # dropped and skipped totals at the last diagnostics
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
        warm_up_conversions()
        self._configure(None, self.params)
        # No QoS event handlers on the diagnostics publisher: each handler is one more
        # entity that rclpy's executor re-examines at every wake-up, i.e. every message.
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, '/diagnostics', 10,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)

    # Parameters --------------------------------------------------------------------

    def _check_parameters(self, parameters):
        """Validate a parameter change (all of it, or none of it, is applied)."""
        try:
            self.params.replaced(_own(parameters))
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        """Apply a validated change; it takes effect on the next message."""
        previous, self.params = self.params, self.params.replaced(_own(parameters))
        # Not while declaring (__init__ configures once), nor for others' parameters.
        if self._pipeline is not None and self.params != previous:
            self._configure(previous, self.params)

    def _configure(self, previous, params):
        """Create or update the pipeline, subscription and publishers for ``params``."""
        qos = qos_profile(params)
        qos_changed = previous is None or qos != qos_profile(previous)
        stats = None if self._pipeline is None else self._pipeline.stats
        self._pipeline = ConversionPipeline(params, on_issue=self._log_issue, stats=stats)
        # The new pipeline's input stream starts empty; a stateful one (tf) subscribes
        # again, so that its latched topics (/tf_static) are delivered to it again.
        stateful = messages.INPUTS[params.input_type].stream is not None
        if qos_changed or stateful or params.input_type != previous.input_type:
            for subscription in self._subscriptions:
                self.destroy_subscription(subscription)
            self._subscriptions = [
                self._subscribe(self._pipeline.input_type, topic, params)
                for topic in messages.INPUTS[params.input_type].topics]
        for name in list(self._output_publishers):
            if qos_changed or name not in params.outputs:
                self.destroy_publisher(self._output_publishers.pop(name))
        for name, message_type in self._pipeline.output_types.items():
            if name not in self._output_publishers:
                self._output_publishers[name] = self.create_publisher(message_type, name, qos)
        self.get_logger().info(
            f'converting {params.input_type} messages on {self._input_topic_names()} '
            f'to {", ".join(params.outputs)} (euler.sequence {params.euler_sequence}, '
            f'{"degrees" if params.euler_degrees else "radians"})')

    def _subscribe(self, message_type, topic, params):
        """Subscribe one topic of the input type; its messages go to the pipeline."""
        name = topic.name
        if name == messages.INPUT_TOPIC.name:   # the common case without a closure
            callback = self._on_input
        else:
            def callback(msg):
                self._on_input(msg, name)
        return self.create_subscription(
            message_type, name, callback,
            qos_profile(params, transient_local=topic.transient_local))

    def _input_topic_names(self):
        return ', '.join(subscription.topic_name for subscription in self._subscriptions)

    # Messages ----------------------------------------------------------------------

    def _on_input(self, msg, topic=messages.INPUT_TOPIC.name):
        for name, output in self._pipeline.process(msg, topic):
            self._output_publishers[name].publish(output)

    def _log_issue(self, reason, detail):
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

    def _publish_diagnostics(self):
        stats = self._pipeline.stats
        totals = (sum(stats.dropped.values()), sum(stats.skipped.values()))
        new_dropped, new_skipped = (now - before for now, before in zip(totals, self._reported))
        self._reported = totals
        if new_dropped or new_skipped:
            level = DiagnosticStatus.WARN
            message = (f'{new_dropped} messages dropped, {new_skipped} partly converted '
                       f'in the last {DIAGNOSTICS_PERIOD_S:g} s')
        else:
            level, message = DiagnosticStatus.OK, 'converting'
        values = {
            'input_topic': self._input_topic_names(),
            'received': stats.received,
            'published': stats.published,
            'dropped': totals[0],
            **{f'dropped.{reason}': stats.dropped[reason]
               for reason in self._pipeline.drop_reasons},
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


def _own(parameters):
    """Return ``{name: value}`` of the node's own parameters (not use_sim_time etc.)."""
    return {p.name: p.value for p in parameters if p.name in PARAMETERS_BY_NAME}


def _text(value):
    if isinstance(value, list):
        return ','.join(value)
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


def main(args: Optional[List[str]] = None) -> int:
    """
    Run the node until Ctrl-C (``--help``: print its usage).

    Returns
    -------
    int
        0 after Ctrl-C or shutdown; 1 if a parameters file or an initial parameter
        value is invalid (one line on stderr says which).

    """
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
    try:
        rclpy.init(args=args)
        node = RotationNode(parameters_files=files)
        # The ~1e5 objects of rclpy, numpy and numba live as long as the process: keep
        # them out of the cyclic collector, whose full passes over them stall a
        # callback for ~50 ms (50 messages at 1 kHz).
        gc.freeze()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterError as exc:
        print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
