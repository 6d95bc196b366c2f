"""
Parameters of the orientation-conversion node, in one table: :class:`NodeParameters`.

Each field's :class:`ParameterSpec` holds its ROS name, default, description and
allowed values; :data:`PARAMETERS` lists them in declaration order. The node
declares its ROS parameters from it (a ``ParameterDescriptor`` each), and
``rotation_bag convert`` reads the same parameters from a ROS parameters file
(:func:`parameters_from_yaml`): both accept exactly the same values, typed as ROS
types them (a double needs ``0.0``, not ``0``). This module does not import rclpy.

Where rcl and rclpy differ
--------------------------
A node reads its ``--params-file`` through rcl (``rcl_yaml_param_parser``);
rclpy's ``rclpy.parameter.parameter_dict_from_yaml_file`` reads the same file
otherwise. Files are read here as rcl reads them, so that ``convert`` and the
node accept the same files; these differences are the reason this module and
:mod:`rotation_node.ros_yaml` read files themselves:

1. Plain scalars are typed by rcl's ``get_value`` (``rcl_yaml_param_parser/src/
   parse.c``: the yes/no/on/off booleans, ``strtol`` base 0, then ``strtod``),
   not by PyYAML's YAML 1.1 resolvers that rclpy's ``yaml.safe_load`` uses: ``1e3``,
   ``1.0e3`` and ``0x1p-3`` are doubles (rclpy: strings), ``1_000`` is a string
   (rclpy: 1000); a number beyond the double range is a string
   (:func:`rotation_node.ros_yaml.ros_scalar`).
2. Aliases are refused (rcl ``parser.c``: an alias event is an error; rclpy
   expands them), and a key given twice is an error (rclpy keeps the last).
3. Node keys: rcl nests namespace keys (``robot: {rotation_node: {ros__parameters:
   ...}}`` is ``/robot/rotation_node``, ``parser.c``/``namespace.c``) and checks
   the names; the node applies sections whose key matches it with the wildcards
   ``*`` (one token) and ``**`` (any tokens), in file order (rclcpp
   ``parameter_map.cpp``; rclpy's ``node.cpp`` likewise). rclpy's function matches
   keys exactly and ``/**`` only (:func:`parameters_file_sections`,
   :func:`_node_key_matches`).
4. Values: rcl refuses a parameter without a value (``null``) and a list mixing
   types or holding mappings (``parse.c``); rclpy turns either into a string
   (:func:`_value_problem`).
5. Naming: errors name the file (or, for the temporary file launch_ros writes,
   :data:`LAUNCH_PARAMETERS`), the section and the parameter; rcl names none
   (:func:`parameters_file_label`).

At run time rclpy checks each parameter of a ``set_parameters`` request on its
own; the node checks the rules between parameters (``input_type: tf`` needs both
``tf.*`` frames, ``mounting.tf_*`` both or neither) once a whole request is in.
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
COVARIANCE_FRAMES = ('fixed', 'body')
RELIABILITIES = ('auto', 'reliable', 'best_effort')
#: Parameters every rclpy node declares by itself; a parameters file may set them.
ROS_BUILTIN_PARAMETERS = frozenset({'use_sim_time', 'start_type_description_service'})


@dataclass(frozen=True, kw_only=True)
class ParameterSpec(FieldSpec):
    """
    One node parameter: a field spec whose ``name`` is the ROS name (``'euler.sequence'``).

    ``default``'s Python type is the parameter's type (a tuple of str is a ROS
    string array); ``description`` is what ``ros2 param describe`` shows;
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
    The node's parameter values; always valid (checked on construction).

    Construct it with keyword arguments named after the fields, from ROS names
    (:meth:`from_ros`), or from a parameters file (:func:`parameters_from_yaml`);
    an invalid value raises ParameterError naming the ROS parameter.
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
        'covariance.frame', 'fixed', Choice(COVARIANCE_FRAMES),
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
        'qos.reliability', 'auto', Choice(RELIABILITIES),
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
        """
        Return a copy with the parameters named (by ROS name) in ``values`` changed.

        Raises ParameterError for a name that is not a parameter, or an invalid value.
        """
        return replace(self, **checked_arguments(type(self), values, _PARAMETER_PATH,
                                                 unknown=unknown_parameter_error))

    @classmethod
    def check_each(cls, values: Mapping[str, Any]) -> None:
        """
        Check each value of ``{ROS name: value}`` on its own, not their combination.

        For the values of one ``set_parameters`` request, whose combination
        (``input_type: tf`` needs both frames) is checked once all are in. Raises
        ParameterError for a name that is not a parameter, or an invalid value.
        """
        checked_arguments(cls, values, _PARAMETER_PATH, unknown=unknown_parameter_error)

    def to_ros(self) -> dict:
        """Return ``{ROS name: value}``, string arrays as lists (what rclpy expects)."""
        return {spec.name: list(value) if isinstance(value, tuple) else value
                for spec, value in ((s, getattr(self, s.attribute)) for s in PARAMETERS)}


def mounting_frames_problem(params: NodeParameters) -> str:
    """
    Return why only one of the two ``mounting.tf_*`` frames is set ('' if both or neither).

    Not checked on construction: ROS declares and sets parameters one at a
    time, so the node checks it once all are set (at start-up, and per
    ``set_parameters`` request); ``convert`` and ``export`` before reading.
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

    The file has the format ``ros2 run ... --ros-args --params-file`` reads::

        rotation_node:            # or /rotation_node, /**, /**/rotation_node
          ros__parameters:
            input_type: imu
            euler:
              sequence: ZYX       # nested keys join with '.', or write euler.sequence

    Every section whose key matches ``node_name`` (a name, or ``/ns/name``; rcl
    wildcards ``*`` and ``**`` in the keys) is applied in file order; sections
    of other nodes are ignored, parameters not in the file keep their defaults.
    Raises ParameterError, naming the file and the parameter, for a file that
    cannot be read, is not valid YAML, has no section for the node, or sets an
    unknown parameter or an invalid value.
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


#: launch_ros writes a launch file's ``parameters=[{...}]`` to such a file in the temporary
#: directory (``NamedTemporaryFile(prefix='launch_params_')``): messages name it thus.
_LAUNCH_PARAMETERS_FILE = re.compile(r'launch_params_[A-Za-z0-9_]+')
LAUNCH_PARAMETERS = 'the parameters the launch file gives'


def parameters_file_label(path: StrPath) -> str:
    """Return how messages name a parameters file: ``parameters file <path>`` (or launch's)."""
    path = Path(path)
    if _LAUNCH_PARAMETERS_FILE.fullmatch(path.name):
        import tempfile   # (and shutil, random): only for the names launch_ros gives
        if path.parent == Path(tempfile.gettempdir()):
            return LAUNCH_PARAMETERS
    return f'parameters file {path}'


def parameters_file_sections(path: StrPath) -> list[tuple[str, dict[str, Any]]]:
    """
    Return the sections of a ROS 2 parameters file, for any node, as rcl reads them.

    ``(node key, {parameter name: value})`` in file order, nested parameter names
    joined with '.', nested node keys as namespaces (``robot: {rotation_node:
    {ros__parameters: ...}}`` is the section ``robot/rotation_node``). Raises
    ParameterError for a file that cannot be read, is not valid YAML, or is not
    a mapping of node keys each holding a ``ros__parameters`` mapping.
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
