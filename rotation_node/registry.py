"""
The registry: what each message type the node reads and writes is, declared once.

:data:`INPUTS` has one :class:`InputType` per ``input_type`` value (message type,
topics, the fields a :class:`Sample` is read from, or the module of a stateful
stream); :data:`OUTPUTS` one :class:`OutputType` per ``outputs`` value (message
type, the pipeline values it is computed from, how it is built and encoded).
The parameters, pipeline, node, bag tools and documentation tables read them.
Message classes and encoders are looked up when first used: this module imports
neither rclpy nor the message packages (docs/ARCHITECTURE.md: adding a type).
"""
from __future__ import annotations

import array
from dataclasses import dataclass
import functools
import importlib
import operator
from typing import Any, Callable, Iterable, NamedTuple, Optional, Sequence, Tuple, TYPE_CHECKING

import numpy as np
from rotation_node import conversions, kinematics

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

# Forms of an input orientation.
QUATERNION = 'quaternion'
EULER = 'euler'
ROTATION_VECTOR = 'rotation_vector'

# The named values the pipeline computes (rotation_node.pipeline.VALUES), outputs need.
ORIENTATION = 'orientation'                # quaternion (x, y, z, w), any non-zero scale
OUTPUT_QUATERNION = 'output_quaternion'    # unit: w >= 0, or sign-continuous
EULER_ANGLES = 'euler_angles'              # of euler.sequence, first and third in (-pi, pi]
PUBLISHED_EULER = 'published_euler'        # first and third unwrapped with euler.unwrap
ANGULAR_VELOCITY = 'angular_velocity'      # rad/s in the output frame, measured or differenced
EULER_RATES = 'euler_rates'                # unavailable near gimbal lock
# Rotation-vector covariance (3 x 3, rad^2) in the output frames, about covariance.frame's
# axes; unavailable when the input has none or it is all zeros (or invalid).
ORIENTATION_COVARIANCE = 'orientation_covariance'
# First-order Euler covariance (rad^2 or deg^2); unavailable near gimbal lock or past
# covariance.max_linearisation_ratio.
EULER_COVARIANCE = 'euler_covariance'
PIPELINE_VALUES = (ORIENTATION, OUTPUT_QUATERNION, EULER_ANGLES, PUBLISHED_EULER,
                   ANGULAR_VELOCITY, EULER_RATES, ORIENTATION_COVARIANCE, EULER_COVARIANCE)


class Sample(NamedTuple):
    """
    One orientation sample read from an input message; None where it has no such data.

    ``header``: a std_msgs/Header or any object with ``stamp`` and ``frame_id``.
    ``orientation`` in the input type's form: ``(x, y, z, w)``, or ``(x, y, z)``
    of Euler angles or a rotation vector. ``angular_velocity`` in rad/s in
    ``angular_velocity.input_frame``; ``covariance`` 3 x 3 row-major, rad^2.
    """

    header: Any
    orientation: Optional[Tuple[float, ...]]
    angular_velocity: Optional[Tuple[float, float, float]] = None
    covariance: Optional[Tuple[float, ...]] = None


SampleStream = Callable[[str, Any], Iterable[Sample]]
"""``(topic name, message) -> samples`` of one input stream (the :class:`InputTopic` name)."""

Report = Callable[[str, str], None]
"""``report(reason, detail)``: a stream's message gave no sample, and why (counted as dropped)."""


class InputTopic(NamedTuple):
    """
    A topic an input type is subscribed on: relative (``'input'``) or absolute (``'/tf'``).

    ``transient_local``: latched data such as ``/tf_static``, subscribed reliable,
    keep all, transient local (volatile with the ``qos`` parameters otherwise).
    """

    name: str
    transient_local: bool = False


INPUT_TOPIC = InputTopic('input')
TF_TOPIC = InputTopic('/tf')
TF_STATIC_TOPIC = InputTopic('/tf_static', transient_local=True)


_XYZ = ('x', 'y', 'z')
_XYZW = ('x', 'y', 'z', 'w')


def _xyz(vector):
    return (vector.x, vector.y, vector.z)


@dataclass(frozen=True)
class InputType:
    """
    One value of ``input_type``: a message type and how a sample is read from it.

    ``*_field``: dotted paths in the message; an ``*_unknown_field`` array whose first
    element is -1 marks the value as absent (REP 145). docs/ARCHITECTURE.md: adding one.
    """

    name: str                     # the parameter value, e.g. 'imu'
    type_name: str                # e.g. 'sensor_msgs/msg/Imu'
    orientation_form: str         # QUATERNION, EULER (of euler.sequence) or ROTATION_VECTOR
    orientation_field: str        # a Quaternion, or a Vector3 for the other forms
    angular_velocity_field: Optional[str] = None   # a Vector3 (rad/s); None: differenced
    covariance_field: Optional[str] = None
    covariance_indices: Tuple[int, ...] = tuple(range(9))   # the 3 x 3 block, row-major
    orientation_unknown_field: Optional[str] = None
    angular_velocity_unknown_field: Optional[str] = None
    topics: Tuple[InputTopic, ...] = (INPUT_TOPIC,)
    stream: Optional[str] = None   # the module of a stateful type's sample stream

    @property
    def message_class(self) -> type:
        """Return the rclpy message class of :attr:`type_name`."""
        return _message_class(self.type_name)

    @property
    def drop_reasons(self) -> Tuple[str, ...]:
        """Return the reasons a stateful type's stream reports (counted as dropped messages)."""
        return () if self.stream is None else importlib.import_module(self.stream).DROP_REASONS

    def sample_reader(self, *, angular_velocity: bool = True,
                      covariance: bool = False) -> Callable[[Any], Sample]:
        """Return ``read(message) -> Sample`` of a plain type; the optional fields on request."""
        new = tuple.__new__   # Sample's own __new__ is a Python function: slower
        components = _XYZW if self.orientation_form == QUATERNION else _XYZ
        orientation = operator.attrgetter(   # one C call returns the tuple
            *(f'{self.orientation_field}.{c}' for c in components))
        unknown = _optional_getter(self.orientation_unknown_field)
        rate = rate_unknown = None
        if angular_velocity and self.angular_velocity_field is not None:
            rate = operator.attrgetter(*(f'{self.angular_velocity_field}.{c}' for c in _XYZ))
            rate_unknown = _optional_getter(self.angular_velocity_unknown_field)
        block = None
        if covariance and self.covariance_field is not None:
            block = _covariance_block(self.covariance_field, self.covariance_indices)
        if unknown is None and rate is None and block is None:
            return lambda msg: new(Sample, (msg.header, orientation(msg), None, None))

        def read(msg):
            return new(Sample, (
                msg.header,
                None if unknown is not None and unknown(msg)[0] == -1.0 else orientation(msg),
                None if rate is None or (rate_unknown is not None and rate_unknown(msg)[0] == -1.0)
                else rate(msg),
                None if block is None else block(msg)))
        return read

    def sample_stream(self, params: Any, *, angular_velocity: bool = True,
                      covariance: bool = False,
                      report: Optional[Report] = None) -> SampleStream:
        """
        Return ``(topic, message) -> samples`` of one input stream (and its state, if any).

        ``report(reason, detail)``: what a stateful type could not use (:attr:`drop_reasons`).
        """
        if self.stream is not None:
            return importlib.import_module(self.stream).sample_stream(
                params, report or (lambda reason, detail: None))
        read = self.sample_reader(angular_velocity=angular_velocity, covariance=covariance)
        return lambda topic, msg: (read(msg),)


def _optional_getter(path):
    return None if path is None else operator.attrgetter(path)


def _covariance_block(path, indices):
    get = operator.attrgetter(path)
    pick = operator.itemgetter(*indices)
    return lambda msg: tuple(float(v) for v in pick(get(msg)))


_POSE_ROTATION_BLOCK = (21, 22, 23, 27, 28, 29, 33, 34, 35)   # rows/columns 3-5 of 6 x 6

_INPUT_LIST = (
    InputType('quaternion', 'geometry_msgs/msg/QuaternionStamped', QUATERNION, 'quaternion'),
    InputType('pose', 'geometry_msgs/msg/PoseStamped', QUATERNION, 'pose.orientation'),
    InputType('pose_with_covariance', 'geometry_msgs/msg/PoseWithCovarianceStamped', QUATERNION,
              'pose.pose.orientation', covariance_field='pose.covariance',
              covariance_indices=_POSE_ROTATION_BLOCK),
    InputType('imu', 'sensor_msgs/msg/Imu', QUATERNION, 'orientation',
              angular_velocity_field='angular_velocity',
              covariance_field='orientation_covariance',
              orientation_unknown_field='orientation_covariance',
              angular_velocity_unknown_field='angular_velocity_covariance'),
    InputType('odometry', 'nav_msgs/msg/Odometry', QUATERNION, 'pose.pose.orientation',
              angular_velocity_field='twist.twist.angular', covariance_field='pose.covariance',
              covariance_indices=_POSE_ROTATION_BLOCK),
    InputType('transform', 'geometry_msgs/msg/TransformStamped', QUATERNION,
              'transform.rotation'),
    InputType('euler', 'geometry_msgs/msg/Vector3Stamped', EULER, 'vector'),
    InputType('rotation_vector', 'geometry_msgs/msg/Vector3Stamped', ROTATION_VECTOR, 'vector'),
    InputType('tf', 'tf2_msgs/msg/TFMessage', QUATERNION, 'transforms',
              topics=(TF_TOPIC, TF_STATIC_TOPIC), stream='rotation_node.tf_input'),
)

INPUTS = {entry.name: entry for entry in _INPUT_LIST}
"""The input types by ``input_type`` value, in documentation order."""


class ArrayDimension(NamedTuple):
    """The values of a std_msgs/MultiArrayDimension."""

    label: str
    size: int
    stride: int


class ArrayLayout(NamedTuple):
    """The values of a std_msgs/MultiArrayLayout (read as the message is)."""

    dim: Tuple[ArrayDimension, ...]
    data_offset: int = 0


@dataclass(frozen=True)
class OutputMessage:
    """
    How the numbers of an output become a message of one type, and back.

    ``numbers(message)`` gives back what ``build(header, numbers)`` was given (from
    rclpy messages and CDR views). ``stamped_numbers``: the type is a Header and the
    numbers only, which :mod:`rotation_node.wire.cdr` encodes without a message.
    """

    type_name: str
    build: Callable[[Any, Sequence[float]], Any]
    numbers: Callable[[Any], Sequence[float]]
    stamped_numbers: bool = False
    layout: Optional[ArrayLayout] = None   # of a Float64MultiArray type

    @property
    def message_class(self) -> type:
        """Return the rclpy message class of :attr:`type_name`."""
        return _message_class(self.type_name)

    def encoder(self) -> Callable[[Any, Sequence[float]], bytes]:
        """
        Return ``encode(header, numbers) -> bytes``: the CDR of the built message.

        Built only where the type needs it; the bytes of ``cdr.message_encoder``,
        else rclpy's. ValueError for ``stamped_numbers`` without a fixed layout.
        """
        from rotation_node.wire import cdr
        if self.stamped_numbers:
            codec = cdr.fixed_layout_codec(self.type_name)
            if codec is None:
                raise ValueError(f'stamped_numbers: {self.type_name} has no fixed CDR layout')
            return codec.stamped_encoder()
        if self.layout is not None:
            encode_data = cdr.float64_multi_array_encoder(self.layout)
            return lambda header, numbers: encode_data(numbers)
        encode = cdr.message_encoder(self.type_name)
        if encode is None:
            from rclpy.serialization import serialize_message
            encode = serialize_message
        build = self.build
        return lambda header, numbers: encode(build(header, numbers))


@functools.lru_cache(maxsize=None)
def _message_class(type_name):
    from rotation_node.wire.message_types import message_class
    return message_class(type_name)


def _build_vector3_stamped(header, numbers):
    message = _message_class('geometry_msgs/msg/Vector3Stamped')()
    message.header = header
    vector = message.vector
    vector.x, vector.y, vector.z = (float(v) for v in numbers)
    return message


def _build_quaternion_stamped(header, numbers):
    message = _message_class('geometry_msgs/msg/QuaternionStamped')()
    message.header = header
    quaternion = message.quaternion
    quaternion.x, quaternion.y, quaternion.z, quaternion.w = (float(v) for v in numbers)
    return message


VECTOR3_STAMPED = OutputMessage(
    'geometry_msgs/msg/Vector3Stamped', _build_vector3_stamped,
    lambda msg: _xyz(msg.vector), stamped_numbers=True)
QUATERNION_STAMPED = OutputMessage(
    'geometry_msgs/msg/QuaternionStamped', _build_quaternion_stamped,
    lambda msg: (msg.quaternion.x, msg.quaternion.y, msg.quaternion.z, msg.quaternion.w),
    stamped_numbers=True)


def _build_vector3_with_covariance(header, numbers):
    message = _message_class('sensor_msgs/msg/MagneticField')()
    message.header = header
    vector = message.magnetic_field
    vector.x, vector.y, vector.z = (float(v) for v in numbers[:3])
    message.magnetic_field_covariance = [float(v) for v in numbers[3:]]
    return message


VECTOR3_WITH_COVARIANCE = OutputMessage(
    'sensor_msgs/msg/MagneticField', _build_vector3_with_covariance,
    lambda msg: (*_xyz(msg.magnetic_field), *msg.magnetic_field_covariance),
    stamped_numbers=True)
"""A stamped 3-vector with its 3 x 3 covariance (row-major), as sensor_msgs/MagneticField.

The only standard type that is exactly a header, a 3-vector and its 3 x 3
covariance (fixed layout). Imu and PoseWithCovariance are avoided on purpose:
theirs is a covariance of rotations, which an Euler-angle covariance is not.
"""


def float64_multi_array(dimensions: Sequence[Tuple[str, int, int]]) -> OutputMessage:
    """
    Return the :class:`OutputMessage` of a std_msgs/Float64MultiArray with a fixed layout.

    ``dimensions``: ``(label, size, stride)`` outermost first. No header: no stamp.
    """
    layout = ArrayLayout(tuple(ArrayDimension(*dimension) for dimension in dimensions))

    @functools.lru_cache(maxsize=None)
    def layout_message():   # one, shared by the messages built
        dimension_class = _message_class('std_msgs/msg/MultiArrayDimension')
        return _message_class('std_msgs/msg/MultiArrayLayout')(
            dim=[dimension_class(label=d.label, size=d.size, stride=d.stride) for d in layout.dim],
            data_offset=layout.data_offset)

    def build(header, numbers):
        message = _message_class('std_msgs/msg/Float64MultiArray')()
        message.layout = layout_message()
        message.data = array.array('d', numbers)   # a tuple, list or array of float64
        return message
    return OutputMessage('std_msgs/msg/Float64MultiArray', build, lambda msg: msg.data,
                         layout=layout)


@dataclass(frozen=True)
class OutputType:
    """
    One value allowed in ``outputs`` (and its relative topic): what is published, and how.

    ``compute(params, *values it needs) -> numbers`` (None: the one value as it is);
    skipped where a value is unavailable. docs/ARCHITECTURE.md: adding one.
    """

    name: str
    message: OutputMessage
    needs: Tuple[str, ...]
    compute: Optional[Callable[..., ArrayLike]]
    compute_takes_blocks: bool = False   # also arrays of samples, rows bit for bit (tested)

    @property
    def type_name(self) -> str:
        """Return the ROS message type of the output."""
        return self.message.type_name

    @property
    def message_class(self) -> type:
        """Return the rclpy message class of the output."""
        return self.message.message_class


def _axis_angle(params, q):
    """Return ``[x, y, z, angle]`` of each quaternion: shape (..., 4), one sample or a block."""
    axis, angle = conversions.axis_angle_from_quaternion(q)
    numbers = np.empty(axis.shape[:-1] + (4,))
    numbers[..., :3] = axis
    numbers[..., 3] = angle
    return numbers


def _matrix(params, q):
    """Return the rotation matrices row-major: shape (..., 9), one sample or a block."""
    matrix = conversions.matrix_from_quaternion(q)
    return matrix.reshape(matrix.shape[:-2] + (9,))


def _euler_stddev(params, covariance):
    return np.sqrt(np.diagonal(covariance))


def _euler_with_covariance(params, angles, covariance):
    return (*angles, *covariance.ravel().tolist())


def _quaternion_rate(params, q, omega):
    return kinematics.quaternion_derivative(q, omega, frame=params.angular_velocity_output_frame)


_OUTPUT_LIST = (
    OutputType('quaternion', QUATERNION_STAMPED, (OUTPUT_QUATERNION,), None),
    OutputType('euler', VECTOR3_STAMPED, (PUBLISHED_EULER,), None),
    OutputType('rotation_vector', VECTOR3_STAMPED, (ORIENTATION,),
               lambda params, q: conversions.rotation_vector_from_quaternion(q),
               compute_takes_blocks=True),
    OutputType('axis_angle', float64_multi_array([('axis_angle', 4, 4)]), (ORIENTATION,),
               _axis_angle, compute_takes_blocks=True),
    OutputType('matrix', float64_multi_array([('rows', 3, 9), ('cols', 3, 3)]), (ORIENTATION,),
               _matrix, compute_takes_blocks=True),
    OutputType('angular_velocity', VECTOR3_STAMPED, (ANGULAR_VELOCITY,), None),
    OutputType('euler_rates', VECTOR3_STAMPED, (EULER_RATES,), None),
    OutputType('quaternion_rate', QUATERNION_STAMPED, (OUTPUT_QUATERNION, ANGULAR_VELOCITY),
               _quaternion_rate, compute_takes_blocks=True),
    OutputType('euler_stddev', VECTOR3_STAMPED, (EULER_COVARIANCE,), _euler_stddev),
    OutputType('euler_covariance', VECTOR3_WITH_COVARIANCE, (PUBLISHED_EULER, EULER_COVARIANCE),
               _euler_with_covariance),
)

OUTPUTS = {entry.name: entry for entry in _OUTPUT_LIST}
"""The output types by name, in documentation order."""
