"""A one-line progress bar on a terminal, nothing elsewhere."""
import sys
import time
from typing import Optional, TextIO

_REFRESH_S = 0.2
_CHECK_EVERY = 1024   # messages between clock reads: keeps update() to an increment
_WIDTH = 30


class ProgressBar:
    """
    ``label[#########.....]  61%  122000/200000 messages  3.1 s``, redrawn in place.

    Drawn only on a terminal (stderr by default), so pipes, logs and CI stay clean; clipped
    at ``total``. A context manager; ``update()`` once per item.
    """

    def __init__(self, total: int, *, stream: Optional[TextIO] = None, label: str = '') -> None:
        self.total = max(int(total), 1)
        self.stream = sys.stderr if stream is None else stream
        self.label = label
        self.enabled = self.stream.isatty()
        self.count = 0
        self._next_check = _CHECK_EVERY
        self._start = time.monotonic()
        self._next_draw = self._start

    def update(self, items: int = 1) -> None:
        """Count ``items`` more; redraw at most every 0.2 s."""
        self.count += items
        if self.enabled and self.count >= self._next_check:
            self._next_check = self.count + _CHECK_EVERY
            if time.monotonic() >= self._next_draw:
                self._draw()

    def _draw(self):
        now = time.monotonic()
        self._next_draw = now + _REFRESH_S
        fraction = min(self.count / self.total, 1.0)
        filled = round(fraction * _WIDTH)
        self.stream.write(
            f'\r{self.label}[{"#" * filled}{"." * (_WIDTH - filled)}] {fraction:4.0%}  '
            f'{self.count}/{self.total} messages  {now - self._start:.1f} s')
        self.stream.flush()

    def close(self) -> None:
        """Draw the final state and end the line."""
        if self.enabled:
            self._draw()
            self.stream.write('\n')
            self.stream.flush()

    def __enter__(self) -> 'ProgressBar':
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
