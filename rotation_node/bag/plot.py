"""
Plot a topic of a bag over time as a PNG (``rotation_bag plot``).

An output topic ``T/NAME`` of ``convert`` is drawn as :func:`output_panels` draws ``NAME``
(in the parameters' units and sequence); a plain input type's topic as its orientation in
Euler angles (gaps where unknown or invalid) and its angular velocity if any. Time is the
header stamp (else the log time) since the first message.
"""
from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple, Optional, Tuple, TYPE_CHECKING

from matplotlib.figure import Figure   # Agg, without pyplot's global state or a display
import numpy as np
from rotation_node import conversions, registry
from rotation_node.bag.convert import output_topic
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.writing.atomic_file import AtomicFile
from rotation_node.command_line.stop_signal import raise_if_stopped
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters
from rotation_node.wire.stamps import header_stamp_ns

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath


class Panel(NamedTuple):
    """One panel of a plot: a line per label, of the numbers from ``start`` on of a message."""

    title: str
    unit: str
    labels: Tuple[str, ...]
    start: int = 0


_XYZ = ('x', 'y', 'z')
_XYZW = ('x', 'y', 'z', 'w')
_MATRIX = tuple(f'R{row}{col}' for row in (1, 2, 3) for col in (1, 2, 3))


def _euler_panels(title, unit_suffix):
    def panels(params):
        kind = 'intrinsic' if conversions.parse_sequence(params.euler_sequence).intrinsic \
            else 'extrinsic'
        labels = tuple(f'{ordinal} ({letter})' for ordinal, letter
                       in zip(('1st', '2nd', '3rd'), params.euler_sequence))
        return [Panel(f'{title}, sequence {params.euler_sequence} ({kind})',
                      ('deg' if params.euler_degrees else 'rad') + unit_suffix, labels)]
    return panels


def _euler_covariance_panels(params):
    euler = _euler_panels('Euler angles', '')(params)[0]
    return [euler, Panel(f'Euler angle covariance, sequence {params.euler_sequence}',
                         euler.unit + '^2',
                         tuple(f'C{row}{col}' for row in (1, 2, 3) for col in (1, 2, 3)), 3)]


_OUTPUT_PANELS = {
    'quaternion': lambda params: [Panel('Quaternion', '', _XYZW)],
    'euler': _euler_panels('Euler angles', ''),
    'rotation_vector': lambda params: [Panel('Rotation vector', 'rad', _XYZ)],
    'axis_angle': lambda params: [Panel('Rotation axis', '', _XYZ),
                                  Panel('Rotation angle', 'rad', ('angle',), 3)],
    'matrix': lambda params: [Panel('Rotation matrix (body to world)', '', _MATRIX)],
    'angular_velocity': lambda params: [Panel(
        f'Angular velocity ({params.angular_velocity_output_frame} frame)', 'rad/s', _XYZ)],
    'euler_rates': _euler_panels('Euler angle rates', '/s'),
    'quaternion_rate': lambda params: [Panel('Quaternion rate', '1/s', _XYZW)],
    'euler_stddev': _euler_panels('Euler angle standard deviations', ''),
    'euler_covariance': _euler_covariance_panels,
}


def output_panels(name: str, params: NodeParameters) -> list:
    """Return the :class:`Panel` of output ``name`` over its ``OutputMessage.numbers``."""
    return _OUTPUT_PANELS[name](params)


def _converted_output(topics, topic):
    """Return the output whose ``convert`` topic ``topic`` is (checked in the bag), or None."""
    parent, _, name = topic.rpartition('/')
    output = registry.OUTPUTS.get(name)
    if (output is None or parent not in topics or topics[topic] != output.type_name
            or output_topic(parent, name) != topic):
        return None
    return output


def _input_type(type_name, params):
    """Return the plain input type of a topic of ``type_name`` (``input_type`` if it is one)."""
    candidates = [entry for entry in registry.INPUTS.values()
                  if entry.type_name == type_name and entry.stream is None]
    preferred = [entry for entry in candidates if entry.name == params.input_type]
    return next(iter(preferred or candidates), None)


def _input_orientation(entry, params):
    """Return ``euler(orientation)`` as the ``euler`` output; NaN if unknown, non-finite, zero."""
    sequence, degrees = params.euler_sequence, params.euler_degrees
    unknown = (math.nan,) * 3
    if entry.orientation_form == registry.EULER:
        def quaternion(angles):
            return conversions.quaternion_from_euler(angles, sequence, degrees=degrees)
    elif entry.orientation_form == registry.ROTATION_VECTOR:
        quaternion = conversions.quaternion_from_rotation_vector
    else:
        def quaternion(q):
            return q if any(q) else None

    def euler(orientation):
        if orientation is None or not all(map(math.isfinite, orientation)):
            return unknown
        q = quaternion(orientation)
        if q is None:
            return unknown
        return tuple(conversions.euler_from_quaternion(q, sequence, degrees=degrees))
    return euler


def _input_panels(entry, params):
    """Return ``(panels, numbers)``: orientation as Euler angles, angular velocity if any."""
    euler, read = _input_orientation(entry, params), entry.sample_reader()
    panels = [panel._replace(title=f'Orientation as {panel.title}')
              for panel in output_panels('euler', params)]
    if entry.angular_velocity_field is None:
        return panels, lambda msg: euler(read(msg).orientation)
    panels.append(Panel('Angular velocity', 'rad/s', _XYZ, 3))
    unknown = (math.nan,) * 3

    def numbers(msg):
        sample = read(msg)
        return (*euler(sample.orientation), *(sample.angular_velocity or unknown))
    return panels, numbers


def _panels(topics, topic, params):
    """Return ``(panels, numbers(msg))`` of a topic: the numbers of a message they index."""
    output = _converted_output(topics, topic)
    if output is not None:
        return output_panels(output.name, params), output.message.numbers
    entry = _input_type(topics[topic], params)
    if entry is not None:
        return _input_panels(entry, params)
    plottable = sorted({e.type_name for e in registry.INPUTS.values() if e.stream is None})
    streams = [e.name for e in registry.INPUTS.values()
               if e.type_name == topics[topic] and e.stream is not None]
    hint = (f' (convert it with input_type {streams[0]} first, then plot an output)'
            if streams else '')
    raise BagError(f'cannot plot {topics[topic]}{hint}: plottable are the outputs '
                   f'rotation_bag convert writes and topics of {", ".join(plottable)}')


def plot_topic(bag_path: StrPath, topic: str, output_path: StrPath, *,
               params: Optional[NodeParameters] = None, overwrite: bool = False,
               strict: bool = False, report: Optional[Callable[[str], None]] = None) -> int:
    """
    Draw ``topic`` of ``bag_path`` over time into the PNG ``output_path``.

    Parameters
    ----------
    bag_path : str or os.PathLike
        The bag to read.
    topic : str
        Its name in the bag or its ROS 2 name.
    output_path : str or os.PathLike
        Written to a temporary file and renamed, so never half-written.
    params : rotation_node.parameters.NodeParameters, optional
        The parameters the bag was converted with: Euler sequence, units and frame for the
        labels. The node's defaults if omitted.
    overwrite : bool, optional
        Replace an existing ``output_path``.
    strict : bool, optional
        Refuse an unfinished recording or a damaged MCAP file instead of plotting what it
        holds.
    report : callable, optional
        ``report(line)`` receives the input's notes (an unfinished recording, a renamed
        topic), then what reading found could not be read.

    Returns
    -------
    int
        The number of messages plotted.

    Raises
    ------
    BagError
        If the bag is unreadable, the topic is not in it or has no messages, or its type
        cannot be plotted.

    """
    params = NodeParameters() if params is None else params
    with open_bag(bag_path, strict=strict) as reader, \
            AtomicFile(output_path, overwrite=overwrite) as output:
        reader.report_notes(report)
        with reader.reporting_new_notes(report):
            times_ns, panels, values = plot_series(reader, topic, params)
        _draw(reader.topic_name(topic), times_ns, values, panels).savefig(
            output.stream, format='png', dpi=110)
        raise_if_stopped()   # the last chance before the PNG is committed
    return len(times_ns)


def plot_series(reader: Any, topic: str,
                params: NodeParameters) -> Tuple[np.ndarray, list, list]:
    """
    Return what ``plot`` draws for a topic: ``(times_ns, panels, values)``.

    Parameters
    ----------
    reader : rotation_node.bag.reading.reader.InputBag
        The open bag.
    topic : str
        Its name in the bag or its ROS 2 name.
    params : rotation_node.parameters.NodeParameters
        Euler sequence and units (of the plotted Euler angles, and for reading Euler-angle
        inputs).

    Returns
    -------
    times_ns : numpy.ndarray of int64
        Header stamp (log time for messages without a header) of each message.
    panels : list of Panel
        What each panel draws.
    values : list of numpy.ndarray
        Per panel, shape ``(messages, len(panel.labels))``; NaN where a value is unknown or
        invalid (left as a gap in the plot).

    Raises
    ------
    BagError
        If the topic is not in the bag, has no messages or cannot be plotted.

    """
    topic = reader.topic_name(topic)
    records = reader.messages([topic])
    panels, numbers = _panels(reader.topics, topic, params)
    times, rows = [], []
    for record in records:
        raise_if_stopped()
        try:
            msg = record.message()
        except BagError as error:   # a message that cannot be decoded names no file
            raise reader.naming_this_bag(error) from None
        header = getattr(msg, 'header', None)
        times.append(record.log_time_ns if header is None else header_stamp_ns(header))
        rows.append(numbers(msg))
    if not times:
        raise BagError(f'topic {topic} in {reader.path} has no messages to plot')
    table = np.asarray(rows, dtype=float)
    return (np.asarray(times, dtype=np.int64), panels,
            [table[:, panel.start:panel.start + len(panel.labels)] for panel in panels])


def _draw(topic, times_ns, values, panels):
    """Return a figure of one panel per :class:`Panel`, time in seconds since the first."""
    seconds = (times_ns - times_ns[0]) * 1e-9
    figure = Figure(figsize=(10, 3.2 * len(panels) + 0.6), layout='constrained')
    axes = figure.subplots(len(panels), 1, sharex=True, squeeze=False)
    for ax, series, panel in zip(axes[:, 0], values, panels):
        for column, label in zip(series.T, panel.labels):
            ax.plot(seconds, column, label=label, linewidth=1.0)
        ax.set_title(panel.title)
        ax.set_ylabel(panel.unit or 'value')
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper right', fontsize='small', ncols=min(len(panel.labels), 5))
    axes[-1, 0].set_xlabel('time since first message [s]')
    figure.suptitle(f'{topic}  ({len(seconds)} messages, {seconds[-1]:.3f} s)')
    return figure
