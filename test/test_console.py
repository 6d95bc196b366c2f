"""Tests of rotation_node.console: a signal while a program loads is one line, not a traceback."""
import importlib
import signal

import pytest

from rotation_node import console


@pytest.mark.parametrize('program', sorted(console._PROGRAMS))
def test_ctrl_c_while_loading_is_one_line_and_130(monkeypatch, capsys, program):
    def interrupted_import(name):
        raise KeyboardInterrupt()

    monkeypatch.setattr(importlib, 'import_module', interrupted_import)
    assert getattr(console, program)() == 130
    assert capsys.readouterr().err.splitlines() == [
        f'{program}: interrupted while starting (SIGINT)']


def test_sigterm_while_loading_is_one_line_and_143(monkeypatch, capsys):
    def terminated_import(name):
        signal.raise_signal(signal.SIGTERM)   # the handler raises in this thread
        raise AssertionError('SIGTERM did not interrupt the import')

    monkeypatch.setattr(importlib, 'import_module', terminated_import)
    before = signal.getsignal(signal.SIGTERM)
    assert console.rotation_bag() == 143
    assert capsys.readouterr().err.splitlines() == [
        'rotation_bag: interrupted while starting (SIGTERM)']
    assert signal.getsignal(signal.SIGTERM) is before


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
