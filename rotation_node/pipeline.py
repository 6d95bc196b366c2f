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

The input and output types are declared in :mod:`rotation_node.registry`: an
input message is read into samples (header, orientation, optional angular
velocity and covariance), each sample passes the input-stage transforms of
:data:`SAMPLE_TRANSFORMS`, and then the named per-message values an output
needs (:data:`rotation_node.registry.PIPELINE_VALUES`) are computed once each,
in the order of :data:`VALUES`, each from the values it depends on; a value is
unavailable (None) when one it requires is. Each configured output is then
computed from its values, or skipped when one is unavailable.

The finite-difference angular velocity is the constant rate that carries the
previous orientation into the current one over the interval between their
stamps: exact for a constant rate, second-order accurate at the interval's
midpoint, so half a sample period older than the stamp it is published with.
It needs increasing stamps: the first message, and a message whose stamp is
not after the previous one, produce no finite-difference outputs.
"""
from collections import Counter
from dataclasses import dataclass, field
import math
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Tuple
import warnings

import numpy as np
from rotation_node import conversions, covariance, kinematics, registry
from rotation_node.errors import ParameterError
from rotation_node.frames import FrameConversion
from rotation_node.mounting import Mounting
from rotation_node.parameters import INPUT_TYPES, NodeParameters, OUTPUTS
from rotation_node.registry import (
    ANGULAR_VELOCITY, EULER_ANGLES, EULER_COVARIANCE, EULER_RATES, ORIENTATION,
    ORIENTATION_COVARIANCE, OUTPUT_QUATERNION, PUBLISHED_EULER, Sample)
from rotation_node.wire.stamps import header_stamp_ns, seconds_text

# Reasons for dropping a whole message (counted in PipelineStats.dropped).
NON_FINITE_ORIENTATION = 'non_finite_orientation'
CONVERSION_ERROR = 'conversion_error'
# Reasons for skipping some outputs of a message (counted in PipelineStats.skipped).
ORIENTATION_UNKNOWN = 'orientation_unknown'
ZERO_QUATERNION = 'zero_quaternion'   # the other form of "orientation not estimated"
NON_FINITE_ANGULAR_VELOCITY = 'non_finite_angular_velocity'
TIMESTAMP_NOT_INCREASING = 'timestamp_not_increasing'
EULER_RATES_NEAR_SINGULAR = 'euler_rates_near_singular'
COVARIANCE_UNKNOWN = 'covariance_unknown'
NON_FINITE_COVARIANCE = 'non_finite_covariance'
COVARIANCE_TOO_LARGE = 'covariance_too_large'
INVALID_COVARIANCE = 'invalid_covariance'
EULER_COVARIANCE_NEAR_SINGULAR = 'euler_covariance_near_singular'
EULER_COVARIANCE_NOT_LINEAR = 'euler_covariance_not_linear'
# A message whose quaternion was normalised (counted in PipelineStats.normalised).
NON_UNIT_QUATERNION = 'non_unit_quaternion'
DROP_REASONS = (NON_FINITE_ORIENTATION, CONVERSION_ERROR)
SKIP_REASONS = (ORIENTATION_UNKNOWN, ZERO_QUATERNION, NON_FINITE_ANGULAR_VELOCITY,
                TIMESTAMP_NOT_INCREASING, EULER_RATES_NEAR_SINGULAR, COVARIANCE_UNKNOWN,
                NON_FINITE_COVARIANCE, COVARIANCE_TOO_LARGE, INVALID_COVARIANCE,
                EULER_COVARIANCE_NEAR_SINGULAR, EULER_COVARIANCE_NOT_LINEAR)
# What the pipeline reports when a sample's orientation is unknown, by the form it took.
ORIENTATION_UNKNOWN_DETAIL = ('orientation unknown (Imu orientation_covariance[0] == -1): '
                              'outputs that need it skipped')
ZERO_QUATERNION_DETAIL = ('zero quaternion (0, 0, 0, 0): orientation not estimated; outputs '
                          'that need it skipped')

SAMPLE_TRANSFORMS: List[Callable[[NodeParameters], Optional[Callable[[Sample], Sample]]]] = []
"""
Input-stage transforms: ``factory(params) -> transform(sample) -> sample``, or None.

Each factory is called once per pipeline; the transforms it returns are applied,
in this order, to every sample before any value is computed from it (e.g. a
change of the input's world or body frame convention). None means the parameters
need no transform.
"""


def mounting_of(params: NodeParameters) -> Optional[Mounting]:
    """
    Return the ``mounting.*`` parameters' :class:`~rotation_node.mounting.Mounting`, or None.

    None when it is the identity: the outputs are then those of a pipeline
    without mounting, bit for bit. Applied after the frame conventions
    (``frames.*``), in the output's conventions: ``R_out = W (F_w R_in F_b) M``.
    """
    if params.mounting_tf_sensor_frame or params.mounting_tf_body_frame:
        raise ParameterError('mounting.tf_sensor_frame and mounting.tf_body_frame: the mounting '
                             'must be read from /tf_static first (static_mounting.resolved)')
    mounting = Mounting.from_parts(
        params.mounting_body_rotation, params.mounting_world_rotation,
        params.mounting_yaw_offset, params.mounting_magnetic_declination)
    return None if mounting.is_identity else mounting


def input_message_type(input_type: str) -> type:
    """Return the message class subscribed for an ``input_type`` value."""
    return registry.INPUTS[input_type].message_class


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
        Input samples that produced no output because they were invalid, by reason
        (``non_finite_orientation``, ``conversion_error``).
    skipped : collections.Counter
        Input samples of which some outputs could not be computed, by reason
        (:data:`SKIP_REASONS`: ``orientation_unknown``, ``zero_quaternion``,
        ``non_finite_angular_velocity``, ``timestamp_not_increasing``,
        ``euler_rates_near_singular``, ``covariance_unknown``,
        ``non_finite_covariance``, ``covariance_too_large``, ``invalid_covariance``,
        ``euler_covariance_near_singular``, ``euler_covariance_not_linear``).
    normalised : int
        Input quaternions further than ``quaternion.norm_tolerance`` from unit length.
    near_singular : int
        Samples whose middle Euler angle was within ``euler.singularity_threshold``
        of gimbal lock (counted when an Euler output is enabled).

    """

    received: int = 0
    published: int = 0
    dropped: Counter = field(default_factory=Counter)
    skipped: Counter = field(default_factory=Counter)
    normalised: int = 0
    near_singular: int = 0


class _Dropped(Exception):
    """Internal: the current sample is invalid and produces no output."""

    def __init__(self, reason, detail):
        super().__init__(detail)
        self.reason = reason


class Value(NamedTuple):
    """
    How the pipeline computes one named per-message value.

    Attributes
    ----------
    name : str
        One of :data:`rotation_node.registry.PIPELINE_VALUES`.
    requires : tuple of str
        Values that must be available; without one, this value is unavailable.
    uses : tuple of str
        Values read when available (computed before this one, not required).
    method : str
        Name of the :class:`ConversionPipeline` method
        ``method(sample, values) -> value or None`` that computes it.
    reads : tuple of str
        The optional :class:`~rotation_node.registry.Sample` fields it reads
        (``'angular_velocity'``, ``'covariance'``): input messages are read into
        them only when a value computed reads them.

    """

    name: str
    requires: Tuple[str, ...]
    uses: Tuple[str, ...]
    method: str
    reads: Tuple[str, ...] = ()


VALUES = (
    Value(ORIENTATION, (), (), '_orientation'),
    Value(ANGULAR_VELOCITY, (), (ORIENTATION,), '_angular_velocity', ('angular_velocity',)),
    Value(OUTPUT_QUATERNION, (ORIENTATION,), (), '_output_quaternion'),
    Value(EULER_ANGLES, (ORIENTATION,), (), '_euler_angles'),
    Value(PUBLISHED_EULER, (EULER_ANGLES,), (), '_published_euler'),
    Value(EULER_RATES, (EULER_ANGLES, ANGULAR_VELOCITY), (), '_euler_rates'),
    Value(ORIENTATION_COVARIANCE, (ORIENTATION,), (), '_orientation_covariance', ('covariance',)),
    Value(EULER_COVARIANCE, (EULER_ANGLES, ORIENTATION_COVARIANCE), (), '_euler_covariance'),
)
"""The per-message values, each after those it requires or uses."""

_VALUES_BY_NAME = {value.name: value for value in VALUES}


def _needed_values(outputs):
    """Return the values the outputs need, with what they depend on, in :data:`VALUES` order."""
    needed = {ORIENTATION}   # always read: an invalid orientation drops the message
    pending = [need for name in outputs for need in registry.OUTPUTS[name].needs]
    while pending:
        name = pending.pop()
        if name not in needed:
            needed.add(name)
            pending.extend(_VALUES_BY_NAME[name].requires)
    return [value for value in VALUES if value.name in needed]


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
        Called as ``on_issue(reason, detail)`` for every dropped sample, skipped
        output group and normalised quaternion (``detail`` is a sentence for a log).
    stats : PipelineStats, optional
        Counters to continue (e.g. across a parameter change); new ones by default.

    Notes
    -----
    The per-stream state (previous orientation and stamp, previous Euler angles,
    previous quaternion, and any state of the input type's sample stream) starts
    empty: create a new pipeline per input stream. Outputs share the header
    object of the sample they come from (the input message's ``header``).

    """

    def __init__(self, params: NodeParameters, *, on_issue: Optional[Callable] = None,
                 stats: Optional[PipelineStats] = None):
        self.params = params
        self.stats = PipelineStats() if stats is None else stats
        self._on_issue = on_issue
        self._input = registry.INPUTS[params.input_type]
        self._outputs = [registry.OUTPUTS[name] for name in params.outputs]
        self._builders = {output.name: output.message.build for output in self._outputs}
        plan = _needed_values(params.outputs)
        reads = {field for value in plan for field in value.reads}
        sample_fields = {'angular_velocity': 'angular_velocity' in reads,
                         'covariance': 'covariance' in reads}
        self._samples = self._input.sample_stream(params, **sample_fields,
                                                  report=self._stream_dropped)
        self._transforms = [transform for transform in
                            (factory(params) for factory in SAMPLE_TRANSFORMS)
                            if transform is not None]
        # A plain input without transforms: one sample per message, read directly.
        self._read = (self._input.sample_reader(**sample_fields)
                      if self._input.stream is None and not self._transforms else None)
        self._plan = [(value.name, value.requires, getattr(self, value.method))
                      for value in plan]
        self._output_plan = [(output.name, output.needs, output.compute)
                             for output in self._outputs]
        frames = FrameConversion(params.frames_input_world, params.frames_input_body,
                                 params.frames_output_world, params.frames_output_body)
        self._frames = None if frames.is_identity else frames
        self._mounting = mounting_of(params)
        self._angle_period = 360.0 if params.euler_degrees else 2.0 * math.pi
        # Per-stream state.
        self._previous_quaternion = None     # last orientation, for the finite difference
        self._previous_stamp_ns = None
        self._previous_output_quaternion: Optional[np.ndarray] = None   # quaternion.continuity
        self._previous_euler: Optional[Tuple[float, float, float]] = None   # euler.unwrap

    @property
    def input_type(self) -> type:
        """Message class of the input."""
        return self._input.message_class

    @property
    def drop_reasons(self) -> Tuple[str, ...]:
        """Reasons counted in ``stats.dropped``: :data:`DROP_REASONS` and the input type's."""
        return DROP_REASONS + self._input.drop_reasons

    @property
    def output_types(self) -> Dict[str, type]:
        """``{output name: message class}`` for the configured outputs, in order."""
        return {output.name: output.message_class for output in self._outputs}

    def process(self, msg: Any, topic: str = registry.INPUT_TOPIC.name) -> list:
        """
        Convert one input message.

        Parameters
        ----------
        msg : message of class :attr:`input_type`
            The input message.
        topic : str, optional
            The input type's relative topic the message came on (input types
            with several topics tell them apart by it).

        Returns
        -------
        list of (str, message)
            ``(output name, message)`` for each output that could be computed, in
            the order of ``outputs`` (for each sample the message gave); empty
            when the message was dropped. Never raises on bad data.

        """
        builders = self._builders
        return [(name, builders[name](header, numbers))
                for name, header, numbers in self.process_values(msg, topic)]

    def process_values(self, msg: Any, topic: str = registry.INPUT_TOPIC.name) -> list:
        """
        Convert one input message into the numbers of the output messages.

        :meth:`process` without building the messages, for callers that encode
        them themselves (``rotation_bag convert``); same outputs, same counts.

        Parameters
        ----------
        msg : object
            A message of class :attr:`input_type`, or any object with the
            fields the input type is read from (``header`` and the orientation
            and angular velocity fields, e.g. a view from
            :mod:`rotation_node.wire.cdr`).
        topic : str, optional
            As for :meth:`process`.

        Returns
        -------
        list of (str, header, sequence of float)
            ``(output name, header, numbers)`` for each output that could be
            computed, in the order of ``outputs`` (for each sample the message
            gave); empty when the message was dropped. ``numbers`` are what the
            output's :class:`~rotation_node.registry.OutputMessage` builds the
            message from: ``(x, y, z[, w])`` of the stamped outputs, ``data`` of
            the Float64MultiArray ones. Never raises on bad data.

        """
        self.stats.received += 1
        if self._read is not None:   # a plain input without transforms: one sample
            return self._outputs_of(self._read(msg))
        samples = self._samples(topic, msg)
        for transform in self._transforms:
            samples = [transform(sample) for sample in samples]
        results = []
        for sample in samples:
            results += self._outputs_of(sample)
        return results

    def _stream_dropped(self, reason, detail):
        """Count what the input type's stream could not use (its own reasons)."""
        self.stats.dropped[reason] += 1
        self._report(reason, detail)

    def _report(self, reason, detail):
        if self._on_issue is not None:
            self._on_issue(reason, detail)

    def _skip(self, reason, detail):
        self.stats.skipped[reason] += 1
        self._report(reason, detail)

    def _outputs_of(self, sample):
        """
        Return the outputs of one sample: every needed value once, then each output from them.

        Counts the sample's outputs, or the sample as dropped (then returns none).
        """
        try:
            values: Dict[str, Any] = {}
            for name, requires, compute in self._plan:
                for required in requires:
                    if values[required] is None:
                        values[name] = None
                        break
                else:
                    values[name] = compute(sample, values)
            params, header, outputs = self.params, sample.header, []
            for name, needs, compute in self._output_plan:
                if compute is None:   # the one value needed, as it is
                    value = values[needs[0]]
                    if value is not None:
                        outputs.append((name, header, value))
                    continue
                needed = []
                for need in needs:
                    value = values[need]
                    if value is None:
                        break
                    needed.append(value)
                else:
                    outputs.append((name, header, compute(params, *needed)))
        except _Dropped as drop:
            self.stats.dropped[drop.reason] += 1
            self._report(drop.reason, str(drop))
            return []
        except ValueError as exc:   # a conversion rejected a value the checks let through
            self.stats.dropped[CONVERSION_ERROR] += 1
            self._report(CONVERSION_ERROR, f'message dropped: {exc}')
            return []
        if values[ORIENTATION] is None and len(outputs) < len(self._outputs):
            if sample.orientation is None:
                self._skip(ORIENTATION_UNKNOWN, ORIENTATION_UNKNOWN_DETAIL)
            else:   # the quaternion was (0, 0, 0, 0)
                self._skip(ZERO_QUATERNION, ZERO_QUATERNION_DETAIL)
        self.stats.published += len(outputs)
        return outputs

    # The per-message values, in the order of VALUES -----------------------------------

    def _orientation(self, sample, values):
        """
        Return the input orientation as a quaternion array (any scale), or None if unknown.

        Unknown: the message says so (Imu ``orientation_covariance[0] == -1``), or its
        quaternion is (0, 0, 0, 0), the other common form of "not estimated".
        """
        orientation = sample.orientation
        if orientation is None:
            return None
        form = self._input.orientation_form
        if not all(map(math.isfinite, orientation)):
            raise _Dropped(NON_FINITE_ORIENTATION,
                           f'message dropped: {form} {orientation} has a NaN or Inf component')
        if form == registry.EULER:
            q = conversions.quaternion_from_euler(
                orientation, self.params.euler_sequence, degrees=self.params.euler_degrees)
        elif form == registry.ROTATION_VECTOR:
            q = conversions.quaternion_from_rotation_vector(orientation)
        else:
            norm = math.hypot(*orientation)
            if norm == 0.0:
                return None   # counted once the outputs that need it are known
            if abs(norm - 1.0) > self.params.quaternion_norm_tolerance:
                self.stats.normalised += 1
                self._report(NON_UNIT_QUATERNION,
                             f'quaternion {orientation} has norm {norm:.9g}; normalised')
            q = np.array(orientation)
        if self._frames is not None:
            q = self._frames.quaternion(q)
        return q if self._mounting is None else self._mounting.quaternion(q)

    def _angular_velocity(self, sample, values):
        """
        Return the angular velocity (rad/s) in the output frame, or None if unavailable.

        From the sample where it carries one, otherwise by finite difference of
        this sample's and the previous sample's orientations.
        """
        frame = self.params.angular_velocity_output_frame
        q = values[ORIENTATION]
        omega = sample.angular_velocity
        if omega is not None:
            if not all(map(math.isfinite, omega)):
                self._skip(NON_FINITE_ANGULAR_VELOCITY,
                           f'angular velocity {omega} has a NaN or Inf component: '
                           'angular-velocity outputs skipped')
                return None
            input_frame = self.params.angular_velocity_input_frame
            if self._frames is not None:
                omega = (self._frames.world_vector(omega) if input_frame == 'world'
                         else self._frames.body_vector(omega))
            if self._mounting is not None:
                omega = self._mounting.vector(omega, input_frame)
            if input_frame == frame:
                return np.array(omega)
            if q is None:
                return None   # the frame change needs the orientation
            if frame == 'world':
                return conversions.rotate_vector(q, omega)
            return conversions.rotate_vector(conversions.quaternion_conjugate(q), omega)
        if q is None:
            return None
        return self._finite_difference(q, header_stamp_ns(sample.header))

    def _finite_difference(self, q, stamp_ns):
        """Return the rate from the previous orientation to ``q``, which becomes the previous."""
        previous_q, previous_ns = self._previous_quaternion, self._previous_stamp_ns
        self._previous_quaternion, self._previous_stamp_ns = q, stamp_ns
        if previous_q is None:
            return None
        if stamp_ns <= previous_ns:
            self._skip(TIMESTAMP_NOT_INCREASING,
                       f'stamp {seconds_text(stamp_ns)} s is not after the previous '
                       f'{seconds_text(previous_ns)} s: finite-difference outputs skipped')
            return None
        # Difference of integer nanoseconds: exact, unlike a difference of float seconds.
        times = (0.0, (stamp_ns - previous_ns) * 1e-9)
        return kinematics.angular_velocity_from_quaternions(
            np.stack((previous_q, q)), times, frame=self.params.angular_velocity_output_frame)[0]

    def _output_quaternion(self, sample, values):
        """Return the unit output quaternion: w >= 0, or with continuity nearer the previous."""
        q = conversions.canonical_quaternion(values[ORIENTATION])
        if not self.params.quaternion_continuity:
            return q
        previous = self._previous_output_quaternion
        if previous is not None and np.dot(previous, q) < 0.0:
            q = -q
        self._previous_output_quaternion = q
        return q

    def _euler_angles(self, sample, values):
        """Return the Euler angles of the orientation; counts a near-singular sample."""
        params, q = self.params, values[ORIENTATION]
        angles = conversions.euler_from_quaternion(
            q, params.euler_sequence, degrees=params.euler_degrees)
        margin = conversions.euler_singularity_margin(q, params.euler_sequence)
        self.stats.near_singular += bool(margin < params.euler_singularity_threshold)
        return angles

    def _published_euler(self, sample, values):
        """Return the Euler angles, first and third unwrapped against the previous published."""
        first, second, third = values[EULER_ANGLES].tolist()
        previous = self._previous_euler
        if self.params.euler_unwrap and previous is not None:
            first = _unwrapped(first, previous[0], self._angle_period)
            third = _unwrapped(third, previous[2], self._angle_period)
        self._previous_euler = (first, second, third)
        return self._previous_euler

    def _euler_rates(self, sample, values):
        """Return the Euler-angle rates, or None within the singularity threshold."""
        params = self.params
        with warnings.catch_warnings():   # counted and reported below instead
            warnings.simplefilter('ignore', kinematics.EulerSingularityWarning)
            rates = kinematics.euler_rates_from_angular_velocity(
                values[EULER_ANGLES], values[ANGULAR_VELOCITY], params.euler_sequence,
                frame=params.angular_velocity_output_frame, degrees=params.euler_degrees,
                singularity_threshold=params.euler_singularity_threshold)
        if math.isnan(rates[0]):
            self._skip(EULER_RATES_NEAR_SINGULAR,
                       f'within {params.euler_singularity_threshold:g} rad of gimbal lock '
                       f'of {params.euler_sequence!r}: euler_rates skipped (unbounded there)')
            return None
        return rates

    def _orientation_covariance(self, sample, values):
        """
        Return the input's rotation-vector covariance in the output frames, or None if unknown.

        About the world axes (``covariance.frame`` fixed) or the body axes (body).
        """
        block = sample.covariance
        if block is None or not any(block):
            self._skip(COVARIANCE_UNKNOWN,
                       'orientation covariance unknown (all zeros, or none in this input '
                       'type): uncertainty outputs skipped')
            return None
        if not all(map(math.isfinite, block)):
            self._skip(NON_FINITE_COVARIANCE,
                       f'orientation covariance {block} has a NaN or Inf element: '
                       'uncertainty outputs skipped')
            return None
        if max(block[0], block[4], block[8]) > covariance.MAX_ROTATION_VECTOR_VARIANCE:
            self._skip(COVARIANCE_TOO_LARGE,
                       f'orientation covariance {block} has a variance above pi^2 rad^2 '
                       '(a standard deviation beyond pi: no orientation information, as '
                       'drivers mark "unknown"): uncertainty outputs skipped')
            return None
        defect = covariance.covariance_defect(block)
        if defect is not None:
            self._skip(INVALID_COVARIANCE,
                       f'orientation covariance {block} is {defect}, not a covariance: '
                       'uncertainty outputs skipped')
            return None
        sigma = np.array(block).reshape(3, 3)
        fixed = self.params.covariance_frame == 'fixed'
        if self._frames is not None:
            sigma = (self._frames.world_covariance(sigma) if fixed
                     else self._frames.body_covariance(sigma))
        if self._mounting is not None:
            sigma = (self._mounting.world_covariance(sigma) if fixed
                     else self._mounting.body_covariance(sigma))
        return sigma

    def _euler_covariance(self, sample, values):
        """Return the first-order Euler covariance; None near gimbal lock or past linearity."""
        params = self.params
        angles, sigma = values[EULER_ANGLES], values[ORIENTATION_COVARIANCE]
        with warnings.catch_warnings():   # counted and reported below instead
            warnings.simplefilter('ignore', kinematics.EulerSingularityWarning)
            result = covariance.euler_covariance_from_rotation_vector_covariance(
                angles, sigma, params.euler_sequence,
                'world' if params.covariance_frame == 'fixed' else 'body',
                degrees=params.euler_degrees,
                singularity_threshold=params.euler_singularity_threshold)
        if math.isnan(result[0, 0]):
            self._skip(EULER_COVARIANCE_NEAR_SINGULAR,
                       f'within {params.euler_singularity_threshold:g} rad of gimbal lock '
                       f'of {params.euler_sequence!r}: uncertainty outputs skipped (unbounded '
                       'there)')
            return None
        # sigma_max^2 <= trace: only above it can the ratio exceed the limit (saves eigvalsh)
        limit = params.covariance_max_linearisation_ratio * float(
            conversions.euler_singularity_margin(values[ORIENTATION], params.euler_sequence))
        if np.trace(sigma) > limit * limit:
            ratio = float(covariance.euler_linearisation_ratio(
                angles, sigma, params.euler_sequence, degrees=params.euler_degrees))
            if not ratio <= params.covariance_max_linearisation_ratio:
                self._skip(EULER_COVARIANCE_NOT_LINEAR,
                           f'orientation standard deviation is {ratio:.3g} x its distance from '
                           f'gimbal lock of {params.euler_sequence!r}, more than '
                           'covariance.max_linearisation_ratio = '
                           f'{params.covariance_max_linearisation_ratio:g}: the first-order '
                           'Euler covariance would be wrong; uncertainty outputs skipped')
                return None
        # A valid input gives a finite, non-negative diagonal; rounding at the edge of
        # positive semi-definiteness may not: never a NaN standard deviation.
        if not (np.isfinite(result).all() and (np.diagonal(result) >= 0.0).all()):
            self._skip(INVALID_COVARIANCE,
                       f'the Euler covariance of orientation covariance {tuple(sigma.ravel())} '
                       'is not positive semi-definite (rounding at its edge): uncertainty '
                       'outputs skipped')
            return None
        return result


def warm_up_conversions() -> None:
    """
    Run dummy samples of every input type through every output once.

    The conversions are numba-compiled on first use; calling this at start-up
    moves that one-off compilation out of the first real message's latency.
    """
    for input_type in INPUT_TYPES:
        if registry.INPUTS[input_type].stream is not None:
            continue   # its samples come from its own topics; the forms it uses are warmed up
        for frame in ('body', 'world'):
            params = NodeParameters(
                input_type=input_type, outputs=OUTPUTS, angular_velocity_output_frame=frame)
            pipeline = ConversionPipeline(params)
            for nanosec in (0, 1_000_000):
                msg = pipeline.input_type()
                msg.header.stamp.nanosec = nanosec
                pipeline.process(msg)
    angles = np.zeros(3)   # the input messages above carry no covariance
    covariance.euler_covariance_from_rotation_vector_covariance(angles, np.eye(3), 'xyz')
    covariance.euler_linearisation_ratio(angles, np.eye(3), 'xyz')
