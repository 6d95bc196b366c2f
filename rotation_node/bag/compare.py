"""
Compare two orientation topics of one bag or two (``rotation_bag compare``; docs/compare.md).

Both are read as the node reads them (a ``ConversionPipeline`` with the ``quaternion``
output: the input type's sample stream, its drop rules); :mod:`rotation_node.comparison`
estimates what was asked of ``R_ref(t) = W R_est(t + time_offset) M`` and the errors of the
aligned estimate at the reference stamps: :class:`ComparisonResult` (``--json``),
:func:`summary`, :func:`draw_comparison` (``--plot``).
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
import io
import json
import math
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, TYPE_CHECKING

from matplotlib.figure import Figure
import numpy as np
from rotation_node import comparison, conversions, registry
from rotation_node.bag.convert import input_streams
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.writing.atomic_file import AtomicFile
from rotation_node.command_line.stop_signal import raise_if_stopped
from rotation_node.errors import BagError, ComparisonError
from rotation_node.parameters import NodeParameters
from rotation_node.pipeline import ConversionPipeline, ORIENTATION_UNKNOWN, ZERO_QUATERNION
from rotation_node.wire.cdr import fixed_layout_codec
from rotation_node.wire.stamps import header_stamp_ns

if TYPE_CHECKING:
    from rotation_node.type_aliases import FloatArray, StrPath

ALIGN_CHOICES = ('none', 'world', 'mounting', 'both')   # as bag.cli's (a test checks)
#: The Euler angles of the plot: ROS roll, pitch, yaw.
PLOT_SEQUENCE = 'xyz'


@dataclass
class StreamSource:
    """
    Where a stream is read: a bag, a topic (its name in the bag or its ROS 2 name), and how.

    ``input_type`` (a key of :data:`rotation_node.registry.INPUTS`) is needed where types
    share a message (``euler``, ``rotation_vector``); ``frames`` is ``(parent, child)`` for
    ``tf``: the orientation of child in parent.
    """

    path: Any
    topic: str
    input_type: Optional[str] = None
    frames: Optional[Tuple[str, str]] = None


@dataclass
class Stream:
    """The samples of one topic: stamps, unit quaternions and body rates (None if not given)."""

    path: str
    topic: str
    messages: int
    stamps_ns: np.ndarray
    quaternions: FloatArray
    rates: Optional[FloatArray]
    dropped: int


def _input_type(source: StreamSource, type_name: str, params: NodeParameters):
    """Return the :class:`~rotation_node.registry.InputType` a topic is read as."""
    if source.input_type is not None:
        entry = registry.INPUTS.get(source.input_type)
        if entry is None:
            raise BagError(f'unknown input type {source.input_type!r} (one of '
                           f'{", ".join(registry.INPUTS)})')
        if entry.type_name != type_name:
            raise BagError(f'{source.topic} is {type_name}, not {entry.type_name} '
                           f'(input type {entry.name})')
        return entry
    candidates = [entry for entry in registry.INPUTS.values() if entry.type_name == type_name]
    preferred = [entry for entry in candidates if entry.name == params.input_type]
    if not candidates:
        readable = sorted({entry.type_name for entry in registry.INPUTS.values()})
        raise BagError(f'cannot compare {source.topic}: {type_name} has no orientation the '
                       f'node reads (readable: {", ".join(readable)})')
    return (preferred or candidates)[0]


def read_stream(source: StreamSource, params: Optional[NodeParameters] = None, *,
                strict: bool = False,
                report: Optional[Callable[[str], None]] = None) -> Stream:
    """
    Read the orientation samples of a topic with the node's sample stream of its input type.

    Samples without an orientation (an Imu's ``orientation_covariance[0] == -1``), with a
    non-finite or zero one, or with a repeated stamp are dropped and counted.

    Parameters
    ----------
    source : StreamSource
        The bag, the topic and how to read it.
    params : NodeParameters, optional
        Euler sequence and unit of Euler-angle inputs; ``input_type`` picks among types that
        share a message.
    strict : bool, optional
        Refuse unfinished recordings.
    report : callable, optional
        Receives the input's notes.

    Returns
    -------
    Stream
        The samples sorted by stamp. Rates are the messages' angular velocities where every
        sample has a finite one and not all are zero (a field never filled in), else None
        (the comparison then differentiates the orientations).

    Raises
    ------
    BagError
        The bag is unreadable, the topic is not in it, has no messages or cannot be read as
        orientations, the frames of ``tf`` are missing.
    ComparisonError
        Fewer than 2 usable samples.

    """
    params = NodeParameters() if params is None else params
    with open_bag(source.path, strict=strict) as reader:
        reader.report_notes(report)
        with reader.reporting_new_notes(report):
            topic = reader.topic_name(source.topic)
            entry = _input_type(source, reader.topics[topic], params)
            # The pipeline's quaternion output: the input type's sample stream, its orientation
            # form (Euler angles of the parameters' sequence and unit), its drop rules; no frame
            # conventions (the orientations as the messages hold them).
            values = {'input_type': entry.name, 'outputs': ['quaternion'],
                      'euler.sequence': params.euler_sequence,
                      'euler.degrees': params.euler_degrees}
            if entry.stream is not None:
                if source.frames is None:
                    raise BagError(f'{topic} is {entry.type_name}: name the parent and child '
                                   'frames to compare (--reference-frames / --estimate-frames '
                                   'PARENT CHILD)')
                values.update({'tf.parent_frame': source.frames[0],
                               'tf.child_frame': source.frames[1]})
            topics = input_streams(reader, entry, [topic])[topic]   # with T_static for T
            pipeline = ConversionPipeline(NodeParameters().replaced(values))
            # The messages' own angular velocities (one sample per message of a plain type).
            read_rate = (entry.sample_reader() if entry.stream is None
                         and entry.angular_velocity_field is not None else None)
            codec = fixed_layout_codec(entry.type_name)   # read-only views, as convert reads them
            decode = None if codec is None else codec.decode
            stamps: List[int] = []
            quaternions: List[Sequence[float]] = []
            rates: List[Optional[Sequence[float]]] = []
            count = 0
            try:
                for record in reader.messages(list(topics)):
                    raise_if_stopped()
                    count += record.topic == topic
                    msg = record.message(decode)
                    for _, header, numbers in pipeline.process_values(msg, topics[record.topic]):
                        stamps.append(header_stamp_ns(header))
                        quaternions.append(numbers)
                        rates.append(None if read_rate is None
                                     else read_rate(msg).angular_velocity)
            except BagError as error:   # a message that cannot be decoded names no file
                raise reader.naming_this_bag(error) from None
        path = str(reader.path)
    skipped = pipeline.stats.skipped   # no orientation: unknown (REP 145) or all zero
    dropped = (sum(pipeline.stats.dropped.values()) + skipped[ORIENTATION_UNKNOWN]
               + skipped[ZERO_QUATERNION])
    return _sorted_stream(path, topic, count, stamps, quaternions, rates, dropped)


def _sorted_stream(path, topic, count, stamps, quaternions, rates, dropped):
    if count == 0:
        raise BagError(f'topic {topic} in {path} has no messages')
    stamps_ns = np.asarray(stamps, dtype=np.int64)
    order = np.argsort(stamps_ns, kind='stable')
    keep = order[np.concatenate([[True], np.diff(stamps_ns[order]) > 0])] if order.size else order
    dropped += len(stamps) - keep.size
    if keep.size < 2:
        raise ComparisonError(f'topic {topic} in {path} has {keep.size} usable orientation '
                              'samples; at least 2 are needed')
    unit = conversions.canonical_quaternion(np.asarray(quaternions, dtype=np.float64)[keep])
    given = None
    if all(rate is not None for rate in rates):
        given = np.asarray(rates, dtype=np.float64)[keep]
        if not np.any(given) or not np.all(np.isfinite(given)):
            given = None   # a field never filled in, or unusable: differentiate
    return Stream(path, topic, count, stamps_ns[keep], unit, given, dropped)


@dataclass
class ComparisonResult:
    """What ``rotation_bag compare`` found (angles of the errors in radians)."""

    reference: Stream
    estimate: Stream
    alignment: comparison.Alignment
    series: comparison.AlignedSeries
    statistics: comparison.ErrorStatistics
    time_offset_estimated: bool
    align: str

    def as_json(self) -> Dict[str, Any]:
        """Return the ``--json`` document."""
        degrees = math.degrees
        stats = self.statistics
        alignment = self.alignment
        return {
            'reference': _stream_json(self.reference),
            'estimate': _stream_json(self.estimate),
            'matched': int(self.series.times.size),
            'time_offset_s': alignment.time_offset,
            'time_offset_std_s': alignment.time_offset_std,
            'world_alignment': {'quaternion': alignment.world.tolist(),
                                'std_rad': alignment.world_std.tolist()},
            'mounting': {'quaternion': alignment.mounting.tolist(),
                         'std_rad': alignment.mounting_std.tolist()},
            'error_deg': {'rmse': degrees(stats.rmse),
                          'mean': degrees(stats.mean),
                          'median': degrees(stats.median),
                          'p95': degrees(stats.p95),
                          'max': degrees(stats.maximum)},
            'per_axis_error_deg': {'rmse': np.degrees(stats.axis_rmse).tolist(),
                                   'max': np.degrees(stats.axis_maximum).tolist()},
        }


def _stream_json(stream):
    return {'path': stream.path, 'topic': stream.topic, 'messages': stream.messages}


def compare_streams(reference: Stream, estimate: Stream, *, time_offset: Optional[float] = None,
                    align: str = 'both', max_gap: Optional[float] = None,
                    max_offset: Optional[float] = None) -> ComparisonResult:
    """
    Estimate what ``time_offset`` (None: estimate it) and ``align`` ask, then the errors.

    ComparisonError if the streams do not overlap in time (after the offset) or the motion
    does not determine what was asked (``DegenerateMotionError``).
    """
    if align not in ALIGN_CHOICES:
        raise ComparisonError(f'align must be one of {", ".join(ALIGN_CHOICES)}, not {align!r}')
    origin = int(min(reference.stamps_ns[0], estimate.stamps_ns[0]))
    t_ref = (reference.stamps_ns - origin) * 1e-9
    t_est = (estimate.stamps_ns - origin) * 1e-9
    world, mounting = align in ('world', 'both'), align in ('mounting', 'both')
    if time_offset is None or world or mounting:
        if time_offset is not None and (t_ref[-1] + time_offset < t_est[0]
                                        or t_ref[0] + time_offset > t_est[-1]):
            raise ComparisonError(
                f'the streams do not overlap in time: reference {t_ref[0]:.3f} to '
                f'{t_ref[-1]:.3f} s, estimate {t_est[0]:.3f} to {t_est[-1]:.3f} s, '
                f'time offset {time_offset} s')
        alignment = comparison.estimate_alignment(
            t_ref, reference.quaternions, t_est, estimate.quaternions, time_offset=time_offset,
            world=world, mounting=mounting, rates_ref=reference.rates, rates_est=estimate.rates,
            max_gap=max_gap, max_offset=max_offset)
    else:
        zero = np.zeros(3)
        alignment = comparison.Alignment(float(time_offset), 0.0, comparison.IDENTITY, zero,
                                         comparison.IDENTITY, zero, 0, math.nan)
    series = comparison.aligned_series(
        t_ref, reference.quaternions, t_est, estimate.quaternions,
        time_offset=alignment.time_offset, world=alignment.world, mounting=alignment.mounting,
        max_gap=max_gap)
    return ComparisonResult(reference, estimate, alignment, series,
                            comparison.error_statistics(series.errors), time_offset is None,
                            align)


def summary(result: ComparisonResult) -> str:
    """Return the printed summary of a comparison."""
    a, s = result.alignment, result.statistics

    def stream_line(role, stream):
        rates = 'angular velocity from the messages' if stream.rates is not None else \
            'angular velocity differentiated'
        dropped = f', {stream.dropped} dropped' if stream.dropped else ''
        return (f'{role:<10}{stream.topic} in {stream.path}: {stream.messages} messages, '
                f'{stream.stamps_ns.size} samples{dropped} ({rates})')

    def rotation_line(name, quaternion, std, estimated):
        if not estimated:
            return f'{name:<16}identity (not estimated)'
        rpy = np.degrees(conversions.euler_from_quaternion(quaternion, PLOT_SEQUENCE))
        return (f'{name:<16}xyzw [{", ".join(f"{v:.6f}" for v in quaternion)}]  '
                f'+- [{", ".join(f"{v:.4f}" for v in np.degrees(std))}] deg\n'
                f'{"":<16}roll {rpy[0]:.3f} pitch {rpy[1]:.3f} yaw {rpy[2]:.3f} deg')

    offset = f'{a.time_offset:+.6f} s'
    offset += (f' +- {a.time_offset_std:.6f} s (estimated)' if result.time_offset_estimated
               else ' (given)')
    deg = np.degrees
    return '\n'.join([
        stream_line('reference', result.reference),
        stream_line('estimate', result.estimate),
        f'matched         {result.series.times.size} reference samples',
        f'time offset     {offset}: R_ref(t) = W R_est(t + offset) M',
        rotation_line('world (W)', a.world, a.world_std, result.align in ('world', 'both')),
        rotation_line('mounting (M)', a.mounting, a.mounting_std,
                      result.align in ('mounting', 'both')),
        f'error [deg]     rmse {deg(s.rmse):.4f}  mean {deg(s.mean):.4f}  median '
        f'{deg(s.median):.4f}  p95 {deg(s.p95):.4f}  max {deg(s.maximum):.4f}',
        'per axis [deg]  rmse x {:.4f} y {:.4f} z {:.4f}  max x {:.4f} y {:.4f} z {:.4f}'.format(
            *deg(s.axis_rmse), *deg(s.axis_maximum)),
    ])


def draw_comparison(result: ComparisonResult) -> Figure:
    """Return ``--plot``: the errors over time, then roll, pitch, yaw of both, aligned."""
    series = result.series
    seconds = series.times - series.times[0]
    errors = np.degrees(series.errors)
    figure = Figure(figsize=(10, 14.0), layout='constrained')
    axes = figure.subplots(5, 1, sharex=True)
    axes[0].plot(seconds, np.linalg.norm(errors, axis=1), linewidth=0.8, color='k', label='angle')
    axes[0].set_title('Error angle |log(R_ref^T W R_est M)|')
    for column, label in zip(errors.T, ('x', 'y', 'z')):
        axes[1].plot(seconds, column, linewidth=0.8, label=label)
    axes[1].set_title('Error about the reference body axes')
    for ax in axes[:2]:
        ax.set_ylabel('deg')
    reference = np.unwrap(conversions.euler_from_quaternion(series.reference, PLOT_SEQUENCE),
                          axis=0)
    estimate = conversions.euler_from_quaternion(series.estimate, PLOT_SEQUENCE)
    # The turn of 2 pi that puts each estimate angle nearest the reference's: the two
    # curves overlay wherever the reference is unwrapped to.
    estimate += 2.0 * np.pi * np.round((reference - estimate) / (2.0 * np.pi))
    for ax, name, ref, est in zip(axes[2:], ('roll', 'pitch', 'yaw'), reference.T, estimate.T):
        ax.plot(seconds, np.degrees(ref), linewidth=1.0,
                label=f'reference {result.reference.topic}')
        ax.plot(seconds, np.degrees(est), linewidth=1.0, linestyle='--',
                label=f'estimate {result.estimate.topic}, aligned')
        ax.set_title(f'{name} (ROS roll-pitch-yaw)')
        ax.set_ylabel('deg')
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper right', fontsize='small')
    axes[-1].set_xlabel('time since the first matched reference sample [s]')
    rmse = math.degrees(result.statistics.rmse)
    figure.suptitle(f'{result.estimate.topic} vs {result.reference.topic}: time offset '
                    f'{result.alignment.time_offset:+.4f} s, error rmse {rmse:.3f} deg')
    return figure


def compare_bags(reference: StreamSource, estimate: StreamSource, *,
                 time_offset: Optional[float] = None, align: str = 'both',
                 json_path: Optional[StrPath] = None, plot_path: Optional[StrPath] = None,
                 params: Optional[NodeParameters] = None, max_gap: Optional[float] = None,
                 max_offset: Optional[float] = None, overwrite: bool = False,
                 strict: bool = False,
                 report: Optional[Callable[[str], None]] = None) -> ComparisonResult:
    """
    Compare two topics; write the JSON and the plot, each complete or not at all.

    Parameters
    ----------
    reference, estimate : StreamSource
        The two topics (of one bag or two).
    time_offset : float, optional
        Seconds; estimated when None.
    align : {'none', 'world', 'mounting', 'both'}, optional
        Which of ``W`` and ``M`` to estimate (the others are the identity).
    json_path, plot_path : str or os.PathLike, optional
        Where to write the JSON document and the PNG.
    params : NodeParameters, optional
        As for :func:`read_stream`.
    max_gap, max_offset : float, optional
        See :func:`rotation_node.comparison.estimate_alignment`.
    overwrite : bool, optional
        Replace existing outputs (refused otherwise, before any work).
    strict : bool, optional
        Refuse unfinished recordings.
    report : callable, optional
        Receives the inputs' notes.

    Returns
    -------
    ComparisonResult
        The alignment, the aligned series and the error statistics.

    Raises
    ------
    BagError, ComparisonError
        One line each: what was wrong.

    """
    with contextlib.ExitStack() as stack:   # each output committed on success, else removed
        outputs = [stack.enter_context(AtomicFile(path, overwrite=overwrite))
                   for path in (json_path, plot_path) if path is not None]
        reference_stream = read_stream(reference, params, strict=strict, report=report)
        estimate_stream = read_stream(estimate, params, strict=strict, report=report)
        result = compare_streams(reference_stream, estimate_stream, time_offset=time_offset,
                                 align=align, max_gap=max_gap, max_offset=max_offset)
        contents = []
        if json_path is not None:
            contents.append(json.dumps(result.as_json(), indent=2).encode() + b'\n')
        if plot_path is not None:
            png = io.BytesIO()
            draw_comparison(result).savefig(png, format='png', dpi=100)
            contents.append(png.getvalue())
        for output, content in zip(outputs, contents):
            output.stream.write(content)
        raise_if_stopped()   # the last chance before the files are committed
    return result
