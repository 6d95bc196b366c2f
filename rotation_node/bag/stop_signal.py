"""
Stop on Ctrl-C (SIGINT) or SIGTERM by setting a flag, never by raising.

``record`` and ``play`` poll the flag between messages. An exception raised
from a signal handler could interrupt a write halfway through a record; a flag
lets the current message finish and the bag be closed cleanly.
"""
import signal
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


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

    def __init__(self):
        self.event = threading.Event()
        self.signal_number = None
        self._previous = {}

    def _handle(self, signal_number, frame):
        self.signal_number = signal_number
        self.event.set()

    def is_set(self):
        """Whether a stop signal arrived."""
        return self.event.is_set()

    def __enter__(self):
        for number in STOP_SIGNALS:
            self._previous[number] = signal.signal(number, self._handle)
        return self

    def __exit__(self, *exc):
        for number, handler in self._previous.items():
            signal.signal(number, handler)
