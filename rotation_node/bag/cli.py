"""
Command line ``rotation_bag``: record, play, convert, plot, export bags; compare two topics.

Each command's module is imported only when it runs, rclpy only with ``--ros-args``. Every
failure is one line on stderr and exit status 1 (Ctrl-C, SIGTERM: 130, 143), with no output
left behind (``record`` keeps what it recorded) and the input untouched (docs/recording.md).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from typing import List, Optional, Sequence

from rotation_node.command_line.stop_signal import exit_status, signal_name, StopSignal
from rotation_node.errors import BagError, RotationNodeError

PROG = 'rotation_bag'
COMPRESSION_CHOICES = ('zstd', 'lz4', 'none')
ALIGN_CHOICES = ('none', 'world', 'mounting', 'both')   # as bag.compare's (a test checks)
_ANY_BAG = 'any bag (rosbag2 directory, .mcap, .db3, ROS 1 .bag...)'


def _record(args, ros_args):
    from rotation_node.bag.record import record
    counts = record(args.output, args.topics, duration=args.duration, overwrite=args.force,
                    compression=args.compression, ros_args=ros_args)
    _say(f'wrote {sum(counts.values())} messages to {args.output}: ' +
         (', '.join(f'{topic} {count}' for topic, count in counts.items()) or 'no topics'))


def _play(args, ros_args):
    from rotation_node.bag.play import play
    play(args.input, rate=args.rate, topics=args.topics, loop=args.loop, delay=args.delay,
         wait_for_subscribers=args.wait_for_subscribers, ros_args=ros_args, strict=args.strict,
         report=_say)


def _convert(args, ros_args):
    from rotation_node.parameters import parameters_from_yaml
    *inputs, output = args.paths
    if not inputs:
        raise BagError('convert needs an input bag and an output (IN OUT, or IN1 IN2 ... OUTDIR)')
    params = parameters_from_yaml(args.params)
    from rotation_node.bag.reading.reader import METADATA_FILE
    if len(inputs) > 1 or (os.path.isdir(output)   # IN OUTDIR: a directory that is no bag
                           and not os.path.exists(os.path.join(output, METADATA_FILE))):
        _convert_many(args, inputs, output, params)
        return
    from rotation_node.bag.convert import convert, output_topic
    stats = _reporting(convert, inputs[0], output, params, topics=args.topic,
                       overwrite=args.force, compression=args.compression, strict=args.strict)
    for topic, topic_stats in stats.items():
        outputs = ', '.join(output_topic(topic, name) for name in params.outputs)
        near = topic_stats.near_singular
        _say(f'{topic}: {topic_stats.received} messages -> {outputs}: '
             f'{topic_stats.published} messages{_dropped(topic_stats)}'
             + (f'; near gimbal lock {near}' if near else ''))
    _say(f'wrote {output}')


def _convert_many(args, inputs, output_directory, params):
    from rotation_node.bag.batch import convert_bags
    results = convert_bags(inputs, output_directory, params, jobs=args.jobs, topics=args.topic,
                           overwrite=args.force, compression=args.compression,
                           strict=args.strict, on_result=lambda result: _say(result.line))
    failed = sum(not result.ok for result in results)
    if failed:
        raise BagError(f'{failed} of {len(results)} bags failed')
    _say(f'converted {len(results)} bags into {output_directory}')


def _plot(args, ros_args):
    from rotation_node.bag.plot import plot_topic
    from rotation_node.parameters import parameters_from_yaml
    bag_name = os.path.splitext(os.path.basename(os.path.normpath(args.input)))[0]
    # /imu/euler -> <bag>_imu_euler.png; a relative name (groundtruth/euler) alike
    output = args.output or f"{bag_name}_{args.topic.lstrip('/').replace('/', '_')}.png"
    params = None if args.params is None else parameters_from_yaml(args.params)
    count = _reporting(plot_topic, args.input, args.topic, output, params=params,
                       overwrite=args.force, strict=args.strict)
    _say(f'plotted {count} messages of {args.topic} to {output}')


def _export(args, ros_args):
    from rotation_node.bag.export import export
    from rotation_node.parameters import parameters_from_yaml
    params = parameters_from_yaml(args.params)
    rows, stats = _reporting(export, args.input, args.output, params, topic=args.topic,
                             overwrite=args.force, strict=args.strict)
    _say(f'wrote {rows} rows ({", ".join(params.outputs)}) of {stats.received} messages to '
         f'{args.output}{_dropped(stats)}')


def _compare(args, ros_args):
    from rotation_node.bag.compare import compare_bags, StreamSource, summary
    from rotation_node.parameters import parameters_from_yaml
    if len(args.bags) > 2:
        raise BagError(f'compare takes one bag or two (reference, estimate), got {len(args.bags)}')
    params = None if args.params is None else parameters_from_yaml(args.params)
    reference = StreamSource(args.bags[0], args.reference, args.reference_type,
                             _frames(args.reference_frames))
    estimate = StreamSource(args.bags[-1], args.estimate, args.estimate_type,
                            _frames(args.estimate_frames))
    result = _reporting(compare_bags, reference, estimate, time_offset=args.time_offset,
                        align=args.align, json_path=args.json, plot_path=args.plot,
                        params=params, max_gap=args.max_gap, max_offset=args.max_offset,
                        overwrite=args.force, strict=args.strict)
    print(summary(result))
    for what, path in (('JSON', args.json), ('plot', args.plot)):
        if path is not None:
            _say(f'wrote the {what} to {path}')


def _frames(frames):
    return None if frames is None else tuple(frames)


def _number(kind, accept, expected):
    """Return an argparse type: ``kind(text)`` if ``accept`` takes it, else 'expected ...'."""
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not accept(value):
            raise argparse.ArgumentTypeError(f'expected {expected}, got {text!r}')
        return value
    return parse


_positive_int = _number(int, lambda value: value >= 1, 'a positive integer')
_positive_seconds = _number(float, lambda value: math.isfinite(value) and value > 0.0,
                            'a positive number of seconds')
_seconds = _number(float, math.isfinite, "'estimate' or seconds")


def _time_offset(text):
    return None if text == 'estimate' else _seconds(text)


def _add_strict(command, doing):
    """Add ``--strict``: what reading could not read (a note otherwise) is an error."""
    command.add_argument('--strict', action='store_true',
                         help='refuse unfinished recordings and damaged bags instead of '
                              f'{doing} what can be read')


def _say(text):
    print(text, file=sys.stderr)


def _dropped(stats):
    """``; <reason> <count>`` for each reason a pipeline dropped or skipped samples."""
    return ''.join(f'; {reason} {count}' for reason, count in
                   sorted({**stats.dropped, **stats.skipped}.items()))


def _reporting(run, *args, **kwargs):
    """Return ``run(..., report=...)``, then say its notes (so a failure stays one line)."""
    notes: List[str] = []
    result = run(*args, report=notes.append, **kwargs)
    for note in notes:
        _say(note)
    return result


def _add_record(commands):
    record = commands.add_parser('record', help='record live topics to an MCAP bag')
    record.add_argument('output', metavar='OUT',
                        help='rosbag2 directory to create, or a single MCAP file *.mcap')
    record.add_argument('--topics', nargs='+', required=True, metavar='TOPIC')
    record.add_argument('--duration', type=float, metavar='S',
                        help='stop after S seconds (default: at Ctrl-C or SIGTERM)')
    record.add_argument('--compression', choices=COMPRESSION_CHOICES, default='zstd',
                        help='MCAP chunk compression (default zstd, as ros2 bag record)')
    record.add_argument('--force', action='store_true', help='replace OUT')
    record.set_defaults(run=_record)


def _add_play(commands):
    play = commands.add_parser('play', help='publish the messages of a bag')
    play.add_argument('input', metavar='IN', help=_ANY_BAG)
    play.add_argument('--rate', type=float, default=1.0, metavar='R',
                      help='speed factor on the recorded timing; 0: as fast as the '
                           'subscribers acknowledge, lossless on reliable QoS (default 1)')
    play.add_argument('--topics', nargs='+', metavar='TOPIC', help='only these topics')
    play.add_argument('--loop', action='store_true', help='start again at the end')
    play.add_argument('--delay', type=float, default=0.0, metavar='S',
                      help='wait S seconds before the first message, so that subscribers '
                           'match the new publishers (default 0)')
    play.add_argument('--wait-for-subscribers', action='store_true',
                      help='start once every played topic has a subscriber (implied by --rate 0)')
    _add_strict(play, 'playing')
    play.set_defaults(run=_play)


def _add_convert(commands):
    convert = commands.add_parser(
        'convert', help="add the node's outputs for the input topics to a copy of a bag",
        usage=f'{PROG} convert IN [IN ...] OUT --params FILE [--topic T] [--compression C] '
              '[--force] [--strict] [--jobs N]',
        description="Write a copy of each input bag with the node's outputs for its input "
                    'topics. IN OUT converts one bag; IN1 IN2 ... OUTDIR (or IN OUTDIR, an '
                    'existing directory that is not a bag) converts each input into '
                    'OUTDIR/<input name>, one line per bag. An output is a rosbag2 '
                    'directory, or a single MCAP file if its name ends in .mcap.')
    convert.add_argument('paths', nargs='+', metavar='PATH',
                         help='input bags (rosbag2 directory, .mcap, .db3, ROS 1 .bag, '
                              'compressed or split), then the output bag or directory')
    convert.add_argument('--params', required=True, metavar='FILE',
                         help="the node's parameters file (rotation_node: ros__parameters: ...)")
    convert.add_argument('--topic', action='append', metavar='T',
                         help='input topic to convert (repeatable; default: every topic of '
                              'the input_type)')
    convert.add_argument('--compression', choices=COMPRESSION_CHOICES,
                         help="MCAP chunk compression (default: the input's)")
    convert.add_argument('--force', action='store_true', help='replace existing outputs')
    _add_strict(convert, 'converting')
    convert.add_argument('--jobs', type=_positive_int, default=1, metavar='N',
                         help='with several inputs, convert N bags at a time in parallel '
                              'processes (default 1)')
    convert.set_defaults(run=_convert)


def _add_plot(commands):
    plot = commands.add_parser('plot', help='plot a topic (input or converted) over time as a PNG')
    plot.add_argument('input', metavar='IN', help=_ANY_BAG)
    plot.add_argument('--topic', required=True, metavar='T')
    plot.add_argument('-o', '--output', metavar='PNG',
                      help='default: <bag name>_<topic with / as _>.png')
    plot.add_argument('--params', metavar='FILE',
                      help='parameters the bag was converted with (Euler sequence and units '
                           'for the labels; default: the node defaults)')
    plot.add_argument('--force', action='store_true', help='overwrite the PNG')
    _add_strict(plot, 'plotting')
    plot.set_defaults(run=_plot)


def _add_export(commands):
    export = commands.add_parser(
        'export', help="write the node's outputs for one topic as a CSV or Parquet table",
        description="Write the converted values of one input topic (the node's outputs, as "
                    'convert computes them) as a table: stamp_ns, frame_id, then named columns '
                    'for each output (qx..qw, roll/pitch/yaw, ...). CSV, or Parquet when the '
                    'name ends in .parquet (needs pyarrow).')
    export.add_argument('input', metavar='IN', help=_ANY_BAG)
    export.add_argument('output', metavar='OUT', help='table to write: *.csv or *.parquet')
    export.add_argument('--params', required=True, metavar='FILE',
                        help="the node's parameters file (input_type, outputs, conventions)")
    export.add_argument('--topic', metavar='T',
                        help='input topic (default: the one topic of the input_type)')
    export.add_argument('--force', action='store_true', help='replace OUT')
    _add_strict(export, 'exporting')
    export.set_defaults(run=_export)


def _add_compare(commands):
    compare = commands.add_parser(
        'compare', help='compare an orientation topic with a reference: time offset, '
                        'alignment, errors',
        description='Compare an estimate topic with a reference topic, of one bag or two, '
                    'of any input type the node reads (Imu, Pose, PoseWithCovariance, '
                    'Odometry, Quaternion, Transform, their Stamped forms, /tf between two '
                    'frames). Estimates the time offset dt, the world alignment W and the '
                    'mounting M of R_ref(t) = W R_est(t + dt) M (docs/compare.md), and the '
                    'errors of the aligned estimate at the reference stamps.')
    compare.add_argument('bags', nargs='+', metavar='BAG',
                         help="the bag of both topics, or the reference bag then the estimate's")
    compare.add_argument('--reference', required=True, metavar='T', help='reference topic')
    compare.add_argument('--estimate', required=True, metavar='T', help='estimate topic')
    for role in ('reference', 'estimate'):
        compare.add_argument(f'--{role}-frames', nargs=2, metavar=('PARENT', 'CHILD'),
                             help=f'for a /tf {role}: the orientation of CHILD in PARENT')
        compare.add_argument(f'--{role}-type', metavar='INPUT_TYPE',
                             help=f'input type of the {role} topic where its message type '
                                  'is shared (euler, rotation_vector); default from the type')
    compare.add_argument('--time-offset', type=_time_offset, default=None, metavar='estimate|S',
                         help='dt in seconds, or estimate it from the angular rates (default)')
    compare.add_argument('--align', choices=ALIGN_CHOICES, default='both',
                         help='estimate the world alignment W, the mounting M, both (default) '
                              'or none (identity)')
    compare.add_argument('--json', metavar='FILE', help='write the results as JSON')
    compare.add_argument('--plot', metavar='PNG',
                         help='write errors over time and the aligned Euler angles as a PNG')
    compare.add_argument('--max-gap', type=_positive_seconds, metavar='S',
                         help='leave out reference samples whose estimate neighbours are more '
                              'than S apart (default 5 median estimate steps)')
    compare.add_argument('--max-offset', type=_positive_seconds, metavar='S',
                         help='search time offsets within +-S (default: where the streams '
                              'overlap by half)')
    compare.add_argument('--params', metavar='FILE',
                         help="the node's parameters file: Euler sequence and unit of Euler "
                              'inputs, input_type among shared message types')
    compare.add_argument('--force', action='store_true', help='overwrite the JSON and PNG')
    _add_strict(compare, 'reading')
    compare.set_defaults(run=_compare)


#: ``rotation_bag`` COMMAND -> adds its parser (with its ``run``) to the subparsers.
_COMMANDS = {'record': _add_record, 'play': _add_play, 'convert': _add_convert, 'plot': _add_plot,
             'export': _add_export, 'compare': _add_compare}


def build_parser(command: Optional[str] = None) -> argparse.ArgumentParser:
    """Return the argument parser of ``rotation_bag``: of every command, or of ``command``."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Record, play, convert, plot and export ROS 2 bags; compare '
                               'two orientation topics.')
    commands = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    for name, add_command in _COMMANDS.items():
        if command in (None, name):
            add_command(commands)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run ``rotation_bag``; return the exit status."""
    argv = sys.argv if argv is None else [PROG, *argv]
    arguments = _without_ros_args(argv)[1:]
    command = arguments[0] if arguments and arguments[0] in _COMMANDS else None
    args = build_parser(command).parse_args(arguments)
    with StopSignal():   # a signal stops the work where it checks (see stop_signal)
        try:
            args.run(args, argv)
        except (RotationNodeError, OSError) as error:
            _error(args, error)
            return 1
        except KeyboardInterrupt as interrupt:
            print(f'{PROG} {args.command}: interrupted ({signal_name(interrupt)})',
                  file=sys.stderr)
            return exit_status(interrupt)
    return 0


def _without_ros_args(argv):
    """Return ``argv`` without its ``--ros-args ... [--]`` sections (rclpy imported only then)."""
    if '--ros-args' not in argv:
        return list(argv)
    from rclpy.utilities import remove_ros_args
    return remove_ros_args(argv)


def _error(args, error):
    """Print ``error`` on one line, whatever it holds (YAML errors span several)."""
    if isinstance(error, OSError) and not isinstance(error, RotationNodeError):
        where = f'{error.filename}: ' if error.filename else ''
        error = f'{where}{error.strerror or error}'
    print(f'{PROG} {args.command}: error: {" ".join(str(error).split())}', file=sys.stderr)
