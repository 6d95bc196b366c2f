"""
Tests of rotation_node.command_line.stop_signal: a signal sets a flag the program checks.

The handler never raises: an exception raised from a handler that Python runs
inside a ``__del__`` is printed and swallowed, and the stop is lost. Here a
signal delivered inside ``__del__`` is still there at the next check.
"""
import os
import signal

import pytest
from rotation_node.command_line.stop_signal import (
    exit_status, raise_if_stopped, signal_name, StopSignal, Terminated)


def _deliver(number):
    """Send ``number`` to this process and let Python run its handler now."""
    os.kill(os.getpid(), number)
    signal.pthread_sigmask(signal.SIG_BLOCK, [])   # a call into C: pending handlers run after it


@pytest.mark.parametrize('number, expected', [(signal.SIGTERM, Terminated),
                                              (signal.SIGINT, KeyboardInterrupt)],
                         ids=['SIGTERM', 'SIGINT'])
def test_a_signal_is_raised_at_the_next_check_only(number, expected):
    with StopSignal() as stop:
        _deliver(number)
        assert stop.is_set() and stop.signal_number == number   # noted, nothing raised yet
        with pytest.raises(expected) as raised:
            raise_if_stopped()
    assert type(raised.value) is expected
    assert exit_status(raised.value) == 128 + number
    assert signal_name(raised.value) == signal.Signals(number).name


def test_a_signal_inside_a_destructor_is_not_lost(capsys):
    class Resource:
        def __del__(self):
            _deliver(signal.SIGTERM)
            self.closed = True   # more bytecode after the handler ran

    with StopSignal():
        Resource()
        with pytest.raises(Terminated):
            raise_if_stopped()
    assert capsys.readouterr().err == ''   # no "Exception ignored in ..."


def test_the_first_signal_is_the_one_reported():
    with StopSignal() as stop:
        _deliver(signal.SIGINT)
        _deliver(signal.SIGTERM)
        with pytest.raises(KeyboardInterrupt) as raised:
            raise_if_stopped()
    assert stop.signal_number == signal.SIGINT and not isinstance(raised.value, Terminated)


def test_without_a_stop_signal_in_force_the_check_does_nothing():
    raise_if_stopped()


def test_nested_stop_signals_restore_the_outer_handlers():
    before = signal.getsignal(signal.SIGTERM)
    with StopSignal() as outer:
        with StopSignal() as inner:
            _deliver(signal.SIGTERM)
        assert inner.is_set() and not outer.is_set()
        raise_if_stopped()   # the inner one is over: its signal is its own
        _deliver(signal.SIGTERM)
        assert outer.is_set()
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_stop_signal_for_sigterm_only_leaves_sigint_alone():
    before = signal.getsignal(signal.SIGINT)
    with StopSignal((signal.SIGTERM,)):
        assert signal.getsignal(signal.SIGINT) is before
    assert signal.getsignal(signal.SIGINT) is before
