"""
Conversion pipeline shared by the live node and ``rotation_bag convert``.

:class:`ConversionPipeline` turns the messages of one input stream into the
configured outputs: the named values they need are computed once each, in the
order of :data:`VALUES`, each unavailable (None) when one it requires is. Bad
data never raises: it is dropped or partly converted, counted in
:class:`PipelineStats` and reported with its text in :data:`REASONS`.

Each :class:`Value` declares its per-message form (the node) and beside it its
block form (a :class:`~rotation_node.sample_block.SampleBlock`: ``convert``).
Both share the :class:`StreamState`, counters and reports, so a stream may mix
them and gets the same numbers bit for bit and the same reports in the same
order. The per-message form is not a block of one: numpy's cost per call (150
us a message, against 10 us) is more than the node can spend.

The block form is exact: blocks stay below the conversions' batch schedules
(:data:`BLOCK_SAMPLES`: vectorised ``atan2`` may differ in the last bit); a rule
carried from sample to sample is one scalar ``@jit`` function, called per
message and in a kernel loop per block; the per-message norm test decides where
a block's estimate is in doubt. The finite-difference rate
(``kinematics.angular_velocity_from_quaternions``) needs increasing stamps.
"""
from collections import Counter
import dataclasses
from dataclasses import dataclass, field
import math
from operator import itemgetter
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Tuple
import warnings

import numpy as np
from rotation_node import conversions, covariance, kinematics, registry
from rotation_node.conversions.kernels import (
    BATCH_SAMPLES, FLAT_OUT, FLOAT, item_samples, jit, kernel)
from rotation_node.errors import ParameterError
from rotation_node.frames import FrameConversion
from rotation_node.mounting import Mounting
from rotation_node.parameters import NodeParameters
from rotation_node.registry import (
    ANGULAR_VELOCITY, EULER_ANGLES, EULER_COVARIANCE, EULER_RATES, ORIENTATION,
    ORIENTATION_COVARIANCE, OUTPUT_QUATERNION, PUBLISHED_EULER, Sample)
from rotation_node.sample_block import SampleBlock
from rotation_node.wire.stamps import header_stamp_ns, seconds_text

NON_FINITE_ORIENTATION = 'non_finite_orientation'
CONVERSION_ERROR = 'conversion_error'
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
NON_UNIT_QUATERNION = 'non_unit_quaternion'

# What a reason counts (the PipelineStats field).
DROPPED = 'dropped'         # the sample gave no output
SKIPPED = 'skipped'         # some outputs of the sample could not be computed
NORMALISED = 'normalised'   # the quaternion was normalised; every output computed


class Reason(NamedTuple):
    """A reason's counter in :class:`PipelineStats` and its report (a :meth:`str.format` text)."""

    kind: str   # DROPPED, SKIPPED or NORMALISED
    text: str


_UNCERTAINTY_SKIPPED = 'uncertainty outputs skipped'
REASONS: Dict[str, Reason] = {
    NON_FINITE_ORIENTATION: Reason(
        DROPPED, 'message dropped: {form} {values} has a NaN or Inf component'),
    CONVERSION_ERROR: Reason(DROPPED, 'message dropped: {error}'),
    ORIENTATION_UNKNOWN: Reason(
        SKIPPED, 'orientation unknown (Imu orientation_covariance[0] == -1): outputs that '
        'need it skipped'),
    ZERO_QUATERNION: Reason(
        SKIPPED, 'zero quaternion (0, 0, 0, 0): orientation not estimated; outputs that need '
        'it skipped'),
    NON_FINITE_ANGULAR_VELOCITY: Reason(
        SKIPPED, 'angular velocity {values} has a NaN or Inf component: angular-velocity '
        'outputs skipped'),
    TIMESTAMP_NOT_INCREASING: Reason(
        SKIPPED, 'stamp {stamp} s is not after the previous {previous} s: finite-difference '
        'outputs skipped'),
    EULER_RATES_NEAR_SINGULAR: Reason(
        SKIPPED, 'within {threshold:g} rad of gimbal lock of {sequence!r}: euler_rates '
        'skipped (unbounded there)'),
    COVARIANCE_UNKNOWN: Reason(
        SKIPPED, 'orientation covariance unknown (all zeros, or none in this input type): '
        + _UNCERTAINTY_SKIPPED),
    NON_FINITE_COVARIANCE: Reason(
        SKIPPED, 'orientation covariance {covariance} has a NaN or Inf element: '
        + _UNCERTAINTY_SKIPPED),
    COVARIANCE_TOO_LARGE: Reason(
        SKIPPED, 'orientation covariance {covariance} has a variance above pi^2 rad^2 (a '
        'standard deviation beyond pi: no orientation information, as drivers mark '
        '"unknown"): ' + _UNCERTAINTY_SKIPPED),
    INVALID_COVARIANCE: Reason(SKIPPED, '{covariance} is {problem}: ' + _UNCERTAINTY_SKIPPED),
    EULER_COVARIANCE_NEAR_SINGULAR: Reason(
        SKIPPED, 'within {threshold:g} rad of gimbal lock of {sequence!r}: '
        + _UNCERTAINTY_SKIPPED + ' (unbounded there)'),
    EULER_COVARIANCE_NOT_LINEAR: Reason(
        SKIPPED, 'orientation standard deviation is {ratio:.3g} x its distance from gimbal '
        'lock of {sequence!r}, more than covariance.max_linearisation_ratio = {limit:g}: the '
        'first-order Euler covariance would be wrong; ' + _UNCERTAINTY_SKIPPED),
    NON_UNIT_QUATERNION: Reason(NORMALISED, 'quaternion {values} has norm {norm:.9g}; normalised'),
}
"""Every reason the pipeline reports, in the order the node's diagnostics list them."""

DROP_REASONS = tuple(name for name, reason in REASONS.items() if reason.kind == DROPPED)
"""The reasons counted in ``PipelineStats.dropped`` (an input type adds its own)."""
SKIP_REASONS = tuple(name for name, reason in REASONS.items() if reason.kind == SKIPPED)
"""The reasons counted in ``PipelineStats.skipped``."""

BLOCK_SAMPLES = BATCH_SAMPLES - 1

# Input-stage transforms: factory(params) -> transform(sample) -> sample, or None (none
# needed); applied in order to every sample before any value. Not in the block form.
SAMPLE_TRANSFORMS: List[Callable[[NodeParameters], Optional[Callable[[Sample], Sample]]]] = []


def mounting_of(params: NodeParameters) -> Optional[Mounting]:
    """
    Return the ``mounting.*`` parameters' :class:`~rotation_node.mounting.Mounting`, or None.

    None when it is the identity (outputs bit for bit those without mounting).
    Applied after the frame conventions: ``R_out = W (F_w R_in F_b) M``.
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
    """Counters of a pipeline since it was created."""

    received: int = 0    # input messages
    published: int = 0   # output messages, all outputs together
    # samples without output, by reason (DROP_REASONS and the input type's own)
    dropped: Counter = field(default_factory=Counter)
    skipped: Counter = field(default_factory=Counter)   # samples with some outputs skipped
    normalised: int = 0   # quaternions beyond quaternion.norm_tolerance from unit length
    # within euler.singularity_threshold of gimbal lock (counted when an Euler output is on)
    near_singular: int = 0


@dataclass
class StreamState:
    """What the conversions over time carry from one sample to the next, in either form."""

    previous_quaternion: Optional[np.ndarray] = None   # the last one differenced
    previous_stamp_ns: Optional[int] = None            # its stamp
    previous_output_quaternion: Optional[np.ndarray] = None   # quaternion.continuity
    previous_euler: Optional[Tuple[float, float, float]] = None   # euler.unwrap


@dataclass
class BlockOutputs:
    """Per output, in the order of ``outputs``: which messages have it, and their numbers."""

    present: Dict[str, np.ndarray]   # bool (n,)
    numbers: Dict[str, np.ndarray]   # float64 (count, k): the per-message numbers, in order


class _Dropped(Exception):
    """The current sample is invalid and produces no output."""

    def __init__(self, reason, **fields):
        super().__init__(reason)
        self.reason = reason
        self.fields = fields


class Value(NamedTuple):
    """
    How the pipeline computes one named value, per message and (where it can) per block.

    ``method(sample, values) -> value or None`` computes it for one sample;
    ``block_method(block, rows, values, run) -> (available, array)`` for the
    ``rows`` of a block where what it requires is available, with the same
    numbers, state changes and reports (None: no block form). ``reads`` are
    the optional :class:`~rotation_node.registry.Sample` fields it reads: a
    message is read into them only when a value computed reads them.
    """

    name: str                    # one of registry.PIPELINE_VALUES
    requires: Tuple[str, ...]    # unavailable without these
    uses: Tuple[str, ...]        # read when available (computed before, not required)
    method: str
    block_method: Optional[str]
    reads: Tuple[str, ...] = ()


VALUES = (
    Value(ORIENTATION, (), (), '_orientation', '_orientation_block'),
    Value(ANGULAR_VELOCITY, (), (ORIENTATION,), '_angular_velocity', '_angular_velocity_block',
          ('angular_velocity',)),
    Value(OUTPUT_QUATERNION, (ORIENTATION,), (), '_output_quaternion',
          '_output_quaternion_block'),
    Value(EULER_ANGLES, (ORIENTATION,), (), '_euler_angles', '_euler_angles_block'),
    Value(PUBLISHED_EULER, (EULER_ANGLES,), (), '_published_euler', '_published_euler_block'),
    Value(EULER_RATES, (EULER_ANGLES, ANGULAR_VELOCITY), (), '_euler_rates',
          '_euler_rates_block'),
    Value(ORIENTATION_COVARIANCE, (ORIENTATION,), (), '_orientation_covariance', None,
          ('covariance',)),
    Value(EULER_COVARIANCE, (EULER_ANGLES, ORIENTATION_COVARIANCE), (), '_euler_covariance',
          None),
)
"""The named values, each after those it requires or uses."""

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


def output_has_block_form(name: str) -> bool:
    """Return whether every value the output needs has a block form, and its compute too."""
    output = registry.OUTPUTS[name]
    return ((output.compute is None or output.compute_takes_blocks)
            and all(value.block_method is not None for value in _needed_values((name,))))


def block_form_missing(params: NodeParameters) -> Optional[str]:
    """Return why the parameters' streams are converted message by message, or None."""
    input_type = registry.INPUTS[params.input_type]
    if input_type.stream is not None:
        return f'input type {params.input_type} reads samples from a stream of its own'
    if any(factory(params) is not None for factory in SAMPLE_TRANSFORMS):
        return 'an input-stage transform is configured'
    if not (params.frames_input_world == params.frames_output_world
            and params.frames_input_body == params.frames_output_body):
        return 'a frame conversion is configured'
    for name in params.outputs:
        if not output_has_block_form(name):
            return f'output {name} has no block form'
    return None


# The rules carried from sample to sample, each defined once: the per-message form calls
# them in Python, the block form in a kernel loop (interpreted or compiled, the same operations).

@jit
def _unwrapped(angle, previous, period):
    """Return ``angle`` shifted by the multiple of ``period`` nearest ``previous`` (ties even)."""
    return angle + period * round((previous - angle) / period)


@jit
def _turns_away(previous_x, previous_y, previous_z, previous_w, x, y, z, w):
    """Return whether ``(x, y, z, w)`` is published negated: its dot with the previous is < 0."""
    return previous_x * x + previous_y * y + previous_z * z + previous_w * w < 0.0


#: The previous output quaternion of the stream's first: a dot product of 0 turns nothing away.
_NO_QUATERNION = (0.0, 0.0, 0.0, 0.0)


@kernel(FLAT_OUT, FLOAT, FLOAT, FLOAT, returns=None)
def _unwrap_chain(angles, first, third, period):   # pragma: no cover
    """Unwrap Euler triples (flat) in place with ``_unwrapped``, from the previous first, third."""
    triples = item_samples(angles, 3)
    for s in range(triples.shape[0]):
        first = _unwrapped(triples[s, 0], first, period)
        third = _unwrapped(triples[s, 2], third, period)
        triples[s, 0], triples[s, 2] = first, third


@kernel(FLAT_OUT, FLOAT, FLOAT, FLOAT, FLOAT, returns=None)
def _sign_chain(q, x, y, z, w):   # pragma: no cover
    """Negate quaternions (flat) in place where ``_turns_away`` says, from the previous output."""
    fq = item_samples(q, 4)
    for s in range(fq.shape[0]):
        qx, qy, qz, qw = fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3]
        if _turns_away(x, y, z, w, qx, qy, qz, qw):
            qx, qy, qz, qw = -qx, -qy, -qz, -qw
            fq[s, 0], fq[s, 1], fq[s, 2], fq[s, 3] = qx, qy, qz, qw
        x, y, z, w = qx, qy, qz, qw


def _is_not_unit(norm, tolerance):
    """Return whether a quaternion of ``norm`` (``math.hypot``) is normalised and reported."""
    return abs(norm - 1.0) > tolerance


def _rates_between(previous_q, q, steps_ns, frame):
    """
    Return the constant rate carrying ``previous_q`` into ``q`` in ``steps_ns``: (3,), or (m, 3).

    Over a unit step, then divided by the step in seconds: exact integer steps.
    """
    pairs = np.array((previous_q, q)).swapaxes(0, -2)   # (2, 4) or (m, 2, 4): np.stack's, sooner
    rates = kinematics.angular_velocity_from_quaternions(pairs, (0.0, 1.0), frame=frame)
    return rates[..., 0, :] / (steps_ns * 1e-9)


class _BlockRun:
    """What a block changes: committed when the whole block is converted, else forgotten."""

    def __init__(self, state, n):
        self.state = dataclasses.replace(state)
        self.events: List[Tuple[int, str, Dict[str, Any]]] = []   # (sample, reason, fields)
        self.kept = np.ones(n, dtype=bool)     # not dropped
        self.zero = np.zeros(n, dtype=bool)    # a (0, 0, 0, 0) quaternion
        self.near_singular = 0

    def issue(self, sample, reason, **fields):
        """Report ``reason`` for ``sample`` once the block is converted."""
        self.events.append((sample, reason, fields))


class ConversionPipeline:
    """
    Convert the messages of one input stream into the configured outputs.

    ``on_issue(reason, detail)`` is called for every dropped sample, skipped
    output group and normalised quaternion (``detail``: a sentence for a log);
    ``stats`` are counters to continue (across a parameter change). The stream
    state starts empty: one pipeline per input stream. Outputs share the input
    message's header object. ``reads_angular_velocity``: samples and blocks
    must carry the input's angular velocity.
    """

    def __init__(self, params: NodeParameters, *, on_issue: Optional[Callable] = None,
                 stats: Optional[PipelineStats] = None):
        self.params = params
        self.stats = PipelineStats() if stats is None else stats
        self.state = StreamState()
        self.on_issue = on_issue
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
        self.block_form_missing = block_form_missing(params)
        self._block_plan = (None if self.block_form_missing is not None else
                            [(value.name, value.requires, getattr(self, value.block_method))
                             for value in plan])
        self.reads_angular_velocity = (sample_fields['angular_velocity']
                                       and self._input.angular_velocity_field is not None)
        frames = FrameConversion(params.frames_input_world, params.frames_input_body,
                                 params.frames_output_world, params.frames_output_body)
        self._frames = None if frames.is_identity else frames
        self._mounting = mounting_of(params)
        self._angle_period = 360.0 if params.euler_degrees else 2.0 * math.pi

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
        Return ``[(output name, message)]`` of one input message (empty when dropped).

        In the order of ``outputs``, for each sample the message gave; ``topic`` is
        the input type's relative topic it came on. Never raises on bad data.
        """
        builders = self._builders
        return [(name, builders[name](header, numbers))
                for name, header, numbers in self.process_values(msg, topic)]

    def process_values(self, msg: Any, topic: str = registry.INPUT_TOPIC.name) -> list:
        """
        Return ``[(output name, header, numbers)]``: :meth:`process` without building messages.

        ``msg`` may be any object with the fields the input type reads (a
        :mod:`rotation_node.wire.cdr` view); ``numbers`` are what the output's
        :class:`~rotation_node.registry.OutputMessage` builds its message from.
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

    def process_block(self, block: SampleBlock) -> Optional[BlockOutputs]:
        """
        Convert a block of at most :data:`BLOCK_SAMPLES` samples: :meth:`process_values` of each.

        None when the block must go message by message (a conversion rejected a
        value): nothing was counted or changed then. ValueError without a block
        form or for a longer block.
        """
        plan = self._block_plan
        if plan is None:
            raise ValueError(f'pipeline: no block form ({self.block_form_missing})')
        n = len(block.stamp_ns)
        if n > BLOCK_SAMPLES:
            raise ValueError(f'block: at most {BLOCK_SAMPLES} samples, got {n}')
        run = _BlockRun(self.state, n)
        try:
            with np.errstate(all='ignore'):
                outputs, published = self._block_outputs(block, run, plan)
        except ValueError:   # a conversion rejected a value: the per-message form says which
            return None
        self.state = run.state
        stats = self.stats
        stats.received += n
        stats.published += published
        stats.near_singular += run.near_singular
        run.events.sort(key=itemgetter(0))   # stable: in each sample, in the order of VALUES
        for _, reason, fields in run.events:
            self._issue(reason, **fields)
        return outputs

    def drop_message(self, reason: str, **fields: Any) -> None:
        """Count and report a message the caller could not give the pipeline (undecodable)."""
        self.stats.received += 1
        self._issue(reason, **fields)

    def _issue(self, reason, **fields):
        """Count ``reason`` where :data:`REASONS` says, and report it with its text."""
        kind, text = REASONS[reason]
        if kind == NORMALISED:
            self.stats.normalised += 1
        else:
            getattr(self.stats, kind)[reason] += 1
        if self.on_issue is not None:
            self.on_issue(reason, text.format(**fields))

    def _stream_dropped(self, reason, detail):
        """Count what the input type's stream could not use (its own reasons)."""
        self.stats.dropped[reason] += 1
        if self.on_issue is not None:
            self.on_issue(reason, detail)

    def _unknown_orientation(self, zero):
        """Return the reason an unknown orientation skipped outputs: Imu's flag or all zeros."""
        return ZERO_QUATERNION if zero else ORIENTATION_UNKNOWN

    def _outputs_of(self, sample):
        """Return the outputs of one sample: every needed value once, then each output."""
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
            self._issue(drop.reason, **drop.fields)
            return []
        except ValueError as exc:   # a conversion rejected a value the checks let through
            self._issue(CONVERSION_ERROR, error=exc)
            return []
        if values[ORIENTATION] is None and len(outputs) < len(self._outputs):
            # None with an orientation: the quaternion was (0, 0, 0, 0)
            self._issue(self._unknown_orientation(sample.orientation is not None))
        self.stats.published += len(outputs)
        return outputs

    def _block_outputs(self, block, run, plan):
        """Return the block's outputs and their count: every needed value once, then outputs."""
        params, n = self.params, len(block.stamp_ns)
        values: Dict[str, Tuple[np.ndarray, np.ndarray]] = {}
        for name, requires, compute in plan:
            rows = run.kept
            for required in requires:
                rows = rows & values[required][0]
            values[name] = compute(block, rows, values, run)
        outputs = BlockOutputs({}, {})
        published = np.zeros(n, dtype=np.int64)
        for name, needs, compute in self._output_plan:
            present = run.kept.copy()
            for need in needs:
                present &= values[need][0]
            needed = [values[need][1][present] for need in needs]
            if compute is None:
                numbers = needed[0]
            elif present.any():
                numbers = compute(params, *needed)
            else:
                numbers = np.zeros((0, 1))
            outputs.present[name] = present
            outputs.numbers[name] = np.ascontiguousarray(numbers, dtype=np.float64)
            published += present
        unknown = run.kept & ~values[ORIENTATION][0] & (published < len(self._outputs))
        for s in np.flatnonzero(unknown).tolist():
            run.issue(s, self._unknown_orientation(run.zero[s]))
        return outputs, int(published.sum())

    # The values, in the order of VALUES: each one's per-message form, then its block form.

    def _orientation(self, sample, values):
        """Return the orientation as a quaternion (any scale); None if unknown (flag, or zero)."""
        orientation = sample.orientation
        if orientation is None:
            return None
        form = self._input.orientation_form
        if not all(map(math.isfinite, orientation)):
            raise _Dropped(NON_FINITE_ORIENTATION, form=form, values=orientation)
        if form != registry.QUATERNION:
            q = self._quaternion_from_input_form(orientation)
        else:
            norm = math.hypot(*orientation)
            if norm == 0.0:
                return None   # counted once the outputs that need it are known
            if _is_not_unit(norm, self.params.quaternion_norm_tolerance):
                self._issue(NON_UNIT_QUATERNION, values=orientation, norm=norm)
            q = np.array(orientation)
        if self._frames is not None:
            q = self._frames.quaternion(q)
        return q if self._mounting is None else self._mounting.quaternion(q)

    def _orientation_block(self, block, rows, values, run):
        """Return where the orientation is known and the quaternions (any norm); marks drops."""
        params, form = self.params, self._input.orientation_form
        orientation = block.orientation
        known = block.orientation_known
        finite = np.isfinite(orientation).all(axis=1)
        run.kept = ~known | finite
        for s in np.flatnonzero(~run.kept).tolist():
            run.issue(s, NON_FINITE_ORIENTATION, form=form,
                      values=tuple(orientation[s].tolist()))
        use = known & finite
        q = np.zeros((len(orientation), 4))
        if form != registry.QUATERNION:
            if use.any():
                q[use] = self._quaternion_from_input_form(orientation[use])
        else:
            run.zero = use & (orientation == 0.0).all(axis=1)
            use &= ~run.zero
            q[use] = orientation[use]
            # Where this estimate is not clearly within the tolerance, math.hypot decides
            # (and gives the reported norm), as for one sample.
            tolerance = params.quaternion_norm_tolerance
            estimate = np.sqrt(np.einsum('ij,ij->i', q, q))
            unclear = use & ~(np.abs(estimate - 1.0) <= tolerance - 1e-12)
            for s in np.flatnonzero(unclear).tolist():
                sample = tuple(orientation[s].tolist())
                norm = math.hypot(*sample)
                if _is_not_unit(norm, tolerance):
                    run.issue(s, NON_UNIT_QUATERNION, values=sample, norm=norm)
        if self._mounting is not None and use.any():
            q[use] = self._mounting.quaternion(q[use])
        return use, q

    def _quaternion_from_input_form(self, orientation):
        """Return the quaternions of Euler angles or rotation vectors: one (3,) or rows (n, 3)."""
        if self._input.orientation_form == registry.EULER:
            return conversions.quaternion_from_euler(
                orientation, self.params.euler_sequence, degrees=self.params.euler_degrees)
        return conversions.quaternion_from_rotation_vector(orientation)

    def _angular_velocity(self, sample, values):
        """Return the sample's angular velocity in the output frame, else the differenced one."""
        frame = self.params.angular_velocity_output_frame
        q = values[ORIENTATION]
        omega = sample.angular_velocity
        if omega is not None:
            if not all(map(math.isfinite, omega)):
                self._issue(NON_FINITE_ANGULAR_VELOCITY, values=omega)
                return None
            input_frame = self.params.angular_velocity_input_frame
            if q is None and input_frame != frame:
                return None   # the frame change needs the orientation
            if self._frames is not None:
                omega = (self._frames.world_vector(omega) if input_frame == 'world'
                         else self._frames.body_vector(omega))
            return self._measured_in_output_frame(q, omega)
        if q is None:
            return None
        stamp_ns = header_stamp_ns(sample.header)
        state = self.state
        previous_q, previous_ns = state.previous_quaternion, state.previous_stamp_ns
        state.previous_quaternion, state.previous_stamp_ns = q, stamp_ns
        if previous_q is None or previous_ns is None:   # both set together
            return None
        step_ns = stamp_ns - previous_ns
        if step_ns <= 0:
            self._issue(TIMESTAMP_NOT_INCREASING, stamp=seconds_text(stamp_ns),
                        previous=seconds_text(previous_ns))
            return None
        return _rates_between(previous_q, q, step_ns, frame)

    def _angular_velocity_block(self, block, rows, values, run):
        """Return where the angular velocity is available and its values (as one sample's)."""
        params = self.params
        known, q = values[ORIENTATION]
        omega = np.zeros((len(rows), 3))
        available = np.zeros(len(rows), dtype=bool)
        differenced = rows & known
        if block.angular_velocity is not None:
            measured = rows & block.angular_velocity_known
            raw = block.angular_velocity
            finite = np.isfinite(raw).all(axis=1)
            for s in np.flatnonzero(measured & ~finite).tolist():
                run.issue(s, NON_FINITE_ANGULAR_VELOCITY, values=tuple(raw[s].tolist()))
            measured &= finite
            if params.angular_velocity_input_frame != params.angular_velocity_output_frame:
                measured &= known   # the frame change needs the orientation
            if measured.any():
                omega[measured] = self._measured_in_output_frame(q[measured], raw[measured])
            available |= measured
            differenced &= ~(rows & block.angular_velocity_known)
        indices = np.flatnonzero(differenced)
        if not indices.size:
            return available, omega
        # The finite differences along the chain of the state's sample and these.
        state = run.state
        chain_q, chain_ns, targets = q[indices], block.stamp_ns[indices], indices
        if state.previous_quaternion is None:   # the stream's first sample has none
            targets = indices[1:]
        else:
            chain_q = np.concatenate(([state.previous_quaternion], chain_q))
            chain_ns = np.concatenate(([state.previous_stamp_ns], chain_ns))
        state.previous_quaternion, state.previous_stamp_ns = chain_q[-1].copy(), int(
            chain_ns[-1])
        steps_ns = chain_ns[1:] - chain_ns[:-1]
        for j in np.flatnonzero(steps_ns <= 0).tolist():
            run.issue(int(targets[j]), TIMESTAMP_NOT_INCREASING, stamp=seconds_text(
                int(chain_ns[j + 1])), previous=seconds_text(int(chain_ns[j])))
        valid = steps_ns > 0
        if valid.any():
            omega[targets[valid]] = _rates_between(
                chain_q[:-1][valid], chain_q[1:][valid], steps_ns[valid, None],
                params.angular_velocity_output_frame)
            available[targets[valid]] = True
        return available, omega

    def _measured_in_output_frame(self, q, omega):
        """Return measured rates (one or rows) mounted and in the output frame (``q``: from)."""
        params = self.params
        if self._mounting is not None:
            omega = self._mounting.vector(omega, params.angular_velocity_input_frame)
        if params.angular_velocity_input_frame == params.angular_velocity_output_frame:
            return np.array(omega)
        if params.angular_velocity_output_frame != 'world':
            q = conversions.quaternion_conjugate(q)
        return conversions.rotate_vector(q, omega)

    def _output_quaternion(self, sample, values):
        """Return the unit output quaternion: w >= 0, or with continuity nearer the previous."""
        q = conversions.canonical_quaternion(values[ORIENTATION])
        if not self.params.quaternion_continuity:
            return q
        previous = self.state.previous_output_quaternion
        if _turns_away(*(_NO_QUATERNION if previous is None else previous.tolist()), *q.tolist()):
            q = -q
        self.state.previous_output_quaternion = q
        return q

    def _output_quaternion_block(self, block, rows, values, run):
        """Return the output quaternions of ``rows``, sign-continuous as one sample's."""
        q = values[ORIENTATION][1]
        out = np.zeros_like(q)
        indices = np.flatnonzero(rows)
        if not indices.size:
            return rows, out
        canonical = conversions.canonical_quaternion(q[indices])
        if self.params.quaternion_continuity:
            previous = run.state.previous_output_quaternion
            _sign_chain(canonical.reshape(-1),
                        *(_NO_QUATERNION if previous is None else previous.tolist()))
            run.state.previous_output_quaternion = canonical[-1].copy()
        out[indices] = canonical
        return rows, out

    def _euler_angles(self, sample, values):
        """Return the Euler angles of the orientation; counts a near-singular sample."""
        angles, near_singular = self._euler_angles_of(values[ORIENTATION])
        self.stats.near_singular += bool(near_singular)
        return angles

    def _euler_angles_block(self, block, rows, values, run):
        angles = np.zeros((len(rows), 3))
        if rows.any():
            angles[rows], near_singular = self._euler_angles_of(values[ORIENTATION][1][rows])
            run.near_singular = int(np.count_nonzero(near_singular))
        return rows, angles

    def _euler_angles_of(self, q):
        """Return the Euler angles of one quaternion or rows, and whether each is near-singular."""
        params = self.params
        angles = conversions.euler_from_quaternion(
            q, params.euler_sequence, degrees=params.euler_degrees)
        margin = conversions.euler_singularity_margin(q, params.euler_sequence)
        return angles, margin < params.euler_singularity_threshold

    def _published_euler(self, sample, values):
        """Return the Euler angles, first and third unwrapped against the previous published."""
        first, second, third = values[EULER_ANGLES].tolist()
        previous = self.state.previous_euler
        if self.params.euler_unwrap and previous is not None:
            first = _unwrapped(first, previous[0], self._angle_period)
            third = _unwrapped(third, previous[2], self._angle_period)
        self.state.previous_euler = (first, second, third)
        return self.state.previous_euler

    def _published_euler_block(self, block, rows, values, run):
        published = values[EULER_ANGLES][1].copy()
        indices = np.flatnonzero(rows)
        if not indices.size:
            return rows, published
        angles = published[indices]
        previous = run.state.previous_euler
        if self.params.euler_unwrap:
            # The stream's first sample is published as it is, and the next unwrapped on it.
            start = 0 if previous is not None else 1
            first, _, third = angles[0].tolist() if previous is None else previous
            _unwrap_chain(angles[start:].reshape(-1), first, third, self._angle_period)
        published[indices] = angles
        run.state.previous_euler = tuple(angles[-1].tolist())
        return rows, published

    def _euler_rates(self, sample, values):
        """Return the Euler-angle rates, or None within the singularity threshold."""
        rates = self._euler_rates_of(values[EULER_ANGLES], values[ANGULAR_VELOCITY])
        if math.isnan(rates[0]):
            self._issue(EULER_RATES_NEAR_SINGULAR, **self._singularity_fields())
            return None
        return rates

    def _euler_rates_block(self, block, rows, values, run):
        rates = np.zeros((len(rows), 3))
        if rows.any():
            rates[rows] = self._euler_rates_of(values[EULER_ANGLES][1][rows],
                                               values[ANGULAR_VELOCITY][1][rows])
        singular = rows & np.isnan(rates[:, 0])
        for s in np.flatnonzero(singular).tolist():
            run.issue(s, EULER_RATES_NEAR_SINGULAR, **self._singularity_fields())
        return rows & ~singular, rates

    def _euler_rates_of(self, angles, omega):
        """Return the Euler-angle rates: NaN within the singularity threshold."""
        params = self.params
        with warnings.catch_warnings():   # counted and reported instead
            warnings.simplefilter('ignore', kinematics.EulerSingularityWarning)
            return kinematics.euler_rates_from_angular_velocity(
                angles, omega, params.euler_sequence,
                frame=params.angular_velocity_output_frame, degrees=params.euler_degrees,
                singularity_threshold=params.euler_singularity_threshold)

    def _singularity_fields(self):
        return {'threshold': self.params.euler_singularity_threshold,
                'sequence': self.params.euler_sequence}

    def _orientation_covariance(self, sample, values):
        """Return the input's rotation-vector covariance in the output frames, or None."""
        block = sample.covariance
        if block is None or not any(block):
            self._issue(COVARIANCE_UNKNOWN)
            return None
        if not all(map(math.isfinite, block)):
            self._issue(NON_FINITE_COVARIANCE, covariance=block)
            return None
        if max(block[0], block[4], block[8]) > covariance.MAX_ROTATION_VECTOR_VARIANCE:
            self._issue(COVARIANCE_TOO_LARGE, covariance=block)
            return None
        defect = covariance.covariance_defect(block)
        if defect is not None:
            self._issue(INVALID_COVARIANCE, covariance=f'orientation covariance {block}',
                        problem=f'{defect}, not a covariance')
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
            self._issue(EULER_COVARIANCE_NEAR_SINGULAR, **self._singularity_fields())
            return None
        # sigma_max^2 <= trace: only above it can the ratio exceed the limit (saves eigvalsh)
        limit = params.covariance_max_linearisation_ratio * float(
            conversions.euler_singularity_margin(values[ORIENTATION], params.euler_sequence))
        if np.trace(sigma) > limit * limit:
            ratio = float(covariance.euler_linearisation_ratio(
                angles, sigma, params.euler_sequence, degrees=params.euler_degrees))
            if not ratio <= params.covariance_max_linearisation_ratio:
                self._issue(EULER_COVARIANCE_NOT_LINEAR, ratio=ratio,
                            sequence=params.euler_sequence,
                            limit=params.covariance_max_linearisation_ratio)
                return None
        # A valid input gives a finite, non-negative diagonal; rounding at the edge of
        # positive semi-definiteness may not: never a NaN standard deviation.
        if not (np.isfinite(result).all() and (np.diagonal(result) >= 0.0).all()):
            self._issue(INVALID_COVARIANCE, covariance='the Euler covariance of orientation '
                        f'covariance {tuple(sigma.ravel())}',
                        problem='not positive semi-definite (rounding at its edge)')
            return None
        return result
