"""
Entry points of the console scripts: a Ctrl-C while a program loads is one line too.

The program's module (numpy, numba, rclpy: a second or more) is imported while SIGINT and
SIGTERM only set a flag (raised inside an import, an exception could be swallowed). If one
came, the program says so and exits 130 or 143; a node exits 0 (as ``ros2 launch`` and
systemd expect) and runs its ``main`` under the same flag.
"""
import importlib
import sys

from rotation_node.command_line.stop_signal import exit_status, signal_name, StopSignal

_PROGRAMS = {'rotation_node': 'rotation_node.node.program',
             'rotation_bag': 'rotation_node.bag.cli', 'rotation_scene': 'rotation_node.scene.cli'}

_NODES = frozenset({'rotation_node'})   # main(stop_signal=...), exit 0 when asked to stop


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
