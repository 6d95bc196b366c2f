"""Tests of rotation_node.console: a signal while a program loads is one line, not a traceback."""
import importlib
import signal

import pytest

from rotation_node import console


class _Program:
    ran = False

    @classmethod
    def main(cls):
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
    assert getattr(console, program)() == 128 + number
    assert not _Program.ran
    assert capsys.readouterr().err.splitlines() == [
        f'{program}: interrupted while starting ({number.name})']
    assert {n: signal.getsignal(n) for n in before} == before


def test_each_program_runs_its_main(monkeypatch):
    modules = []

    class Program:
        @staticmethod
        def main():
            return 7

    def fake_import(name):
        modules.append(name)
        return Program

    monkeypatch.setattr(importlib, 'import_module', fake_import)
    assert [getattr(console, program)() for program in sorted(console._PROGRAMS)] == [7] * 3
    assert modules == [console._PROGRAMS[program] for program in sorted(console._PROGRAMS)]
    assert set(modules) == {'rotation_node.node', 'rotation_node.bag.cli',
                            'rotation_node.scene.cli'}
    monkeypatch.undo()
    assert all(callable(importlib.import_module(module).main) for module in modules)
