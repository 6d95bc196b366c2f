"""Tests of rotation_node.command_line.progress: drawn on a terminal only."""
import io
import re

import pytest

from rotation_node.command_line import progress
from rotation_node.command_line.progress import ProgressBar


class _Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize('stream_class, drawn', [(_Terminal, True), (io.StringIO, False)],
                         ids=['terminal', 'pipe'])
def test_bar_only_on_a_terminal(monkeypatch, stream_class, drawn):
    monkeypatch.setattr(progress, '_REFRESH_S', 0.0)
    stream = stream_class()
    with ProgressBar(4096, stream=stream, label='converting ') as bar:
        for _ in range(2048):
            bar.update()
    frames = stream.getvalue().split('\r')[1:]
    if drawn:   # redrawn every 1024 messages (the clock is read that often), then closed
        assert [re.sub(r'\d+\.\d s', 'T', frame) for frame in frames] == [
            'converting [########......................]  25%  1024/4096 messages  T',
            'converting [###############...............]  50%  2048/4096 messages  T',
            'converting [###############...............]  50%  2048/4096 messages  T\n']
    else:
        assert stream.getvalue() == ''


def test_bar_is_clipped_at_full():
    stream = _Terminal()
    with ProgressBar(10, stream=stream) as bar:
        bar.update(25)
    assert stream.getvalue().startswith('\r[' + '#' * 30 + '] 100%  25/10 messages')
