"""
Message-level conversion pipeline shared by the live node and ``rotation_bag convert``.

:class:`ConversionPipeline` turns one input message (the type named by the
``input_type`` parameter) into the output messages listed by ``outputs``. It
holds the per-stream state that conversions over time need (the previous
orientation and stamp for the finite-difference angular velocity, the previous
Euler angles for unwrapping, the previous quaternion for sign continuity), and
it never raises on bad data: a bad message is dropped or partly converted,
counted in :attr:`ConversionPipeline.stats` by reason, and reported to an
optional ``on_issue`` callback. All rotation math is done by
:mod:`rotation_node.conversions` and :mod:`rotation_node.kinematics`.

Input types (``input_type``), with where the orientation and the angular
velocity come from (finite difference: from consecutive orientations):

- ``quaternion``: geometry_msgs/QuaternionStamped; finite difference.
- ``pose``: geometry_msgs/PoseStamped; finite difference.
- ``pose_with_covariance``: geometry_msgs/PoseWithCovarianceStamped; finite difference.
- ``imu``: sensor_msgs/Imu ``orientation`` (unknown when ``orientation_covariance[0]
  == -1``) and ``angular_velocity`` (finite difference when
  ``angular_velocity_covariance[0] == -1``).
- ``odometry``: nav_msgs/Odometry ``pose.pose.orientation`` and ``twist.twist.angular``.
- ``transform``: geometry_msgs/TransformStamped ``transform.rotation``; finite difference.
- ``euler``: geometry_msgs/Vector3Stamped, x, y, z = first, second, third angle of
  ``euler.sequence`` (degrees with ``euler.degrees``); finite difference.
- ``rotation_vector``: geometry_msgs/Vector3Stamped, axis times angle (rad);
  finite difference.

Outputs (``outputs``), each published on the relative topic of its name. Every
stamped output carries the input's header (stamp and frame_id):

- ``quaternion``: geometry_msgs/QuaternionStamped, unit, w >= 0 (or sign-continuous
  over time with ``quaternion.continuity``).
- ``euler``: geometry_msgs/Vector3Stamped, x, y, z = first, second, third angle of
  ``euler.sequence``; first and third in (-pi, pi] (or unwrapped with
  ``euler.unwrap``), the middle in [-pi/2, pi/2] (Tait-Bryan) or [0, pi] (proper
  Euler); degrees with ``euler.degrees``.
- ``rotation_vector``: geometry_msgs/Vector3Stamped, unit axis times angle in
  [0, pi] (rad).
- ``axis_angle``: std_msgs/Float64MultiArray ``[x, y, z, angle]``: unit axis and
  angle in [0, pi] (rad), axis (1, 0, 0) for the identity; one layout dimension
  ``axis_angle`` (size 4).
- ``matrix``: std_msgs/Float64MultiArray, the rotation matrix (body to world)
  row-major; layout dimensions ``rows`` (size 3, stride 9) and ``cols`` (size 3,
  stride 3).
- ``angular_velocity``: geometry_msgs/Vector3Stamped, rad/s in
  ``angular_velocity.output_frame``.
- ``euler_rates``: geometry_msgs/Vector3Stamped, time derivatives of the three
  Euler angles (rad/s, or deg/s with ``euler.degrees``).
- ``quaternion_rate``: geometry_msgs/QuaternionStamped, dq/dt (1/s) of the
  published quaternion.

std_msgs/Float64MultiArray has no header: ``axis_angle`` and ``matrix`` carry no
stamp or frame_id.

The finite-difference angular velocity is the constant rate that carries the
previous orientation into the current one over the interval between their
stamps: exact for a constant rate, second-order accurate at the interval's
midpoint, so half a sample period older than the stamp it is published with.
It needs increasing stamps: the first message, and a message whose stamp is
not after the previous one, produce no finite-difference outputs.
"""
import math
import warnings
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable, NamedTuple, Optional

import numpy as np
from geometry_msgs.msg import (
    PoseStamped, PoseWithCovarianceStamped, QuaternionStamped, TransformStamped,
    Vector3Stamped)
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from rotation_node import conversions, kinematics
from rotation_node.parameters import (
    ANGULAR_VELOCITY_OUTPUTS, INPUT_TYPES, OUTPUTS, NodeParameters)

# Reasons for dropping a whole message (counted in PipelineStats.dropped).
NON_FINITE_ORIENTATION = 'non_finite_orientation'
ZERO_QUATERNION = 'zero_quaternion'
CONVERSION_ERROR = 'conversion_error'
# Reasons for skipping some outputs of a message (counted in PipelineStats.skipped).
ORIENTATION_UNKNOWN = 'orientation_unknown'
NON_FINITE_ANGULAR_VELOCITY = 'non_finite_angular_velocity'
TIMESTAMP_NOT_INCREASING = 'timestamp_not_increasing'
EULER_RATES_NEAR_SINGULAR = 'euler_rates_near_singular'
# A message whose quaternion was normalised (counted in PipelineStats.normalised).
NON_UNIT_QUATERNION = 'non_unit_quaternion'
DROP_REASONS = (NON_FINITE_ORIENTATION, ZERO_QUATERNION, CONVERSION_ERROR)
SKIP_REASONS = (ORIENTATION_UNKNOWN, NON_FINITE_ANGULAR_VELOCITY, TIMESTAMP_NOT_INCREASING,
                EULER_RATES_NEAR_SINGULAR)

MULTI_ARRAY_LAYOUTS = {
    'axis_angle': MultiArrayLayout(
        dim=[MultiArrayDimension(label='axis_angle', size=4, stride=4)], data_offset=0),
    'matrix': MultiArrayLayout(
        dim=[MultiArrayDimension(label='rows', size=3, stride=9),
             MultiArrayDimension(label='cols', size=3, stride=3)], data_offset=0),
}
"""Layout of each std_msgs/Float64MultiArray output (do not modify)."""


class _InputSpec(NamedTuple):
    """How to read one input type: message class and field accessors."""

    message_type: type
    orientation: Callable     # msg -> Quaternion or Vector3 message field
    orientation_form: str     # 'quaternion', 'euler' or 'rotation_vector'
    angular_velocity: Optional[Callable] = None   # msg -> Vector3, or None to difference


def _imu_orientation(msg):
    return None if msg.orientation_covariance[0] == -1.0 else msg.orientation


def _imu_angular_velocity(msg):
    return None if msg.angular_velocity_covariance[0] == -1.0 else msg.angular_velocity


_INPUTS = {
    'quaternion': _InputSpec(QuaternionStamped, lambda m: m.quaternion, 'quaternion'),
    'pose': _InputSpec(PoseStamped, lambda m: m.pose.orientation, 'quaternion'),
    'pose_with_covariance': _InputSpec(
        PoseWithCovarianceStamped, lambda m: m.pose.pose.orientation, 'quaternion'),
    'imu': _InputSpec(Imu, _imu_orientation, 'quaternion', _imu_angular_velocity),
    'odometry': _InputSpec(
        Odometry, lambda m: m.pose.pose.orientation, 'quaternion',
        lambda m: m.twist.twist.angular),
    'transform': _InputSpec(TransformStamped, lambda m: m.transform.rotation, 'quaternion'),
    'euler': _InputSpec(Vector3Stamped, lambda m: m.vector, 'euler'),
    'rotation_vector': _InputSpec(Vector3Stamped, lambda m: m.vector, 'rotation_vector'),
}
assert tuple(_INPUTS) == INPUT_TYPES

OUTPUT_MESSAGE_TYPES = {
    'quaternion': QuaternionStamped,
    'euler': Vector3Stamped,
    'rotation_vector': Vector3Stamped,
    'axis_angle': Float64MultiArray,
    'matrix': Float64MultiArray,
    'angular_velocity': Vector3Stamped,
    'euler_rates': Vector3Stamped,
    'quaternion_rate': QuaternionStamped,
}
"""Message class published for each output name."""
assert tuple(OUTPUT_MESSAGE_TYPES) == OUTPUTS


def input_message_type(input_type: str) -> type:
    """Return the message class subscribed for an ``input_type`` value."""
    return _INPUTS[input_type].message_type


@dataclass
class PipelineStats:
    """
    Counters of a pipeline since it was created.

    Attributes
    ----------
    received : int
        Input messages processed.
    published : int
        Output messages returned (all outputs together).
    dropped : collections.Counter
        Input messages that produced no output because they were invalid, by reason
        (``non_finite_orientation``, ``zero_quaternion``, ``conversion_error``).
    skipped : collections.Counter
        Input messages of which some outputs could not be computed, by reason
        (``orientation_unknown``, ``non_finite_angular_velocity``,
        ``timestamp_not_increasing``, ``euler_rates_near_singular``).
    normalised : int
        Input quaternions further than ``quaternion.norm_tolerance`` from unit length.
    near_singular : int
        Messages whose middle Euler angle was within ``euler.singularity_threshold``
        of gimbal lock (counted when an Euler output is enabled).

    """

    received: int = 0
    published: int = 0
    dropped: Counter = field(default_factory=Counter)
    skipped: Counter = field(default_factory=Counter)
    normalised: int = 0
    near_singular: int = 0


class _Dropped(Exception):
    """Internal: the current message is invalid and produces no output."""

    def __init__(self, reason, detail):
        super().__init__(detail)
        self.reason = reason


def _xyzw(quaternion):
    return (quaternion.x, quaternion.y, quaternion.z, quaternion.w)


def _xyz(vector):
    return (vector.x, vector.y, vector.z)


def _stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def _seconds(stamp_ns):
    return f'{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d}'


def _unwrapped(angle, previous, period):
    """Return ``angle`` shifted by the multiple of ``period`` nearest to ``previous``."""
    return angle + period * round((previous - angle) / period)


class ConversionPipeline:
    """
    Convert input messages into the configured output messages, one stream at a time.

    Parameters
    ----------
    params : NodeParameters
        Input type, outputs and conventions.
    on_issue : callable, optional
        Called as ``on_issue(reason, detail)`` for every dropped message, skipped
        output group and normalised quaternion (``detail`` is a sentence for a log).
    stats : PipelineStats, optional
        Counters to continue (e.g. across a parameter change); new ones by default.

    Notes
    -----
    The per-stream state (previous orientation and stamp, previous Euler angles,
    previous quaternion) starts empty: create a new pipeline per input stream.
    Outputs share the input message's ``header`` object.

    """

    def __init__(self, params: NodeParameters, *, on_issue=None, stats=None):
        self.params = params
        self.stats = PipelineStats() if stats is None else stats
        self._on_issue = on_issue
        self._input = _INPUTS[params.input_type]
        self._outputs = params.outputs
        self._needs_angular_velocity = not set(ANGULAR_VELOCITY_OUTPUTS).isdisjoint(self._outputs)
        self._angle_period = 360.0 if params.euler_degrees else 2.0 * math.pi
        # Per-stream state.
        self._previous_quaternion = None     # last orientation, for the finite difference
        self._previous_stamp_ns = None
        self._previous_output_quaternion = None   # for quaternion.continuity
        self._previous_euler = None               # for euler.unwrap

    @property
    def input_type(self) -> type:
        """Message class of the input."""
        return self._input.message_type

    @property
    def output_types(self) -> dict:
        """``{output name: message class}`` for the configured outputs, in order."""
        return {name: OUTPUT_MESSAGE_TYPES[name] for name in self._outputs}

    def process(self, msg) -> list:
        """
        Convert one input message.

        Parameters
        ----------
        msg : message of class :attr:`input_type`

        Returns
        -------
        list of (str, message)
            ``(output name, message)`` for each output that could be computed, in
            the order of ``outputs``; empty when the message was dropped. Never
            raises on bad data.

        """
        return [(name, _BUILDERS[name](header, values))
                for name, header, values in self.process_values(msg)]

    def process_values(self, msg) -> list:
        """
        Convert one input message into the values of the output messages.

        :meth:`process` without building the messages, for callers that encode
        them themselves (``rotation_bag convert``); same outputs, same counts.

        Parameters
        ----------
        msg : object
            A message of class :attr:`input_type`, or any object with the
            fields the input type is read from (``header`` and the orientation
            and angular velocity fields, e.g. a view from
            :mod:`rotation_node.bag.cdr`).

        Returns
        -------
        list of (str, header, sequence of float)
            ``(output name, msg.header, values)`` for each output that could be
            computed, in the order of ``outputs``; empty when the message was
            dropped. ``values`` are the output message's numbers in definition
            order: ``(x, y, z[, w])`` of the stamped outputs, ``data`` of the
            Float64MultiArray ones (their layout is :data:`MULTI_ARRAY_LAYOUTS`).
            Never raises on bad data.

        """
        self.stats.received += 1
        try:
            outputs = self._converted(msg)
        except _Dropped as drop:
            self.stats.dropped[drop.reason] += 1
            self._report(drop.reason, str(drop))
            return []
        except ValueError as exc:   # a conversion rejected a value the checks let through
            self.stats.dropped[CONVERSION_ERROR] += 1
            self._report(CONVERSION_ERROR, f'message dropped: {exc}')
            return []
        self.stats.published += len(outputs)
        return outputs

    def _report(self, reason, detail):
        if self._on_issue is not None:
            self._on_issue(reason, detail)

    def _skip(self, reason, detail):
        self.stats.skipped[reason] += 1
        self._report(reason, detail)

    def _converted(self, msg):
        params, wanted = self.params, self._outputs
        header = msg.header
        q = self._orientation(msg)
        omega = self._angular_velocity(msg, header, q)
        values = {}
        if q is not None:
            if 'quaternion' in wanted or 'quaternion_rate' in wanted:
                q_out = values['quaternion'] = self._sign_continuous(
                    conversions.canonical_quaternion(q))
            if 'euler' in wanted or 'euler_rates' in wanted:
                angles = conversions.euler_from_quaternion(
                    q, params.euler_sequence, degrees=params.euler_degrees)
                margin = conversions.euler_singularity_margin(q, params.euler_sequence)
                self.stats.near_singular += bool(margin < params.euler_singularity_threshold)
                if 'euler' in wanted:
                    values['euler'] = self._unwrapped_euler(angles.tolist())
            if 'rotation_vector' in wanted:
                values['rotation_vector'] = conversions.rotation_vector_from_quaternion(q)
            if 'axis_angle' in wanted:
                axis, angle = conversions.axis_angle_from_quaternion(q)
                values['axis_angle'] = (*axis.tolist(), float(angle))
            if 'matrix' in wanted:
                values['matrix'] = conversions.matrix_from_quaternion(q).ravel().tolist()
        if omega is not None:
            values['angular_velocity'] = omega
            frame = params.angular_velocity_output_frame
            if q is not None and 'euler_rates' in wanted:
                rates = self._euler_rates(angles, omega)
                if rates is not None:
                    values['euler_rates'] = rates
            if q is not None and 'quaternion_rate' in wanted:
                values['quaternion_rate'] = kinematics.quaternion_derivative(
                    q_out, omega, frame=frame)
        if q is None and len(values) < len(wanted):
            self._skip(ORIENTATION_UNKNOWN,
                       'orientation unknown (Imu orientation_covariance[0] == -1): '
                       'outputs that need it skipped')
        return [(name, header, values[name]) for name in wanted if name in values]

    def _orientation(self, msg):
        """Return the input orientation as a quaternion array (any scale), or None if unknown."""
        source = self._input.orientation(msg)
        if source is None:
            return None
        form = self._input.orientation_form
        values = _xyzw(source) if form == 'quaternion' else _xyz(source)
        if not all(map(math.isfinite, values)):
            raise _Dropped(NON_FINITE_ORIENTATION,
                           f'message dropped: {form} {values} has a NaN or Inf component')
        if form == 'euler':
            return conversions.quaternion_from_euler(
                values, self.params.euler_sequence, degrees=self.params.euler_degrees)
        if form == 'rotation_vector':
            return conversions.quaternion_from_rotation_vector(values)
        norm = math.hypot(*values)
        if norm == 0.0:
            raise _Dropped(ZERO_QUATERNION, 'message dropped: zero quaternion')
        if abs(norm - 1.0) > self.params.quaternion_norm_tolerance:
            self.stats.normalised += 1
            self._report(NON_UNIT_QUATERNION,
                         f'quaternion {values} has norm {norm:.9g}; normalised')
        return np.array(values)

    def _angular_velocity(self, msg, header, q):
        """
        Return the angular velocity (rad/s) in the output frame, or None if unavailable.

        From the input where it carries one, otherwise by finite difference of the
        current and previous orientations (this updates the finite-difference state).
        """
        if not self._needs_angular_velocity:
            return None
        frame = self.params.angular_velocity_output_frame
        source = self._input.angular_velocity
        measured = None if source is None else source(msg)
        if measured is not None:
            omega = _xyz(measured)
            if not all(map(math.isfinite, omega)):
                self._skip(NON_FINITE_ANGULAR_VELOCITY,
                           f'angular velocity {omega} has a NaN or Inf component: '
                           'angular-velocity outputs skipped')
                return None
            if self.params.angular_velocity_input_frame == frame:
                return np.array(omega)
            if q is None:
                return None   # the frame change needs the orientation
            if frame == 'world':
                return conversions.rotate_vector(q, omega)
            return conversions.rotate_vector(conversions.quaternion_conjugate(q), omega)
        if q is None:
            return None
        stamp_ns = _stamp_ns(header)
        previous_q, previous_ns = self._previous_quaternion, self._previous_stamp_ns
        self._previous_quaternion, self._previous_stamp_ns = q, stamp_ns
        if previous_q is None:
            return None
        if stamp_ns <= previous_ns:
            self._skip(TIMESTAMP_NOT_INCREASING,
                       f'stamp {_seconds(stamp_ns)} s is not after the previous '
                       f'{_seconds(previous_ns)} s: finite-difference outputs skipped')
            return None
        # Difference of integer nanoseconds: exact, unlike a difference of float seconds.
        times = (0.0, (stamp_ns - previous_ns) * 1e-9)
        return kinematics.angular_velocity_from_quaternions(
            np.stack((previous_q, q)), times, frame=frame)[0]

    def _euler_rates(self, angles, omega):
        """Return the Euler-angle rates, or None within the singularity threshold."""
        params = self.params
        with warnings.catch_warnings():   # counted and reported below instead
            warnings.simplefilter('ignore', kinematics.EulerSingularityWarning)
            rates = kinematics.euler_rates_from_angular_velocity(
                angles, omega, params.euler_sequence, frame=params.angular_velocity_output_frame,
                degrees=params.euler_degrees,
                singularity_threshold=params.euler_singularity_threshold)
        if math.isnan(rates[0]):
            self._skip(EULER_RATES_NEAR_SINGULAR,
                       f'within {params.euler_singularity_threshold:g} rad of gimbal lock '
                       f'of {params.euler_sequence!r}: euler_rates skipped (unbounded there)')
            return None
        return rates

    def _sign_continuous(self, q):
        """Return q or -q, whichever is nearer the previous output (with quaternion.continuity)."""
        if not self.params.quaternion_continuity:
            return q
        previous = self._previous_output_quaternion
        if previous is not None and np.dot(previous, q) < 0.0:
            q = -q
        self._previous_output_quaternion = q
        return q

    def _unwrapped_euler(self, angles):
        """Return the Euler angles, first and third unwrapped against the previous output."""
        first, second, third = angles
        previous = self._previous_euler
        if self.params.euler_unwrap and previous is not None:
            first = _unwrapped(first, previous[0], self._angle_period)
            third = _unwrapped(third, previous[2], self._angle_period)
        self._previous_euler = (first, second, third)
        return self._previous_euler


def _vector3_stamped(header, values):
    message = Vector3Stamped()
    message.header = header
    vector = message.vector
    vector.x, vector.y, vector.z = (float(v) for v in values)
    return message


def _quaternion_stamped(header, values):
    message = QuaternionStamped()
    message.header = header
    quaternion = message.quaternion
    quaternion.x, quaternion.y, quaternion.z, quaternion.w = (float(v) for v in values)
    return message


def _multi_array(layout):
    def build(header, values):   # Float64MultiArray has no header
        message = Float64MultiArray()
        message.layout = layout
        message.data = values
        return message
    return build


_BUILDERS = {
    'quaternion': _quaternion_stamped,
    'euler': _vector3_stamped,
    'rotation_vector': _vector3_stamped,
    'axis_angle': _multi_array(MULTI_ARRAY_LAYOUTS['axis_angle']),
    'matrix': _multi_array(MULTI_ARRAY_LAYOUTS['matrix']),
    'angular_velocity': _vector3_stamped,
    'euler_rates': _vector3_stamped,
    'quaternion_rate': _quaternion_stamped,
}


def warm_up_conversions():
    """
    Run dummy samples of every input type through every output once.

    The conversions are numba-compiled on first use; calling this at start-up
    moves that one-off compilation out of the first real message's latency.
    """
    for input_type in INPUT_TYPES:
        for frame in ('body', 'world'):
            params = NodeParameters(
                input_type=input_type, outputs=OUTPUTS, angular_velocity_output_frame=frame)
            pipeline = ConversionPipeline(params)
            for nanosec in (0, 1_000_000):
                msg = pipeline.input_type()
                msg.header.stamp.nanosec = nanosec
                pipeline.process(msg)
