"""
What Ctrl-C (SIGINT) and SIGTERM do in the command-line tools.

A signal handler never raises. Python runs a handler between any two
bytecodes of the main thread, also inside a ``__del__`` method, a generator
being closed or a library's ``except`` clause: an exception raised there can
be printed and swallowed ("Exception ignored in ..."), or turned into another
error (numpy reports one as a ``TypeError`` from a comparison), and the
program then goes on or dies with a traceback. So a signal only sets a flag,
and the programs look at it where stopping is safe:

- ``record`` and ``play`` poll a :class:`StopSignal` between messages, close
  the bag cleanly and exit 0;
- ``convert``, ``plot`` and ``rotation_scene`` run under one (their ``main``;
  a ``--jobs`` worker process under :func:`stop_at_checkpoints`) and call
  :func:`raise_if_stopped` between blocks of messages. It raises
  ``KeyboardInterrupt`` for SIGINT or :class:`Terminated` (a
  ``KeyboardInterrupt``) for SIGTERM, the clean-up of the unfinished output
  runs, and the tools exit with ``128 + signal number`` (130, 143). A signal
  that arrives after the last block is noted and ignored: the output is
  complete, the program finishes and exits 0.
"""
from __future__ import annotations

import signal
import threading
from typing import Any, Dict, List, Optional

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; raised as Ctrl-C's ``KeyboardInterrupt`` is, so the same clean-up runs."""


class StopSignal:
    """
    Context manager: while active, SIGINT and SIGTERM set ``event`` instead of raising.

    The previous handlers are restored on exit. Use it in the main thread (Python
    delivers signals there only) and initialise rclpy without its own handlers
    (``signal_handler_options=SignalHandlerOptions.NO``).

    Attributes
    ----------
    event : threading.Event
        Set once a stop signal arrived; ``event.wait(timeout)`` sleeps until
        then, so waits end at once on Ctrl-C.
    signal_number : int or None
        The first signal that arrived.

    """

    def __init__(self, signals: tuple = STOP_SIGNALS) -> None:
        self.event = threading.Event()
        self.signal_number: Optional[int] = None
        self._signals = signals
        self._previous: Dict[int, Any] = {}

    def _handle(self, signal_number, frame):
        if self.signal_number is None:
            self.signal_number = signal_number
        self.event.set()

    def is_set(self) -> bool:
        """Whether a stop signal arrived."""
        return self.event.is_set()

    def interrupt(self) -> Optional[KeyboardInterrupt]:
        """Return what the signal that arrived stands for (``Terminated`` for SIGTERM), or None."""
        if self.signal_number is None:
            return None
        return Terminated() if self.signal_number == signal.SIGTERM else KeyboardInterrupt()

    def __enter__(self) -> StopSignal:
        for number in self._signals:
            self._previous[number] = signal.signal(number, self._handle)
        _active.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        _active.remove(self)
        for number, handler in self._previous.items():
            signal.signal(number, handler)


_active: List[StopSignal] = []   # the StopSignals in force, the innermost last


def stop_at_checkpoints(signals: tuple = STOP_SIGNALS) -> StopSignal:
    """
    Make ``signals`` set a flag for the rest of the process; return its :class:`StopSignal`.

    For a worker process: its work then stops where it calls
    :func:`raise_if_stopped`, and a signal between two tasks is kept for
    the next one's first check.
    """
    return StopSignal(signals).__enter__()


def raise_if_stopped() -> None:
    """
    Raise ``KeyboardInterrupt`` or :class:`Terminated` if a stop signal arrived; else nothing.

    Call it where a long computation may stop: between blocks of messages,
    before a commit. Without a :class:`StopSignal` in force (a library caller)
    it does nothing, and Ctrl-C behaves as Python's default.
    """
    if _active:
        interrupt = _active[-1].interrupt()
        if interrupt is not None:
            raise interrupt


def exit_status(interrupt: KeyboardInterrupt) -> int:
    """Return the exit status after ``interrupt``: 143 for SIGTERM, 130 for Ctrl-C."""
    return 128 + (signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT)


def signal_name(interrupt: KeyboardInterrupt) -> str:
    """``'SIGTERM'`` or ``'SIGINT'``."""
    return 'SIGTERM' if isinstance(interrupt, Terminated) else 'SIGINT'
