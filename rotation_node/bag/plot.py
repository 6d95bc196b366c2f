"""
Plot a topic of a bag over time as a PNG (``rotation_bag plot``).

Meant for converted topics: a topic that ``rotation_bag convert`` wrote for
the output ``NAME`` of an input topic ``T`` (``T/NAME``, ``T`` in the bag,
the type the output's) is drawn as that output of
:data:`rotation_node.messages.OUTPUTS` declares (Euler angles in the units and
sequence of the parameters the bag was converted with). A topic of an input
type (``sensor_msgs/msg/Imu``...) is drawn as its orientation and angular
velocity; a type several input types share (Vector3Stamped) is read as
``input_type`` of the parameters. The time axis is the header stamp where the
message has one, else the log time, in seconds since the first message.
"""
import numpy as np
# A bare Figure renders PNG with the Agg backend and never touches pyplot's
# global state or a display.
from matplotlib.figure import Figure

from rotation_node import messages
from rotation_node.bag.atomic_file import AtomicFile
from rotation_node.bag.convert import output_topic
from rotation_node.bag.mcap_io import BagReader
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters
from rotation_node.stamps import header_stamp_ns


def _converted_output(topics, topic):
    """The output whose ``convert`` topic ``topic`` is (checked against the bag), or None."""
    parent, _, name = topic.rpartition('/')
    output = messages.OUTPUTS.get(name)
    if (output is None or parent not in topics or topics[topic] != output.type_name
            or output_topic(parent, name) != topic):
        return None
    return output


def _input_type(type_name, params):
    """The plain input type of a topic of ``type_name`` (``input_type`` if it is one)."""
    candidates = [entry for entry in messages.INPUTS.values()
                  if entry.type_name == type_name and entry.stream is None]
    preferred = [entry for entry in candidates if entry.name == params.input_type]
    return (preferred or candidates or [None])[0]


def _panels(topics, topic, params):
    """
    What to draw for a topic: ``(panels, numbers)``.

    ``panels`` are :class:`rotation_node.messages.Panel`; ``numbers(msg)`` gives the
    numbers of one message that they index.
    """
    output = _converted_output(topics, topic)
    if output is not None:
        return output.panels(params), output.message.numbers
    entry = _input_type(topics[topic], params)
    if entry is not None:
        read = entry.sample_reader()
        return (messages.input_panels(entry, params),
                lambda msg: messages.sample_numbers(entry, read(msg)))
    plottable = sorted({e.type_name for e in messages.INPUTS.values()})
    raise BagError(f'cannot plot {topics[topic]}: plottable are the outputs rotation_bag '
                   f'convert writes and topics of {", ".join(plottable)}')


def _time_ns(record, msg):
    header = getattr(msg, 'header', None)
    if header is None:
        return record.log_time_ns
    return header_stamp_ns(header)


def plot_topic(bag_path, topic, output_path, *, params=None, overwrite=False):
    """
    Draw ``topic`` of ``bag_path`` over time into the PNG ``output_path``.

    Parameters
    ----------
    bag_path : str or os.PathLike
    topic : str
    output_path : str or os.PathLike
        Written to a temporary file and renamed, so never half-written.
    params : rotation_node.parameters.NodeParameters, optional
        The parameters the bag was converted with: Euler sequence, units and
        frame for the labels. The node's defaults if omitted.
    overwrite : bool, optional
        Replace an existing ``output_path``.

    Returns
    -------
    int
        The number of messages plotted.

    Raises
    ------
    BagError
        If the bag is unreadable, the topic is not in it or has no messages,
        or its type cannot be plotted.

    """
    params = NodeParameters() if params is None else params
    with AtomicFile(output_path, overwrite=overwrite) as output, BagReader(bag_path) as reader:
        records = reader.messages([topic])
        panels, numbers = _panels(reader.topics, topic, params)
        times, values = [], [[] for _ in panels]
        for record in records:
            msg = record.message()
            times.append(_time_ns(record, msg))
            msg_numbers = numbers(msg)
            for series, panel in zip(values, panels):
                series.append(tuple(msg_numbers[panel.start:panel.start + len(panel.labels)]))
        if not times:
            raise BagError(f'topic {topic} in {bag_path} has no messages to plot')
        _draw(topic, np.asarray(times, dtype=np.int64), values, panels).savefig(
            output.stream, format='png', dpi=110)
    return len(times)


def _draw(topic, times_ns, values, panels):
    """A figure with one panel per entry of ``panels``, time in seconds since the first."""
    seconds = (times_ns - times_ns[0]) * 1e-9
    figure = Figure(figsize=(10, 3.2 * len(panels) + 0.6), layout='constrained')
    axes = figure.subplots(len(panels), 1, sharex=True, squeeze=False)
    for ax, series, panel in zip(axes[:, 0], values, panels):
        for column, label in zip(np.asarray(series, dtype=float).T, panel.labels):
            ax.plot(seconds, column, label=label, linewidth=1.0)
        ax.set_title(panel.title)
        ax.set_ylabel(panel.unit or 'value')
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper right', fontsize='small', ncols=min(len(panel.labels), 5))
    axes[-1, 0].set_xlabel('time since first message [s]')
    figure.suptitle(f'{topic}  ({len(seconds)} messages, {seconds[-1]:.3f} s)')
    return figure
