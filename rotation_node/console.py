"""
Entry points of the console scripts: a Ctrl-C while a program loads is one line too.

Loading numpy, numba and rclpy takes a second or more; a Ctrl-C (or SIGTERM)
in that time would end the program with a traceback from deep inside an
import. Each script starts here instead, with nothing heavy imported: the
program's module is imported under a handler that turns the interrupt into
one line and exit status 130 (143 for SIGTERM), then its ``main`` runs.
"""
import importlib
import signal
import sys

_PROGRAMS = {
    'rotation_node': 'rotation_node.node',
    'rotation_bag': 'rotation_node.bag.cli',
    'rotation_scene': 'rotation_node.scene.cli',
}


class _Terminated(Exception):
    pass


def _terminated(signal_number, frame):
    raise _Terminated()


def _run(program):
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        main = importlib.import_module(_PROGRAMS[program]).main
    except KeyboardInterrupt:
        print(f'{program}: interrupted while starting (SIGINT)', file=sys.stderr)
        return 128 + signal.SIGINT
    except _Terminated:
        print(f'{program}: interrupted while starting (SIGTERM)', file=sys.stderr)
        return 128 + signal.SIGTERM
    finally:
        signal.signal(signal.SIGTERM, previous)
    return main()


def rotation_node() -> int:
    """Run ``rotation_node`` (:func:`rotation_node.node.main`)."""
    return _run('rotation_node')


def rotation_bag() -> int:
    """Run ``rotation_bag`` (:func:`rotation_node.bag.cli.main`)."""
    return _run('rotation_bag')


def rotation_scene() -> int:
    """Run ``rotation_scene`` (:func:`rotation_node.scene.cli.main`)."""
    return _run('rotation_scene')
