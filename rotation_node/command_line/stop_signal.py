"""
What Ctrl-C (SIGINT) and SIGTERM do in the command-line tools: set a flag, never raise.

A handler runs between any two bytecodes (in a ``__del__``, a closing generator, a
library's ``except``), where an exception can be swallowed or turned into another error.
``record`` and ``play`` poll a :class:`StopSignal` and close the bag (exit 0); the other
tools call :func:`raise_if_stopped` between blocks: ``KeyboardInterrupt`` (``Terminated``
for SIGTERM) runs the clean-up, exit 130 or 143. A signal after the last block is ignored.
"""
from __future__ import annotations

import signal
import threading
from typing import Any, Dict, List, Optional


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; raised as Ctrl-C's ``KeyboardInterrupt`` is, so the same clean-up runs."""


class StopSignal:
    """
    Context manager: while active, SIGINT and SIGTERM set ``event`` instead of raising.

    ``event.wait(timeout)`` ends at once on a signal, ``signal_number`` is the first one;
    the previous handlers come back on exit. For the main thread (where Python delivers
    signals), with rclpy's handlers off (``SignalHandlerOptions.NO``).
    """

    def __init__(self, signals: tuple = (signal.SIGINT, signal.SIGTERM)) -> None:
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


def stop_at_checkpoints(signals: tuple) -> StopSignal:
    """Make ``signals`` set a flag for the rest of a worker process; return its StopSignal."""
    return StopSignal(signals).__enter__()


def raise_if_stopped() -> None:
    """
    Raise ``KeyboardInterrupt`` or :class:`Terminated` if a stop signal arrived; else nothing.

    Without a :class:`StopSignal` in force (a library caller) Ctrl-C is Python's default.
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
