"""
The ``rotation_node`` program: its command line, start-up and shut-down.

:func:`main` checks the ``--params-file`` files and the ``-p`` names first, the
node's own way (:func:`ros_arguments`: rclpy gives no access to them before rcl
reads the files, whose errors are many lines), so that a mistake is one line on
stderr and exit status 1; then it initialises rclpy, creates the node (imported
only then) and spins it until Ctrl-C or SIGTERM.
"""
import gc
import sys
from typing import List, Optional, Sequence, Tuple

import rclpy
from rclpy.exceptions import InvalidHandle, NotInitializedException
from rclpy.executors import ExternalShutdownException
from rclpy.signals import install_signal_handlers, SignalHandlerOptions
from rclpy.utilities import remove_ros_args
from rotation_node.command_line.stop_signal import signal_name, StopSignal
from rotation_node.errors import ParameterError
from rotation_node.parameters import (
    NODE_NAME, PARAMETERS, PARAMETERS_BY_NAME, parameters_file_sections, ROS_BUILTIN_PARAMETERS,
    unknown_parameter_error)
from rotation_node.rclpy_private import RCLError

# ROS arguments (after --ros-args, up to --) that take a value, and those that do not.
_ROS_FLAGS_WITH_VALUE = frozenset((
    '-r', '--remap', '-p', '--param', '--params-file', '-e', '--enclave', '--log-level',
    '--log-file-name', '--log-config-file'))


def ros_arguments(args: Sequence[str]) -> List[Tuple[str, Optional[str]]]:
    """
    Return the ``(flag, value)`` pairs of the ROS arguments (after ``--ros-args``, up to ``--``).

    E.g. ``[('-p', 'qos.depth:=5'), ('--disable-rosout-logs', None)]``.
    """
    pairs: List[Tuple[str, Optional[str]]] = []
    in_ros_args, tokens = False, iter(args)
    for token in tokens:
        if token == '--ros-args':
            in_ros_args = True
        elif token == '--':
            in_ros_args = False
        elif in_ros_args:
            pairs.append((token, next(tokens, None) if token in _ROS_FLAGS_WITH_VALUE else None))
    return pairs


def parameters_files(args: Sequence[str]) -> List[str]:
    """Return the files of the ``--params-file`` arguments of a command line."""
    # A --params-file without a file is rclpy's to report (as its other malformed arguments).
    return [value for flag, value in ros_arguments(args)
            if flag == '--params-file' and value is not None]


def check_parameter_names(args: Sequence[str]) -> None:
    """Raise ParameterError for a ``-p [NODE:]NAME:=VALUE`` naming no parameter of the node."""
    known = {*PARAMETERS_BY_NAME, *ROS_BUILTIN_PARAMETERS}
    for flag, value in ros_arguments(args):
        if flag in ('-p', '--param') and value is not None:
            node, _, name = value.split(':=', 1)[0].rpartition(':')   # [node:]name:=value
            if node not in ('', NODE_NAME):
                continue   # a parameter of another node of the process
            if name not in known:
                raise unknown_parameter_error(name, f' in {flag} {value}')


def usage() -> str:
    """Return the text ``rotation_node --help`` prints: how to run it, its parameters."""
    return ('usage: rotation_node [--ros-args [-r input:=TOPIC] [-p NAME:=VALUE]... '
            '[--params-file FILE]]\n\n'
            'Convert the orientations on the topic "input" and publish the outputs listed in '
            'the parameter "outputs".\nParameters: '
            + ', '.join(spec.name for spec in PARAMETERS) + '.\n')


def main(args: Optional[List[str]] = None, stop_signal: Optional[StopSignal] = None) -> int:
    """
    Run the node until Ctrl-C or SIGTERM (``--help``: print its usage); return the exit status.

    0 after a stop at any moment (during start-up with one line on stderr); 1
    with one line on stderr for an invalid parameters file or value. ``stop_signal``:
    the console script's, in force since loading. Start-up runs with signals only
    setting its flag: rclpy's handler, shutting the context from another thread,
    would surface mid-construction as any rclpy error; it is installed (chained)
    once the node exists, so that a signal ends ``spin``.
    """
    if stop_signal is None:
        with StopSignal() as stop:
            return _run(args, stop)
    return _run(args, stop_signal)


def _run(args: Optional[List[str]], stop: StopSignal) -> int:
    """Run :func:`main` with ``stop`` in force."""
    argv = sys.argv if args is None else list(args)
    try:
        own = remove_ros_args(argv)[1:]   # the program's own arguments
    except RCLError:   # malformed ROS arguments: reported by the checks or by rclpy.init
        own = []
    if {'-h', '--help'} & set(own):
        print(usage(), end='')
        return 0
    files = parameters_files(argv)
    try:   # before rclpy reads the files, whose own errors are many lines long
        for path in files:
            parameters_file_sections(path)
        check_parameter_names(argv)
    except ParameterError as exc:
        print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
        return 1
    node = None
    spinning = False
    try:
        if not stop.is_set():
            try:
                rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
            except RCLError as exc:   # e.g. a malformed --ros-args remapping
                print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
                return 1
        if not stop.is_set():
            from rotation_node.node.conversion_node import RotationNode
            node = RotationNode(parameters_files=files)
            # From here a signal also shuts the context down (rclpy's handler, chained to
            # the flag's), which ends spin; one that came before is seen below.
            install_signal_handlers(SignalHandlerOptions.ALL)
        if not stop.is_set() and node is not None:
            # The ~1e5 objects of rclpy, numpy and numba live as long as the process: keep
            # them out of the cyclic collector, whose full passes over them stall a
            # callback for ~50 ms (50 messages at 1 kHz).
            gc.freeze()
            spinning = True
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (RCLError, NotInitializedException, InvalidHandle):
        if rclpy.ok():
            raise
        # A stop request shut the context down under an rclpy call.
    except ParameterError as exc:
        print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    interrupt = stop.interrupt()
    if interrupt is not None and not spinning:
        print(f'{NODE_NAME}: interrupted while starting ({signal_name(interrupt)})',
              file=sys.stderr)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
