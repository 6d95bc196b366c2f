"""
Parameters of the orientation-conversion node, in one table.

Every parameter is a field of :class:`NodeParameters`; its ROS name, default,
description and allowed values live in that field's :class:`ParameterSpec`, and
:data:`PARAMETERS` lists them in declaration order. The node declares its ROS
parameters from this table, and :func:`parameters_from_yaml` reads the same
parameters from a ROS parameters file for ``rotation_bag convert``, so the live
node and the offline conversion accept exactly the same values.

Values are typed as ROS types them: a double parameter needs a float (``0.0``,
not ``0``), a string array a list of strings. This module does not import rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
import math
from pathlib import Path
import re
from typing import Any, Callable, Mapping, Optional, TYPE_CHECKING

from rotation_node import messages
from rotation_node.conversions import parse_sequence
from rotation_node.errors import ParameterError
from rotation_node.frames import BODY_FRAMES, WORLD_FRAMES
from rotation_node.ros_yaml import load_ros_yaml
from rotation_node.validation import describe_value, did_you_mean

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

NODE_NAME = 'rotation_node'

INPUT_TYPES = tuple(messages.INPUTS)
"""Values of ``input_type``: the input types of :data:`rotation_node.messages.INPUTS`."""

OUTPUTS = tuple(messages.OUTPUTS)
"""Values allowed in ``outputs``: the outputs of :data:`rotation_node.messages.OUTPUTS`."""

FRAMES = ('body', 'world')
COVARIANCE_FRAMES = ('fixed', 'body')
RELIABILITIES = ('auto', 'reliable', 'best_effort')

ROS_BUILTIN_PARAMETERS = frozenset({'use_sim_time', 'start_type_description_service'})
"""Parameters every rclpy node declares by itself; a parameters file may set them."""


@dataclass(frozen=True)
class ParameterSpec:
    """
    One node parameter: ROS name, default, description and allowed values.

    Attributes
    ----------
    name : str
        ROS parameter name, e.g. ``'euler.sequence'``.
    default : str, bool, int, float or tuple of str
        Default value; its Python type is the parameter's type (a tuple of str
        is a ROS string array).
    description : str
        One-line description, shown by ``ros2 param describe``.
    choices : tuple of str, optional
        Allowed values of a string parameter, or of each string-array element.
    bounds : tuple of (float, float) or (int, int), optional
        Inclusive range of a numeric parameter.
    check : callable, optional
        Further check of a value of the right type; raises ParameterError.
    rule : str, optional
        The allowed values in words, where ``choices`` and ``bounds`` cannot say it.
    attribute : str
        Name of the :class:`NodeParameters` field that holds the value.

    """

    name: str
    default: Any
    description: str
    choices: Optional[tuple] = None
    bounds: Optional[tuple] = None
    check: Optional[Callable[[Any], None]] = None
    rule: str = ''
    attribute: str = ''

    @property
    def type(self) -> type:  # noqa: A003
        """Python type of the value: str, bool, int, float or tuple (string array)."""
        return type(self.default)

    @property
    def constraints(self) -> str:
        """Return the allowed values in words ('' when the type is the only constraint)."""
        if self.choices is not None:
            prefix = 'each one of' if self.type is tuple else 'one of'
            return f'{prefix}: {", ".join(self.choices)}'
        if self.bounds is not None:
            return f'from {self.bounds[0]:g} to {self.bounds[1]:g}'
        return self.rule

    def checked(self, value: Any) -> Any:
        """
        Return ``value`` in canonical form (string arrays as tuples) if it is valid.

        Raises
        ------
        ParameterError
            The value has the wrong type or is not allowed; the message names the
            parameter.

        """
        value = _checked_type(self, value)
        if self.choices is not None:
            for item in (value if self.type is tuple else (value,)):
                if item not in self.choices:
                    raise ParameterError(
                        f"parameter '{self.name}': {item!r} is not allowed"
                        f'{did_you_mean(item, self.choices)}; {self.constraints}')
        if self.bounds is not None and not self.bounds[0] <= value <= self.bounds[1]:
            raise ParameterError(
                f"parameter '{self.name}': {value!r} is out of range; "
                f'allowed {self.constraints}')
        if self.check is not None:
            self.check(value)
        return value


_TYPE_NAMES = {
    str: 'a string', bool: 'a boolean', int: 'an integer',
    float: 'a floating-point number (write 0.0, not 0)', tuple: 'a list of strings'}


def _checked_type(spec, value):
    if spec.type is tuple and value is None:
        value = ()   # ROS gives an empty list in a parameters file (outputs: []) as no value
    if spec.type is tuple:
        ok = isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)
        value = tuple(value) if ok else value
    elif spec.type is bool:
        ok = isinstance(value, bool)
    else:  # bool is an int subclass, but a bool is not a number here
        ok = isinstance(value, spec.type) and not isinstance(value, bool)
    if not ok:
        raise ParameterError(
            f"parameter '{spec.name}': expected {_TYPE_NAMES[spec.type]}, "
            f'got {describe_value(value)}')
    if spec.type is float and not math.isfinite(value):
        raise ParameterError(f"parameter '{spec.name}': must be finite, got {value!r}")
    return value


def _check_sequence(value):
    try:
        parse_sequence(value)
    except ValueError as exc:
        raise ParameterError(
            f"parameter 'euler.sequence': {value!r} is not an Euler sequence ({exc})"
        ) from None


def _check_outputs(value):
    if not value:
        raise ParameterError(
            f"parameter 'outputs': list at least one output; choose from {', '.join(OUTPUTS)}")
    repeated = sorted({name for name in value if value.count(name) > 1})
    if repeated:
        raise ParameterError(f"parameter 'outputs': {', '.join(repeated)} listed twice")


def _check_frame_name(name):
    def check(value):
        if value.startswith('/'):
            raise ParameterError(f"parameter '{name}': {value!r} starts with '/'; TF frame "
                                 f'names do not (write {value.lstrip("/")!r})')
    return check


def _parameter(name, default, description, **constraints):
    return field(default=default, metadata={'spec': ParameterSpec(
        name, default, description, **constraints)})


@dataclass(frozen=True)
class NodeParameters:
    """
    The node's parameter values; always valid (checked on construction).

    Construct it with keyword arguments named after the fields, from ROS names
    with :meth:`from_ros`, or from a parameters file with
    :func:`parameters_from_yaml`. Each field's :class:`ParameterSpec` (ROS name,
    default, description, allowed values) is in :data:`PARAMETERS`.

    Raises
    ------
    ParameterError
        A value is invalid; the message names the ROS parameter.

    """

    input_type: str = _parameter(
        'input_type', 'imu',
        'Message type subscribed on the topic "input"; changing it recreates the subscription',
        choices=INPUT_TYPES)
    outputs: tuple = _parameter(
        'outputs', ('euler',),
        'Outputs to publish, each on the relative topic of the same name',
        choices=OUTPUTS, check=_check_outputs)
    euler_sequence: str = _parameter(
        'euler.sequence', 'xyz',
        'Euler axis sequence of the euler input and outputs: lower case extrinsic, '
        'upper case intrinsic; xyz is ROS roll, pitch, yaw (REP 103)',
        check=_check_sequence,
        rule='three of x, y, z, no two consecutive alike, all lower case (extrinsic) '
             'or all upper case (intrinsic)')
    euler_degrees: bool = _parameter(
        'euler.degrees', False,
        'Euler angles (input and output) and Euler rates in degrees instead of radians')
    euler_unwrap: bool = _parameter(
        'euler.unwrap', False,
        'Keep the first and third Euler angles continuous over time instead of '
        'wrapping them to (-pi, pi]')
    euler_singularity_threshold: float = _parameter(
        'euler.singularity_threshold', 0.01,
        'Distance (rad) of the middle Euler angle from gimbal lock below which a '
        'sample counts as near-singular',
        bounds=(0.0, math.pi / 2))
    quaternion_continuity: bool = _parameter(
        'quaternion.continuity', False,
        'Choose the sign of each output quaternion to be continuous with the previous '
        'one, instead of w >= 0')
    quaternion_norm_tolerance: float = _parameter(
        'quaternion.norm_tolerance', 1e-3,
        'Largest | |q| - 1 | of an input quaternion normalised without a warning',
        bounds=(0.0, 1.0))
    angular_velocity_input_frame: str = _parameter(
        'angular_velocity.input_frame', 'body',
        'Frame of the angular velocity carried by Imu and Odometry inputs '
        '(body as REP 145 says)',
        choices=FRAMES)
    angular_velocity_output_frame: str = _parameter(
        'angular_velocity.output_frame', 'body',
        'Frame of the angular_velocity output',
        choices=FRAMES)
    covariance_frame: str = _parameter(
        'covariance.frame', 'fixed',
        'Axes of the input orientation covariance: fixed (rotation about the world axes, '
        'REP 145) or body (about the body axes)',
        choices=COVARIANCE_FRAMES)
    covariance_max_linearisation_ratio: float = _parameter(
        'covariance.max_linearisation_ratio', 0.3,
        'Largest orientation standard deviation over distance from gimbal lock (rad/rad) for '
        'which euler_stddev and euler_covariance are published (about 10 % accurate at 0.3)',
        bounds=(0.0, 1e6))
    frames_input_world: str = _parameter(
        'frames.input_world', 'enu',
        'World frame convention of the input: enu (x east, y north, z up; REP 103) or ned',
        choices=WORLD_FRAMES)
    frames_input_body: str = _parameter(
        'frames.input_body', 'flu',
        'Body frame convention of the input: flu (x forward, y left, z up; REP 103) or frd',
        choices=BODY_FRAMES)
    frames_output_world: str = _parameter(
        'frames.output_world', 'enu',
        'World frame convention of the outputs: enu or ned',
        choices=WORLD_FRAMES)
    frames_output_body: str = _parameter(
        'frames.output_body', 'flu',
        'Body frame convention of the outputs: flu or frd',
        choices=BODY_FRAMES)
    qos_reliability: str = _parameter(
        'qos.reliability', 'auto',
        'Reliability of the input subscriptions and output publishers; auto: inputs adapt '
        'reliability and durability to what the publishers offer, outputs are reliable',
        choices=RELIABILITIES)
    qos_depth: int = _parameter(
        'qos.depth', 1000,
        'History depth (keep last) of the input subscriptions and of the output publishers',
        bounds=(1, 10000))
    tf_parent_frame: str = _parameter(
        'tf.parent_frame', '',
        'input_type tf: the frame the orientation is expressed in (tf2 target frame, '
        'e.g. map)',
        check=_check_frame_name('tf.parent_frame'),
        rule='a TF frame name without a leading /; required with input_type tf')
    tf_child_frame: str = _parameter(
        'tf.child_frame', '',
        'input_type tf: the frame whose orientation is published (tf2 source frame, '
        'e.g. base_link)',
        check=_check_frame_name('tf.child_frame'),
        rule='a TF frame name without a leading /, not tf.parent_frame; required with '
             'input_type tf')

    def __post_init__(self) -> None:
        """Check every value, then the input type's own parameters; string arrays as tuples."""
        for spec in PARAMETERS:
            object.__setattr__(self, spec.attribute, spec.checked(getattr(self, spec.attribute)))
        check = messages.INPUTS[self.input_type].check_parameters
        if check is not None:
            check(self)

    @classmethod
    def from_ros(cls, values: Mapping[str, Any]) -> 'NodeParameters':
        """Return parameters from ``{ROS name: value}``; missing ones take their defaults."""
        return cls().replaced(values)

    def replaced(self, values: Mapping[str, Any]) -> 'NodeParameters':
        """
        Return a copy with the parameters named (by ROS name) in ``values`` changed.

        Raises
        ------
        ParameterError
            A name is not a parameter of the node, or a value is invalid.

        """
        changes = {}
        for name, value in values.items():
            if name not in PARAMETERS_BY_NAME:
                raise unknown_parameter_error(name)
            changes[PARAMETERS_BY_NAME[name].attribute] = value
        return replace(self, **changes)

    def to_ros(self) -> dict:
        """Return ``{ROS name: value}``, string arrays as lists (what rclpy expects)."""
        return {spec.name: list(value) if isinstance(value, tuple) else value
                for spec, value in ((s, getattr(self, s.attribute)) for s in PARAMETERS)}


PARAMETERS = tuple(replace(f.metadata['spec'], attribute=f.name) for f in fields(NodeParameters))
"""The parameter table: one :class:`ParameterSpec` per :class:`NodeParameters` field."""

PARAMETERS_BY_NAME = {spec.name: spec for spec in PARAMETERS}


def unknown_parameter_error(name: str, where: str = '') -> ParameterError:
    """
    Return the error for a name that is not a parameter of the node.

    It names the nearest parameter (``difflib``) and lists them all; ``where``
    (e.g. ``' in -p euler.sequense:=xyz'``) follows the name.
    """
    return ParameterError(
        f"unknown parameter '{name}'{where}{did_you_mean(name, PARAMETERS_BY_NAME)}; "
        f"the node's parameters are {', '.join(PARAMETERS_BY_NAME)}")


def parameters_from_yaml(path: StrPath, node_name: str = NODE_NAME) -> NodeParameters:
    """
    Read the node's parameters from a ROS 2 parameters file.

    The file has the format ``ros2 run ... --ros-args --params-file`` reads::

        rotation_node:            # or /rotation_node, /**, /**/rotation_node
          ros__parameters:
            input_type: imu
            euler:
              sequence: ZYX       # nested keys join with '.', or write euler.sequence

    Every section whose key matches the node (rcl wildcards ``*`` and ``**``
    allowed) is applied in file order; sections of other nodes are ignored.
    Parameters not in the file keep their defaults.

    Parameters
    ----------
    path : str or os.PathLike
        The parameters file.
    node_name : str, optional
        Node name, or fully qualified name (``/ns/name``) to match the keys against.

    Returns
    -------
    NodeParameters

    Raises
    ------
    ParameterError
        The file is missing or unreadable, is not valid YAML, has no section for
        the node, or sets an unknown parameter or an invalid value; the message
        names the file and the parameter.

    """
    path = Path(path)
    fq_name = node_name if node_name.startswith('/') else '/' + node_name
    sections = parameters_file_sections(path)
    matching = [values for key, values in sections if _node_key_matches(key, fq_name)]
    if not matching:
        found = ', '.join(repr(key) for key, _ in sections) or 'none'
        raise ParameterError(
            f"parameters file {path}: no section for node '{fq_name}' (its sections: {found}; "
            f"key it '{fq_name}:', '/**/{fq_name.rsplit('/', 1)[-1]}:' or '/**:')")
    values = {}
    for section in matching:
        values.update(section)
    for name in ROS_BUILTIN_PARAMETERS.intersection(values):
        del values[name]
    try:
        return NodeParameters.from_ros(values)
    except ParameterError as exc:
        raise ParameterError(f'parameters file {path}: {exc}') from None


def parameters_file_sections(path: StrPath) -> list[tuple[str, dict[str, Any]]]:
    """
    Read the sections of a ROS 2 parameters file, for any node.

    Node keys may nest as namespaces (``robot: {rotation_node: {ros__parameters:
    ...}}`` is the section ``robot/rotation_node``), as rcl reads them.

    Parameters
    ----------
    path : str or os.PathLike
        The parameters file.

    Returns
    -------
    list of (str, dict)
        ``(node key, {parameter name: value})`` in file order, nested parameter
        names joined with ``'.'``.

    Raises
    ------
    ParameterError
        The file cannot be read, is not valid YAML, is not a mapping of node
        names, or a node key holds no ``ros__parameters`` mapping.

    """
    document = load_ros_yaml(path, f'parameters file {path}', ParameterError, aliases=False)
    if not isinstance(document, dict):
        raise ParameterError(f'parameters file {path}: expected a mapping of node names')
    sections = []

    def read(prefix, mapping):
        for key, value in mapping.items():
            name = f'{prefix}/{str(key).strip("/")}' if prefix else str(key)
            if isinstance(value, dict) and isinstance(value.get('ros__parameters'), dict):
                problem = _node_key_problem(name) or next(filter(None, (
                    _value_problem(parameter, v)
                    for parameter, v in _flattened(value['ros__parameters']).items())), '')
                if problem:
                    raise ParameterError(f"parameters file {path}: section '{name}': {problem}")
                sections.append((name, _flattened(value['ros__parameters'])))
            elif (isinstance(value, dict) and value and 'ros__parameters' not in value
                    and all(isinstance(child, dict) for child in value.values())):
                read(name, value)   # a namespace of node keys
            else:
                raise ParameterError(
                    f"parameters file {path}: section '{name}' needs a 'ros__parameters:' "
                    'mapping')
    read('', document)
    return sections


_NODE_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')
_NAMESPACE = re.compile(r'(?:/[A-Za-z_][A-Za-z0-9_]*)+')


def _node_key_problem(key):
    """Return what rcl finds wrong with a node key of a parameters file ('' if nothing)."""
    if key == '/**':
        return ''
    namespace, _, node = key.rpartition('/')
    if node != '*' and not _NODE_NAME.fullmatch(node):
        return (f'{node!r} is not a node name (letters, digits and _, not starting with a '
                'digit), nor * or **')
    namespace = namespace if namespace.startswith('/') or not namespace else '/' + namespace
    if namespace not in ('', '/', '/**') and not _NAMESPACE.fullmatch(namespace):
        return f'{namespace!r} is not a namespace'
    return ''


def _value_problem(name, value):
    """Return what rcl refuses in a parameter value of a file ('' if nothing)."""
    if value is None:
        return f"parameter '{name}' has no value"
    if isinstance(value, list):
        kinds = {type(item) for item in value}
        if not kinds <= {bool, int, float, str}:
            return f"parameter '{name}': a list may hold only booleans, numbers or strings"
        if len(kinds) > 1:
            return (f"parameter '{name}': a list must hold values of one type, got "
                    f"{', '.join(sorted(kind.__name__ for kind in kinds))}")
    return ''


def _flattened(mapping, prefix=''):
    """Return ``{'a.b': value}`` from nested ``{'a': {'b': value}}``, as rcl reads it."""
    flat = {}
    for key, value in mapping.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            flat.update(_flattened(value, name + '.'))
        else:
            flat[name] = value
    return flat


def _node_key_matches(key, fq_name):
    """Whether a parameters-file node key (rcl syntax, wildcards * and **) names the node."""
    tokens = key.strip('/').split('/')
    pattern = ''.join(
        '(?:/[^/]+)*' if token == '**' else '/[^/]+' if token == '*' else '/' + re.escape(token)
        for token in tokens)
    return re.fullmatch(pattern, fq_name) is not None
