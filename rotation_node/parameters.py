"""
Parameters of the orientation-conversion node, in one table: :class:`NodeParameters`.

Each field's :class:`ParameterSpec` holds its ROS name, default, description and
allowed values (:data:`PARAMETERS`). The node declares its parameters from it and
``rotation_bag convert`` reads the same ones from a parameters file
(:func:`parameters_from_yaml`): both accept exactly the same values and files.
Files are read as rcl reads a ``--params-file``, not with rclpy's
``parameter_dict_from_yaml_file``, which differs: scalars typed by rcl's
``strtol``/``strtod`` (:mod:`rotation_node.ros_yaml`), aliases, duplicate keys,
``null`` values and mixed lists refused, node keys nested as namespaces and
matched with the wildcards ``*`` and ``**`` in file order (rclcpp's
``parameter_map.cpp``), and errors naming the file, section and parameter.
The rules between parameters (``input_type: tf`` needs both ``tf.*`` frames,
``mounting.tf_*`` both or neither) are checked once all values are in.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
from pathlib import Path
import re
from typing import Any, cast, Mapping, Optional, Tuple, TYPE_CHECKING

from rotation_node import registry
from rotation_node.conversions import parse_sequence
from rotation_node.errors import ParameterError
from rotation_node.frames import BODY_FRAMES, WORLD_FRAMES
from rotation_node.mounting import IDENTITY, quaternion_from_rotation_values
from rotation_node.ros_yaml import load_ros_yaml
from rotation_node.validation import (
    Boolean, check_fields_in_place, checked_arguments, Choice, ChoiceList, did_you_mean,
    field_specs, FieldSpec, Integer, KeyPath, Real, Reals, Text)

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

NODE_NAME = 'rotation_node'
INPUT_TYPES = tuple(registry.INPUTS)
OUTPUTS = tuple(registry.OUTPUTS)
FRAMES = ('body', 'world')
#: Parameters every rclpy node declares by itself; a parameters file may set them.
ROS_BUILTIN_PARAMETERS = frozenset({'use_sim_time', 'start_type_description_service'})


@dataclass(frozen=True, kw_only=True)
class ParameterSpec(FieldSpec):
    """
    One node parameter: a field spec whose ``name`` is the ROS name (``'euler.sequence'``).

    ``default``'s Python type is the parameter's (a tuple of str: a string array);
    ``rule`` says the allowed values in words where the kind cannot.
    """

    default: Any
    description: str
    rule: str = ''

    @property
    def choices(self) -> Optional[tuple]:
        """Return the allowed values of a string, or of each string-array element (or None)."""
        return getattr(self.kind, 'choices', None)

    @property
    def bounds(self) -> Optional[tuple]:
        """Return the inclusive range ``(low, high)`` of a number (or None)."""
        return getattr(self.kind, 'bounds', None)

    @property
    def constraints(self) -> str:
        """Return the allowed values in words ('' when the type is the only constraint)."""
        return self.kind.constraints or self.rule


_PARAMETER_PATH = KeyPath(error_type=ParameterError, template="parameter '{}'")


def _frame_name(value: str, where: KeyPath) -> str:
    if value.startswith('/'):
        raise where.error(f"{value!r} starts with '/'; TF frame names do not "
                          f'(write {value.lstrip("/")!r})')
    return value


def _rotation(value: tuple, where: KeyPath) -> tuple:
    try:
        quaternion_from_rotation_values(value)
    except ValueError as exc:
        raise where.error(str(exc)) from None
    return value


_ROTATION_RULE = ('[x, y, z, w] (unit quaternion) or [roll, pitch, yaw] (degrees, ROS RPY), '
                  'floating-point numbers')


def _parameter(name, default, kind, description, **options):
    return ParameterSpec(name=name, default=default, description=description, kind=kind,
                         **options).field(default)


def _frame_parameter(name, description, rule):
    """Return a TF frame name parameter ('': none); ``rule`` adds to the rule of frame names."""
    return _parameter(name, '', Text(), description, check=_frame_name,
                      rule='a TF frame name without a leading /' + rule)


@dataclass(frozen=True)
class NodeParameters:
    """
    The node's parameter values; always valid (ParameterError naming the parameter).

    From keyword arguments, ROS names (:meth:`from_ros`) or a parameters file
    (:func:`parameters_from_yaml`).
    """

    input_type: str = _parameter(
        'input_type', 'imu', Choice(INPUT_TYPES),
        'Message type subscribed on the topic "input"; changing it recreates the subscription')
    outputs: tuple = _parameter(
        'outputs', ('euler',), ChoiceList(OUTPUTS, item='output'),
        'Outputs to publish, each on the relative topic of the same name')
    euler_sequence: str = _parameter(
        'euler.sequence', 'xyz', Text('an Euler sequence', parser=parse_sequence),
        'Euler axis sequence of the euler input and outputs: lower case extrinsic, '
        'upper case intrinsic; xyz is ROS roll, pitch, yaw (REP 103)',
        rule='three of x, y, z, no two consecutive alike, all lower case (extrinsic) '
             'or all upper case (intrinsic)')
    euler_degrees: bool = _parameter(
        'euler.degrees', False, Boolean(),
        'Euler angles (input and output) and Euler rates in degrees instead of radians')
    euler_unwrap: bool = _parameter(
        'euler.unwrap', False, Boolean(),
        'Keep the first and third Euler angles continuous over time instead of '
        'wrapping them to (-pi, pi]')
    euler_singularity_threshold: float = _parameter(
        'euler.singularity_threshold', 0.01, Real(0.0, math.pi / 2, integers=False),
        'Distance (rad) of the middle Euler angle from gimbal lock below which a '
        'sample counts as near-singular')
    quaternion_continuity: bool = _parameter(
        'quaternion.continuity', False, Boolean(),
        'Choose the sign of each output quaternion to be continuous with the previous '
        'one, instead of w >= 0')
    quaternion_norm_tolerance: float = _parameter(
        'quaternion.norm_tolerance', 1e-3, Real(0.0, 1.0, integers=False),
        'Largest | |q| - 1 | of an input quaternion normalised without a warning')
    angular_velocity_input_frame: str = _parameter(
        'angular_velocity.input_frame', 'body', Choice(FRAMES),
        'Frame of the angular velocity carried by Imu and Odometry inputs '
        '(body as REP 145 says)')
    angular_velocity_output_frame: str = _parameter(
        'angular_velocity.output_frame', 'body', Choice(FRAMES),
        'Frame of the angular_velocity output')
    covariance_frame: str = _parameter(
        'covariance.frame', 'fixed', Choice(('fixed', 'body')),
        'Axes of the input orientation covariance: fixed (rotation about the world axes, '
        'REP 145) or body (about the body axes)')
    covariance_max_linearisation_ratio: float = _parameter(
        'covariance.max_linearisation_ratio', 0.3, Real(0.0, 1e6, integers=False),
        'Largest orientation standard deviation over distance from gimbal lock (rad/rad) for '
        'which euler_stddev and euler_covariance are published (about 10 % accurate at 0.3)')
    frames_input_world: str = _parameter(
        'frames.input_world', 'enu', Choice(WORLD_FRAMES),
        'World frame convention of the input: enu (x east, y north, z up; REP 103) or ned')
    frames_input_body: str = _parameter(
        'frames.input_body', 'flu', Choice(BODY_FRAMES),
        'Body frame convention of the input: flu (x forward, y left, z up; REP 103) or frd')
    frames_output_world: str = _parameter(
        'frames.output_world', 'enu', Choice(WORLD_FRAMES),
        'World frame convention of the outputs: enu or ned')
    frames_output_body: str = _parameter(
        'frames.output_body', 'flu', Choice(BODY_FRAMES),
        'Body frame convention of the outputs: flu or frd')
    mounting_body_rotation: tuple = _parameter(
        'mounting.body_rotation', IDENTITY, Reals((3, 4)),
        "M in R' = W R M: the output body frame's orientation in the input's body frame "
        '(e.g. base_link in imu_link); applied to orientation, angular velocity and covariance',
        check=_rotation, rule=_ROTATION_RULE)
    mounting_world_rotation: tuple = _parameter(
        'mounting.world_rotation', IDENTITY, Reals((3, 4)),
        "W in R' = W R M: the input world frame's orientation in the output world frame",
        check=_rotation, rule=_ROTATION_RULE)
    mounting_yaw_offset: float = _parameter(
        'mounting.yaw_offset', 0.0, Real(integers=False),
        "Added to the yaw (rad), as robot_localization's yaw_offset: W = Rz(yaw_offset + "
        'magnetic_declination) mounting.world_rotation')
    mounting_magnetic_declination: float = _parameter(
        'mounting.magnetic_declination', 0.0, Real(integers=False),
        "Added to the yaw (rad), as robot_localization's magnetic_declination_radians")
    mounting_tf_sensor_frame: str = _frame_parameter(
        'mounting.tf_sensor_frame',
        'With mounting.tf_body_frame: M is read once from /tf_static, the orientation of '
        'tf_body_frame in this frame (e.g. imu_link)', '; with mounting.tf_body_frame')
    mounting_tf_body_frame: str = _frame_parameter(
        'mounting.tf_body_frame',
        'With mounting.tf_sensor_frame: the output body frame whose orientation in '
        'tf_sensor_frame is M (e.g. base_link)',
        ', not mounting.tf_sensor_frame; with mounting.tf_sensor_frame and '
        'mounting.body_rotation left at identity')
    qos_reliability: str = _parameter(
        'qos.reliability', 'auto', Choice(('auto', 'reliable', 'best_effort')),
        'Reliability of the input subscriptions and output publishers; auto: inputs adapt '
        'reliability and durability to what the publishers offer, outputs are reliable')
    qos_depth: int = _parameter(
        'qos.depth', 1000, Integer(1, 10000),
        'History depth (keep last) of the input subscriptions and of the output publishers')
    tf_parent_frame: str = _frame_parameter(
        'tf.parent_frame',
        'input_type tf: the frame the orientation is expressed in (tf2 target frame, '
        'e.g. map)', '; required with input_type tf')
    tf_child_frame: str = _frame_parameter(
        'tf.child_frame',
        'input_type tf: the frame whose orientation is published (tf2 source frame, '
        'e.g. base_link)', ', not tf.parent_frame; required with input_type tf')

    def __post_init__(self) -> None:
        """Check every value, then the input type's own parameters; string arrays as tuples."""
        check_fields_in_place(self, _PARAMETER_PATH)
        _check_mounting_frames(self)
        if self.input_type == 'tf':
            _check_tf_frames(self)

    @classmethod
    def from_ros(cls, values: Mapping[str, Any]) -> NodeParameters:
        """Return parameters from ``{ROS name: value}``; missing ones take their defaults."""
        return cls().replaced(values)

    def replaced(self, values: Mapping[str, Any]) -> NodeParameters:
        """Return a copy with the parameters in ``{ROS name: value}`` changed; ParameterError."""
        return replace(self, **checked_arguments(type(self), values, _PARAMETER_PATH,
                                                 unknown=unknown_parameter_error))

    @classmethod
    def check_each(cls, values: Mapping[str, Any]) -> None:
        """Check each value of ``{ROS name: value}`` on its own (a ``set_parameters`` request)."""
        checked_arguments(cls, values, _PARAMETER_PATH, unknown=unknown_parameter_error)

    def to_ros(self) -> dict:
        """Return ``{ROS name: value}``, string arrays as lists (what rclpy expects)."""
        return {spec.name: list(value) if isinstance(value, tuple) else value
                for spec, value in ((s, getattr(self, s.attribute)) for s in PARAMETERS)}


def mounting_frames_problem(params: NodeParameters) -> str:
    """
    Return why only one of the two ``mounting.tf_*`` frames is set ('' if both or neither).

    Not checked on construction: ROS sets parameters one at a time.
    """
    sensor, body = params.mounting_tf_sensor_frame, params.mounting_tf_body_frame
    if bool(sensor) == bool(body):
        return ''
    given, missing = (('tf_sensor_frame', 'tf_body_frame') if sensor
                      else ('tf_body_frame', 'tf_sensor_frame'))
    return (f"parameter 'mounting.{missing}': required with 'mounting.{given}' (the mounting "
            'is read from /tf_static between the two frames)')


def _check_mounting_frames(params: NodeParameters) -> None:
    sensor, body = params.mounting_tf_sensor_frame, params.mounting_tf_body_frame
    if not (sensor and body):
        return
    if sensor == body:
        raise ParameterError(f"parameters 'mounting.tf_sensor_frame' and "
                             f"'mounting.tf_body_frame' are both {sensor!r}; name two frames")
    if quaternion_from_rotation_values(params.mounting_body_rotation) != IDENTITY:
        raise ParameterError("parameter 'mounting.body_rotation': set it or the "
                             'mounting.tf_* frames, not both')


def _check_tf_frames(params: NodeParameters) -> None:
    for name, value, example in (('tf.parent_frame', params.tf_parent_frame, 'map'),
                                 ('tf.child_frame', params.tf_child_frame, 'base_link')):
        if not value:
            raise ParameterError(f"parameter '{name}': required with input_type tf "
                                 f'(a frame name such as {example})')
    if params.tf_parent_frame == params.tf_child_frame:
        raise ParameterError(f"parameters 'tf.parent_frame' and 'tf.child_frame' are both "
                             f'{params.tf_parent_frame!r}; name two different frames')


PARAMETERS = cast(Tuple[ParameterSpec, ...], field_specs(NodeParameters))
PARAMETERS_BY_NAME = {spec.name: spec for spec in PARAMETERS}


def unknown_parameter_error(name: str, where: str = '') -> ParameterError:
    """Return the error for a name that is not a parameter: the nearest one, and all of them."""
    return ParameterError(
        f"unknown parameter '{name}'{where}{did_you_mean(name, PARAMETERS_BY_NAME)}; "
        f"the node's parameters are {', '.join(PARAMETERS_BY_NAME)}")


def parameters_from_yaml(path: StrPath, node_name: str = NODE_NAME) -> NodeParameters:
    """
    Read the node's parameters from a ROS 2 parameters file, as the node reads its own.

    Every section whose key matches ``node_name`` (a name or ``/ns/name``; keys may
    use ``*`` and ``**``) is applied in file order; parameters not set keep their
    defaults. ParameterError, naming the file and the parameter, for a file that
    cannot be read or parsed, has no section for the node, or sets an unknown
    parameter or an invalid value.
    """
    fq_name = node_name if node_name.startswith('/') else '/' + node_name
    sections = parameters_file_sections(path)
    matching = [values for key, values in sections if _node_key_matches(key, fq_name)]
    if not matching:
        found = ', '.join(repr(key) for key, _ in sections) or 'none'
        raise ParameterError(
            f"{parameters_file_label(path)}: no section for node '{fq_name}' (its sections: "
            f'{found}; '
            f"key it '{fq_name}:', '/**/{fq_name.rsplit('/', 1)[-1]}:' or '/**:')")
    values = {name: value for section in matching for name, value in section.items()
              if name not in ROS_BUILTIN_PARAMETERS}
    try:
        return NodeParameters.from_ros(values)
    except ParameterError as exc:
        raise ParameterError(f'{parameters_file_label(path)}: {exc}') from None


# launch_ros writes a launch file's parameters=[{...}] to a temporary file named so.
_LAUNCH_PARAMETERS_FILE = re.compile(r'launch_params_[A-Za-z0-9_]+')


def parameters_file_label(path: StrPath) -> str:
    """Return how messages name a parameters file: ``parameters file <path>`` (or launch's)."""
    path = Path(path)
    if _LAUNCH_PARAMETERS_FILE.fullmatch(path.name):
        import tempfile   # (and shutil, random): only for the names launch_ros gives
        if path.parent == Path(tempfile.gettempdir()):
            return 'the parameters the launch file gives'
    return f'parameters file {path}'


def parameters_file_sections(path: StrPath) -> list[tuple[str, dict[str, Any]]]:
    """
    Return ``[(node key, {parameter: value})]`` of a parameters file, for any node, as rcl.

    Nested parameter names joined with '.', nested node keys as namespaces
    (``robot/rotation_node``); ParameterError for what rcl refuses.
    """
    label = parameters_file_label(path)
    document = load_ros_yaml(path, label, ParameterError, aliases=False)
    if not isinstance(document, dict):
        raise ParameterError(f'{label}: expected a mapping of node names')
    sections = []

    def read(prefix, mapping):
        for key, value in mapping.items():
            name = f'{prefix}/{str(key).strip("/")}' if prefix else str(key)
            if isinstance(value, dict) and isinstance(value.get('ros__parameters'), dict):
                values = _flattened(value['ros__parameters'])
                problem = _node_key_problem(name) or next(filter(None, (
                    _value_problem(parameter, v) for parameter, v in values.items())), '')
                if problem:
                    raise ParameterError(f"{label}: section '{name}': {problem}")
                sections.append((name, values))
            elif (isinstance(value, dict) and value and 'ros__parameters' not in value
                    and all(isinstance(child, dict) for child in value.values())):
                read(name, value)   # a namespace of node keys
            else:
                raise ParameterError(
                    f"{label}: section '{name}' needs a 'ros__parameters:' mapping")
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
    kinds = {type(item) for item in value} if isinstance(value, list) else set()
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
        if isinstance(value, dict):
            flat.update(_flattened(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


def _node_key_matches(key, fq_name):
    """Whether a parameters-file node key (rcl syntax, wildcards * and **) names the node."""
    pattern = ''.join(
        '(?:/[^/]+)*' if token == '**' else '/[^/]+' if token == '*' else '/' + re.escape(token)
        for token in key.strip('/').split('/'))
    return re.fullmatch(pattern, fq_name) is not None
