"""
Plot a topic of a bag over time as a PNG (``rotation_bag plot``).

Meant for converted topics: ``.../euler`` (Euler angles, in the units and
sequence of the parameters the bag was converted with), ``.../angular_velocity``,
``.../euler_rates``, ``.../rotation_vector``, ``.../quaternion``,
``.../quaternion_rate``, ``.../axis_angle``, ``.../matrix``, and also raw
``sensor_msgs/msg/Imu`` (orientation quaternion and angular velocity). The
time axis is the header stamp where the message has one, else the log time,
in seconds since the first message.
"""
import numpy as np
# A bare Figure renders PNG with the Agg backend and never touches pyplot's
# global state or a display.
from matplotlib.figure import Figure

from rotation_node.bag.atomic_file import AtomicFile
from rotation_node.bag.reader import open_bag
from rotation_node.conversions import parse_sequence
from rotation_node.errors import BagError
from rotation_node.parameters import NodeParameters

_ORDINALS = ('1st', '2nd', '3rd')
_XYZ = ('x', 'y', 'z')
_XYZW = ('x', 'y', 'z', 'w')


def _xyz(vector):
    return (vector.x, vector.y, vector.z)


def _xyzw(quaternion):
    return (quaternion.x, quaternion.y, quaternion.z, quaternion.w)


def _stamped_vector(msg):
    return _xyz(msg.vector)


def _panels(type_name, output_name, params):
    """
    What to draw for a topic: a list of ``(title, unit, labels, extract)``.

    ``extract(msg)`` returns the values of one panel for one message.
    """
    angle_unit = 'deg' if params.euler_degrees else 'rad'
    if type_name == 'geometry_msgs/msg/Vector3Stamped':
        if output_name in ('euler', 'euler_rates'):
            seq = parse_sequence(params.euler_sequence)
            kind = 'intrinsic' if seq.intrinsic else 'extrinsic'
            labels = [f'{ordinal} ({letter})'
                      for ordinal, letter in zip(_ORDINALS, params.euler_sequence)]
            title, unit = (('Euler angles', angle_unit) if output_name == 'euler'
                           else ('Euler angle rates', f'{angle_unit}/s'))
            return [(f'{title}, sequence {params.euler_sequence} ({kind})', unit, labels,
                     _stamped_vector)]
        if output_name == 'angular_velocity':
            return [(f'Angular velocity ({params.angular_velocity_output_frame} frame)',
                     'rad/s', _XYZ, _stamped_vector)]
        if output_name == 'rotation_vector':
            return [('Rotation vector', 'rad', _XYZ, _stamped_vector)]
        return [('Vector', '', _XYZ, _stamped_vector)]
    if type_name == 'geometry_msgs/msg/QuaternionStamped':
        title, unit = (('Quaternion rate', '1/s') if output_name == 'quaternion_rate'
                       else ('Quaternion', ''))
        return [(title, unit, _XYZW, lambda msg: _xyzw(msg.quaternion))]
    if type_name == 'std_msgs/msg/Float64MultiArray':
        if output_name == 'axis_angle':
            return [('Rotation axis', '', _XYZ, lambda msg: msg.data[:3]),
                    ('Rotation angle', 'rad', ('angle',), lambda msg: msg.data[3:4])]
        if output_name == 'matrix':
            labels = [f'R{row}{col}' for row in (1, 2, 3) for col in (1, 2, 3)]
            return [('Rotation matrix (body to world)', '', labels, lambda msg: msg.data)]
    if type_name == 'sensor_msgs/msg/Imu':
        return [('Orientation quaternion', '', _XYZW,
                 lambda msg: _xyzw(msg.orientation)),
                ('Angular velocity', 'rad/s', _XYZ, lambda msg: _xyz(msg.angular_velocity))]
    raise BagError(f'cannot plot {type_name}; plottable: Vector3Stamped, QuaternionStamped, '
                   'Float64MultiArray (axis_angle, matrix) and Imu topics')


def _time_ns(record, msg):
    header = getattr(msg, 'header', None)
    if header is None:
        return record.log_time_ns
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def plot_topic(bag_path, topic, output_path, *, params=None, overwrite=False, strict=False,
               report=None):
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
    strict : bool, optional
        Refuse an unfinished recording instead of plotting what it holds.
    report : callable, optional
        ``report(line)`` receives the input's notes (an unfinished recording,
        a renamed topic).

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
    with open_bag(bag_path, strict=strict) as reader, \
            AtomicFile(output_path, overwrite=overwrite) as output:
        for note in reader.notes if report is not None else ():
            report(note)
        topic = reader.topic_name(topic)
        records = reader.messages([topic])
        panels = _panels(reader.topics[topic], topic.rsplit('/', 1)[-1], params)
        times, values = [], [[] for _ in panels]
        for record in records:
            msg = record.message()
            times.append(_time_ns(record, msg))
            for series, (_, _, _, extract) in zip(values, panels):
                series.append(tuple(extract(msg)))
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
    for ax, series, (title, unit, labels, _) in zip(axes[:, 0], values, panels):
        for column, label in zip(np.asarray(series, dtype=float).T, labels):
            ax.plot(seconds, column, label=label, linewidth=1.0)
        ax.set_title(title)
        ax.set_ylabel(unit or 'value')
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper right', fontsize='small', ncols=min(len(labels), 5))
    axes[-1, 0].set_xlabel('time since first message [s]')
    figure.suptitle(f'{topic}  ({len(seconds)} messages, {seconds[-1]:.3f} s)')
    return figure
