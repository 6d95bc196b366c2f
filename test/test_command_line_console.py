"""Tests of rotation_node.command_line.console: a signal while a program loads is one line."""
import importlib
import signal

import pytest

from rotation_node.command_line import console


class _Program:
    ran = False

    @classmethod
    def main(cls, **options):
        cls.ran = True
        return 0


@pytest.mark.parametrize('program', sorted(console._PROGRAMS))
@pytest.mark.parametrize('number', [signal.SIGINT, signal.SIGTERM], ids=lambda n: n.name)
def test_a_signal_while_loading_is_one_line_and_main_does_not_run(
        monkeypatch, capsys, program, number):
    def interrupted_import(name):
        signal.raise_signal(number)   # the handler runs now, in this thread, and only notes it
        return _Program

    monkeypatch.setattr(importlib, 'import_module', interrupted_import)
    before = {n: signal.getsignal(n) for n in (signal.SIGINT, signal.SIGTERM)}
    _Program.ran = False
    # A node asked to stop exits with 0, as ros2 launch expects; the tools with 128 + signal.
    assert getattr(console, program)() == (0 if program == 'rotation_node' else 128 + number)
    assert not _Program.ran
    assert capsys.readouterr().err.splitlines() == [
        f'{program}: interrupted while starting ({number.name})']
    assert {n: signal.getsignal(n) for n in before} == before


def test_each_program_runs_its_main(monkeypatch):
    modules = []

    class Program:
        @staticmethod
        def main(stop_signal=None):
            assert stop_signal is None or stop_signal.event is not None
            return 7

    def fake_import(name):
        modules.append(name)
        return Program

    monkeypatch.setattr(importlib, 'import_module', fake_import)
    assert [getattr(console, program)() for program in sorted(console._PROGRAMS)] == [7] * 3
    assert modules == [console._PROGRAMS[program] for program in sorted(console._PROGRAMS)]
    assert set(modules) == {'rotation_node.node.program', 'rotation_node.bag.cli',
                            'rotation_node.scene.cli'}
    monkeypatch.undo()
    assert all(callable(importlib.import_module(module).main) for module in modules)


def test_the_node_runs_under_the_loading_stop_signal(monkeypatch):
    """No moment between loading and the node's own start-up is left to the default handlers."""
    active = []

    class Program:
        @staticmethod
        def main(stop_signal=None):
            active.append((stop_signal, signal.getsignal(signal.SIGTERM)))
            return 0

    monkeypatch.setattr(importlib, 'import_module', lambda name: Program)
    assert console.rotation_node() == 0
    (stop, handler), = active
    assert stop is not None and handler == stop._handle
