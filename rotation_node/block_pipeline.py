"""
The conversion pipeline over blocks of samples: :class:`ConversionPipeline`'s results, in arrays.

:class:`BlockPipeline` converts a block of samples of one input stream (a
:class:`SampleBlock`: stamps, orientations, angular velocities as arrays)
with one library call per conversion, and gives exactly what
:meth:`rotation_node.pipeline.ConversionPipeline.process_values` gives for
the same messages one by one: the same numbers bit for bit, the same
per-stream state carried from block to block (Euler unwrapping, quaternion
sign continuity, the finite-difference angular velocity and its restarts),
the same counters in :class:`~rotation_node.pipeline.PipelineStats` and the
same ``on_issue`` reports in the same order. It runs on the state and
counters of a :class:`ConversionPipeline`, so that a stream can go block by
block and message by message in any mix.

Not everything has a block form: :data:`BLOCK_OUTPUTS` says which outputs do,
and :func:`block_support` which parameters and input types; anything else
(and any block in which a conversion raises) is left to the per-message
pipeline: :meth:`BlockPipeline.process_block` returns None, having changed
nothing, and the caller converts the block message by message.

Exactness: blocks are kept below the size at which the conversions switch to
their batch schedules (``BLOCK_SAMPLES``), whose vectorised ``atan2`` may
differ from the single-sample path in the last bit; below it a block call
runs the single-sample code once per sample. The finite difference is taken
over unit time steps and divided by each step afterwards, the very division
the per-message call makes. Decisions that a last-bit difference could flip
(the norm tolerance, the sign of a dot product) are made with the
per-message pipeline's own expression wherever the block's estimate is not
clearly on one side.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Dict, FrozenSet, List, NamedTuple, Optional, Tuple, TYPE_CHECKING
import warnings

import numpy as np
from rotation_node import conversions, kinematics, messages
from rotation_node.conversions.kernels import BATCH_SAMPLES, FLAT_OUT, FLOAT, kernel
from rotation_node.messages import (
    ANGULAR_VELOCITY, EULER_ANGLES, EULER_RATES, ORIENTATION, OUTPUT_QUATERNION, PUBLISHED_EULER)
from rotation_node.pipeline import (
    _needed_values, ConversionPipeline, EULER_RATES_NEAR_SINGULAR, mounting_of,
    NON_FINITE_ANGULAR_VELOCITY, NON_FINITE_ORIENTATION, NON_UNIT_QUATERNION, ORIENTATION_UNKNOWN,
    ORIENTATION_UNKNOWN_DETAIL, SAMPLE_TRANSFORMS, TIMESTAMP_NOT_INCREASING, ZERO_QUATERNION,
    ZERO_QUATERNION_DETAIL)
from rotation_node.stamps import seconds_text

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

#: Most samples in one block: below the conversions' batch schedules (see the module notes).
BLOCK_SAMPLES = BATCH_SAMPLES - 1


BLOCK_OUTPUTS: FrozenSet[str] = frozenset((
    'quaternion', 'euler', 'rotation_vector', 'axis_angle', 'matrix', 'angular_velocity',
    'euler_rates', 'quaternion_rate'))
"""
The outputs with a block form: those whose registry ``compute`` also works on blocks.

Each one's :class:`~rotation_node.messages.OutputType` ``compute(params,
*values)`` is given the values it ``needs`` as arrays of the samples that
have them all (one row per sample) and returns an ``(n, k)`` array, each row
bit for bit what the same ``compute`` gives for that sample alone (tested);
a ``compute`` of None publishes the one value needed as it is. An output
missing here (a new registry entry, the covariance outputs) is converted by
the per-message pipeline.
"""

#: The values :class:`BlockPipeline` computes (the others leave a stream to the pipeline).
BLOCK_VALUES = (ORIENTATION, ANGULAR_VELOCITY, OUTPUT_QUATERNION, EULER_ANGLES,
                PUBLISHED_EULER, EULER_RATES)


def block_support(params: NodeParameters) -> Optional[str]:
    """
    Return why the parameters' streams cannot be converted in blocks, or None if they can.

    Parameters
    ----------
    params : rotation_node.parameters.NodeParameters
        The node's parameters (input type, outputs, frames).

    Returns
    -------
    str or None
        E.g. ``'output euler_stddev has no block form'``; None when
        :class:`BlockPipeline` converts every block of such a stream.

    """
    input_type = messages.INPUTS[params.input_type]
    if input_type.stream is not None:
        return f'input type {params.input_type} reads samples from a stream of its own'
    if any(factory(params) is not None for factory in SAMPLE_TRANSFORMS):
        return 'an input-stage transform is configured'
    if not (params.frames_input_world == params.frames_output_world
            and params.frames_input_body == params.frames_output_body):
        return 'a frame conversion is configured'
    for name in params.outputs:
        if name not in BLOCK_OUTPUTS:
            return f'output {name} has no block form'
    for value in _needed_values(params.outputs):
        if value.name not in BLOCK_VALUES:
            return f'value {value.name} has no block form'
    return None


class SampleBlock(NamedTuple):
    """
    Consecutive samples of one input stream, one row per message.

    Attributes
    ----------
    stamp_ns : ndarray of int64, shape (n,)
        Header stamps in integer nanoseconds.
    orientation : ndarray, shape (n, 4) or (n, 3)
        In the input type's form (rows where it is unknown are ignored).
    orientation_known : ndarray of bool, shape (n,)
        False where the message says the orientation is unknown.
    angular_velocity : ndarray, shape (n, 3), or None
        None when the input type carries none (or it is not read).
    angular_velocity_known : ndarray of bool, shape (n,), or None
        False where the message says its angular velocity is unknown.

    """

    stamp_ns: np.ndarray
    orientation: np.ndarray
    orientation_known: np.ndarray
    angular_velocity: Optional[np.ndarray] = None
    angular_velocity_known: Optional[np.ndarray] = None


@dataclass
class BlockOutputs:
    """
    What a block gave: for each output, which messages have it and its numbers.

    Attributes
    ----------
    present : dict
        ``{output name: bool array (n,)}`` in the order of ``outputs``.
    numbers : dict
        ``{output name: float64 array (count, k)}``, one row per message that
        has the output, in message order: what the per-message pipeline
        returns as the output's numbers.

    """

    present: Dict[str, np.ndarray]
    numbers: Dict[str, np.ndarray]


# A kernel (conversions' runtime): interpreted for a few samples, compiled for more.
@kernel(FLAT_OUT, FLAT_OUT, FLOAT, FLOAT, FLOAT, returns=None)
def _unwrap_chain(first, third, previous_first, previous_third, period):   # pragma: no cover
    """
    Unwrap ``first`` and ``third`` in place, each against the one before, as ``_unwrapped``.

    ``rint`` rounds half to even as Python's ``round``; ``+ 0.0`` makes a zero
    correction +0, as the pipeline's ``period * 0`` (an int) is.
    """
    for s in range(first.shape[0]):
        first[s] = first[s] + (period * np.rint((previous_first - first[s]) / period) + 0.0)
        third[s] = third[s] + (period * np.rint((previous_third - third[s]) / period) + 0.0)
        previous_first, previous_third = first[s], third[s]


def _sign_chain(dots):
    """
    Signs of sign-continuous quaternions from the dot products of consecutive canonical ones.

    ``dots[k]`` is the dot product of the canonical quaternions ``k - 1`` and
    ``k`` (the first with the previous output); the pipeline flips quaternion
    ``k`` when its dot product with the previous (flipped) one is negative.
    """
    negative = dots < 0.0
    reset = dots == 0.0   # a zero dot product flips nothing: the sign restarts at +1
    flips = np.cumsum(negative)
    at_reset = np.where(reset, flips, 0)
    base = np.maximum.accumulate(at_reset) if at_reset.size else at_reset
    return np.where((flips - base) % 2 == 1, -1.0, 1.0)


class BlockPipeline:
    """
    Convert blocks of samples of one stream as a :class:`ConversionPipeline` converts messages.

    Parameters
    ----------
    pipeline : ConversionPipeline
        The per-message pipeline whose parameters, per-stream state,
        counters and ``on_issue`` this one uses and updates.

    Raises
    ------
    ValueError
        If :func:`block_support` says the pipeline's parameters have no block form.

    """

    def __init__(self, pipeline: ConversionPipeline):
        reason = block_support(pipeline.params)
        if reason is not None:
            raise ValueError(f'pipeline: no block form ({reason})')
        self.pipeline = pipeline
        params = pipeline.params
        self.params = params
        self.input_type = messages.INPUTS[params.input_type]
        self._plan = {value.name for value in _needed_values(params.outputs)}
        self._outputs = [messages.OUTPUTS[name] for name in params.outputs]
        self._angle_period = 360.0 if params.euler_degrees else 2.0 * math.pi
        self._mounting = mounting_of(params)   # the pipeline's own rule, on arrays

    @property
    def reads_angular_velocity(self) -> bool:
        """Whether blocks must carry the angular velocity (the input has one and it is used)."""
        return (ANGULAR_VELOCITY in self._plan
                and self.input_type.angular_velocity_field is not None)

    def process_block(self, block: SampleBlock) -> Optional[BlockOutputs]:
        """
        Convert a block of at most :data:`BLOCK_SAMPLES` samples.

        Returns
        -------
        BlockOutputs or None
            None when the block must be converted message by message (a
            conversion rejected a value): nothing was counted or changed then.

        """
        if len(block.stamp_ns) > BLOCK_SAMPLES:
            raise ValueError(f'block: at most {BLOCK_SAMPLES} samples, got '
                             f'{len(block.stamp_ns)}')
        try:
            with np.errstate(all='ignore'):
                result = self._converted(block)
        except ValueError:   # a conversion rejected a value: the pipeline says which
            return None
        state, stats, events, outputs = result
        self._commit(state, stats, events)
        return outputs

    def _commit(self, state, stats, events):
        pipeline = self.pipeline
        for name, value in state.items():
            setattr(pipeline, name, value)
        counters = pipeline.stats
        counters.received += stats['received']
        counters.published += stats['published']
        counters.normalised += stats['normalised']
        counters.near_singular += stats['near_singular']
        for reason, kind, _ in events:
            if kind is not None:   # a normalised quaternion is counted in ``normalised``
                getattr(counters, kind)[reason] += 1
        if pipeline._on_issue is not None:
            for reason, _, detail in events:
                pipeline._on_issue(reason, detail)

    # ------------------------------------------------------------------ the values

    def _converted(self, block):
        params = self.params
        n = len(block.stamp_ns)
        # (sample, rank, reason, kind: 'dropped', 'skipped' or None, detail)
        events: List[Tuple[int, int, str, Optional[str], str]] = []
        state: Dict[str, Any] = {}   # pipeline attribute -> its value after the block
        stats = {'received': n, 'published': 0, 'normalised': 0, 'near_singular': 0}
        kept, zero, q = self._orientation(block, events, stats)
        known = kept & block.orientation_known & ~zero
        if self._mounting is not None and known.any():
            q[known] = self._mounting.quaternion(q[known])
        values: Dict[str, Tuple[np.ndarray, np.ndarray]] = {ORIENTATION: (known, q)}
        if ANGULAR_VELOCITY in self._plan:
            values[ANGULAR_VELOCITY] = self._angular_velocity(block, kept, known, q, events,
                                                              state)
        if OUTPUT_QUATERNION in self._plan:
            values[OUTPUT_QUATERNION] = (known, self._output_quaternion(q, known, state))
        if EULER_ANGLES in self._plan:
            angles = np.zeros((n, 3))
            if known.any():
                angles[known] = conversions.euler_from_quaternion(
                    q[known], params.euler_sequence, degrees=params.euler_degrees)
                margin = conversions.euler_singularity_margin(q[known], params.euler_sequence)
                stats['near_singular'] = int(np.count_nonzero(
                    margin < params.euler_singularity_threshold))
            values[EULER_ANGLES] = (known, angles)
        if PUBLISHED_EULER in self._plan:
            values[PUBLISHED_EULER] = (known, self._published_euler(angles, known, state))
        if EULER_RATES in self._plan:
            values[EULER_RATES] = self._euler_rates(values, events)
        outputs = BlockOutputs({}, {})
        published = np.zeros(n, dtype=np.int64)
        for output in self._outputs:
            present = kept.copy()
            for need in output.needs:
                present &= values[need][0]
            compute = output.compute
            needed = [values[need][1][present] for need in output.needs]
            if compute is None:
                numbers = needed[0]
            elif present.any():
                numbers = compute(params, *needed)
            else:
                numbers = np.zeros((0, 1))
            outputs.present[output.name] = present
            outputs.numbers[output.name] = np.ascontiguousarray(numbers, dtype=np.float64)
            published += present
        stats['published'] = int(published.sum())
        unknown = kept & ~known & (published < len(self._outputs))
        for s in np.flatnonzero(unknown).tolist():
            if zero[s]:
                events.append((s, 99, ZERO_QUATERNION, 'skipped', ZERO_QUATERNION_DETAIL))
            else:
                events.append((s, 99, ORIENTATION_UNKNOWN, 'skipped', ORIENTATION_UNKNOWN_DETAIL))
        events.sort(key=lambda event: event[:2])
        return state, stats, [event[2:] for event in events], outputs

    def _orientation(self, block, events, stats):
        """
        Return the kept samples, the zero quaternions and the quaternions (any norm).

        Counts the drops. A zero quaternion is an unknown orientation, as in the
        pipeline: kept, and counted once the outputs are known.
        """
        params, form = self.params, self.input_type.orientation_form
        orientation = block.orientation
        n = len(orientation)
        known = block.orientation_known
        finite = np.isfinite(orientation).all(axis=1)
        kept = ~known | finite
        for s in np.flatnonzero(~kept).tolist():
            events.append((s, 0, NON_FINITE_ORIENTATION, 'dropped',
                           f'message dropped: {form} {tuple(orientation[s].tolist())} has a '
                           'NaN or Inf component'))
        use = known & finite
        q = np.zeros((n, 4))
        zero = np.zeros(n, dtype=bool)
        if form == messages.EULER:
            if use.any():
                q[use] = conversions.quaternion_from_euler(
                    orientation[use], params.euler_sequence, degrees=params.euler_degrees)
            return kept, zero, q
        if form == messages.ROTATION_VECTOR:
            if use.any():
                q[use] = conversions.quaternion_from_rotation_vector(orientation[use])
            return kept, zero, q
        zero = use & (orientation == 0.0).all(axis=1)
        use &= ~zero
        q[use] = orientation[use]
        # The pipeline's test is on math.hypot; where this estimate is not clearly
        # within the tolerance, math.hypot decides (and gives the reported norm).
        tolerance = params.quaternion_norm_tolerance
        estimate = np.sqrt(np.einsum('ij,ij->i', q, q))
        unclear = use & ~(np.abs(estimate - 1.0) <= tolerance - 1e-12)
        for s in np.flatnonzero(unclear).tolist():
            values = tuple(orientation[s].tolist())
            norm = math.hypot(*values)
            if abs(norm - 1.0) > tolerance:
                stats['normalised'] += 1
                events.append((s, 0, NON_UNIT_QUATERNION, None,
                               f'quaternion {values} has norm {norm:.9g}; normalised'))
        return kept, zero, q

    def _angular_velocity(self, block, kept, known, q, events, state):
        """Return the angular velocity in the output frame: measured, or by finite difference."""
        params = self.params
        n = len(kept)
        omega = np.zeros((n, 3))
        available = np.zeros(n, dtype=bool)
        if block.angular_velocity is not None:
            measured = kept & block.angular_velocity_known
            raw = block.angular_velocity
            finite = np.isfinite(raw).all(axis=1)
            for s in np.flatnonzero(measured & ~finite).tolist():
                events.append((s, 1, NON_FINITE_ANGULAR_VELOCITY, 'skipped',
                               f'angular velocity {tuple(raw[s].tolist())} has a NaN or Inf '
                               'component: angular-velocity outputs skipped'))
            measured_ok = measured & finite
            if self._mounting is not None and measured_ok.any():
                raw = raw.copy()
                raw[measured_ok] = self._mounting.vector(raw[measured_ok],
                                                         params.angular_velocity_input_frame)
            frame = params.angular_velocity_output_frame
            if params.angular_velocity_input_frame == frame:
                omega[measured_ok] = raw[measured_ok]
                available |= measured_ok
            else:
                rotated = measured_ok & known
                if rotated.any():
                    rotation = q[rotated]
                    if frame != 'world':
                        rotation = conversions.quaternion_conjugate(rotation)
                    omega[rotated] = conversions.rotate_vector(rotation, raw[rotated])
                available |= rotated
            differenced = kept & ~measured & known
        else:
            differenced = kept & known
        indices = np.flatnonzero(differenced)
        if indices.size:
            self._finite_differences(block, indices, q, omega, available, events, state)
        return available, omega

    def _finite_differences(self, block, indices, q, omega, available, events, state):
        """Compute the finite-difference rates of the samples ``indices``, from the state."""
        pipeline = self.pipeline
        stamps = block.stamp_ns[indices]
        previous_q = np.empty((len(indices), 4))
        previous_q[1:] = q[indices[:-1]]
        previous_ns = np.empty(len(indices), dtype=np.int64)
        previous_ns[1:] = stamps[:-1]
        has_previous = np.ones(len(indices), dtype=bool)
        if pipeline._previous_quaternion is None:
            has_previous[0] = False
            previous_q[0] = 0.0
            previous_ns[0] = 0
        else:
            previous_q[0] = pipeline._previous_quaternion
            previous_ns[0] = pipeline._previous_stamp_ns
        state['_previous_quaternion'] = q[indices[-1]].copy()
        state['_previous_stamp_ns'] = int(stamps[-1])
        increasing = stamps > previous_ns
        for j in np.flatnonzero(has_previous & ~increasing).tolist():
            events.append((int(indices[j]), 1, TIMESTAMP_NOT_INCREASING, 'skipped',
                           f'stamp {seconds_text(int(stamps[j]))} s is not after the previous '
                           f'{seconds_text(int(previous_ns[j]))} s: finite-difference outputs '
                           'skipped'))
        valid = has_previous & increasing
        if not valid.any():
            return
        pairs = np.stack((previous_q[valid], q[indices[valid]]), axis=1)
        # Unit steps, then the per-message call's own division by each step.
        steps = (stamps[valid] - previous_ns[valid]).astype(np.float64) * 1e-9
        rates = kinematics.angular_velocity_from_quaternions(
            pairs, (0.0, 1.0), frame=self.params.angular_velocity_output_frame)[:, 0]
        target = indices[valid]
        omega[target] = rates / steps[:, None]
        available[target] = True

    def _output_quaternion(self, q, known, state):
        """Return canonical unit quaternions, sign-continuous with ``quaternion.continuity``."""
        out = np.zeros_like(q)
        indices = np.flatnonzero(known)
        if not indices.size:
            return out
        canonical = conversions.canonical_quaternion(q[indices])
        if self.params.quaternion_continuity:
            previous = self.pipeline._previous_output_quaternion
            before = np.empty_like(canonical)
            before[1:] = canonical[:-1]
            before[0] = 0.0 if previous is None else previous
            dots = np.einsum('ij,ij->i', before, canonical)
            # The pipeline's np.dot decides signs this estimate leaves in doubt.
            for k in np.flatnonzero(np.abs(dots) < 1e-9).tolist():
                dots[k] = 0.0 if k == 0 and previous is None else np.dot(before[k], canonical[k])
            canonical = canonical * _sign_chain(dots)[:, None]
            state['_previous_output_quaternion'] = canonical[-1].copy()
        out[indices] = canonical
        return out

    def _published_euler(self, angles, known, state):
        """Return the Euler angles, first and third unwrapped against the previous published."""
        published = angles.copy()
        indices = np.flatnonzero(known)
        if not indices.size:
            return published
        rows = published[indices]
        previous = self.pipeline._previous_euler
        if self.params.euler_unwrap:
            # The stream's first sample is published as it is, and the next unwrapped on it.
            start = 0 if previous is not None else 1
            if previous is None:
                previous = rows[0]
            first, third = rows[start:, 0].copy(), rows[start:, 2].copy()
            _unwrap_chain(first, third, float(previous[0]), float(previous[2]),
                          self._angle_period)
            rows[start:, 0], rows[start:, 2] = first, third
        published[indices] = rows
        state['_previous_euler'] = tuple(rows[-1].tolist())
        return published

    def _euler_rates(self, values, events):
        """Return the Euler-angle rates; skipped within the singularity threshold."""
        params = self.params
        angles_ok, angles = values[EULER_ANGLES]
        omega_ok, omega = values[ANGULAR_VELOCITY]
        present = angles_ok & omega_ok
        rates = np.zeros_like(angles)
        if present.any():
            with warnings.catch_warnings():   # counted and reported below instead
                warnings.simplefilter('ignore', kinematics.EulerSingularityWarning)
                rates[present] = kinematics.euler_rates_from_angular_velocity(
                    angles[present], omega[present], params.euler_sequence,
                    frame=params.angular_velocity_output_frame, degrees=params.euler_degrees,
                    singularity_threshold=params.euler_singularity_threshold)
        singular = present & np.isnan(rates[:, 0])
        for s in np.flatnonzero(singular).tolist():
            events.append((s, 5, EULER_RATES_NEAR_SINGULAR, 'skipped',
                           f'within {params.euler_singularity_threshold:g} rad of gimbal lock '
                           f'of {params.euler_sequence!r}: euler_rates skipped (unbounded there)'))
        return present & ~singular, rates
