"""
What Ctrl-C (SIGINT) and SIGTERM do in the command-line tools.

``record`` and ``play`` stop by a flag (:class:`StopSignal`), polled between
messages: an exception raised from a signal handler could interrupt a write
halfway through a record; a flag lets the current message finish and the bag
be closed cleanly.

``convert``, ``plot`` and ``rotation_scene`` stop by an exception
(:func:`interrupt_on_stop_signals`): ``KeyboardInterrupt`` for SIGINT,
:class:`Terminated` (a ``KeyboardInterrupt``) for SIGTERM, raised once; the
second signal is ignored, so that removing the unfinished output cannot be
interrupted. The tools exit with ``128 + signal number`` (130, 143).
"""
from __future__ import annotations

import signal
import threading
from typing import Any, Dict, Optional

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; raised as Ctrl-C's ``KeyboardInterrupt`` is, so the same clean-up runs."""


def _raise_once(signal_number, frame):
    for number in STOP_SIGNALS:
        signal.signal(number, signal.SIG_IGN)
    if signal_number == signal.SIGTERM:
        raise Terminated()
    raise KeyboardInterrupt()


def interrupt_on_stop_signals() -> None:
    """Make the first SIGINT or SIGTERM raise ``KeyboardInterrupt`` or ``Terminated``."""
    for number in STOP_SIGNALS:
        signal.signal(number, _raise_once)


def exit_status(interrupt: KeyboardInterrupt) -> int:
    """Return the exit status after ``interrupt``: 143 for SIGTERM, 130 for Ctrl-C."""
    return 128 + (signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT)


def signal_name(interrupt: KeyboardInterrupt) -> str:
    """``'SIGTERM'`` or ``'SIGINT'``."""
    return 'SIGTERM' if isinstance(interrupt, Terminated) else 'SIGINT'


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
        The signal that arrived.

    """

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal_number: Optional[int] = None
        self._previous: Dict[int, Any] = {}

    def _handle(self, signal_number, frame):
        self.signal_number = signal_number
        self.event.set()

    def is_set(self) -> bool:
        """Whether a stop signal arrived."""
        return self.event.is_set()

    def __enter__(self) -> StopSignal:
        for number in STOP_SIGNALS:
            self._previous[number] = signal.signal(number, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
