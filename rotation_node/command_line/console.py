"""
Entry points of the console scripts: a Ctrl-C while a program loads is one line too.

Loading numpy, numba and rclpy takes a second or more. Each script starts
here instead, with nothing heavy imported: the program's module is imported
while SIGINT and SIGTERM only set a flag (:class:`StopSignal`; an exception
raised from a handler in the middle of an import could be swallowed or leave
a traceback). If one came, the program says so on one line and exits with
130 (143 for SIGTERM) instead of running its ``main``; the node exits with 0,
as ``ros2 launch`` and systemd expect of a node asked to stop, and runs its
``main`` under the same flag, so that no moment of its start-up is left to
Python's default handlers.
"""
import importlib
import sys

from rotation_node.command_line.stop_signal import exit_status, signal_name, StopSignal

_PROGRAMS = {
    'rotation_node': 'rotation_node.node.program',
    'rotation_bag': 'rotation_node.bag.cli',
    'rotation_scene': 'rotation_node.scene.cli',
}

#: Programs whose ``main(stop_signal=...)`` runs under the loading's StopSignal and that
#: exit with 0 after a stop request (a node); the others exit with 128 + the signal.
_NODES = frozenset({'rotation_node'})


def _run(program):
    with StopSignal() as stop:
        main = importlib.import_module(_PROGRAMS[program]).main
        if program in _NODES and not stop.is_set():
            return main(stop_signal=stop)
    interrupt = stop.interrupt()
    if interrupt is not None:
        print(f'{program}: interrupted while starting ({signal_name(interrupt)})',
              file=sys.stderr)
        return 0 if program in _NODES else exit_status(interrupt)
    return main()


def rotation_node() -> int:
    """Run ``rotation_node`` (:func:`rotation_node.node.program.main`)."""
    return _run('rotation_node')


def rotation_bag() -> int:
    """Run ``rotation_bag`` (:func:`rotation_node.bag.cli.main`)."""
    return _run('rotation_bag')


def rotation_scene() -> int:
    """Run ``rotation_scene`` (:func:`rotation_node.scene.cli.main`)."""
    return _run('rotation_scene')
