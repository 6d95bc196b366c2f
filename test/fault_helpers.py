"""
Fault injection for the bag tests: small file systems, killed processes, unfinished bags.

``small_filesystem`` mounts a size-limited tmpfs where the tests may mount one
(as root, where ``mount`` works); ``limited_allocation`` is the fallback that
needs no privileges: it makes the writer's disk-space reservation (the call
through which a full disk shows first) fail beyond a byte limit.
``linear_scan`` reads an unfinished MCAP file the way a recovery does, with the
``mcap`` library's stream reader (an oracle independent of the package's
reader): every complete record up to the first incomplete one.
"""
import contextlib
import errno
import functools
import os
import subprocess
import time

from mcap.exceptions import McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
import pytest


@functools.lru_cache(maxsize=1)
def can_mount():
    """Whether this process may mount a tmpfs (root, and ``mount`` allowed here)."""
    if os.geteuid() != 0:
        return False
    probe = f'/tmp/rotation_node_mount_probe_{os.getpid()}'
    os.makedirs(probe, exist_ok=True)
    try:
        mounted = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=64k', 'tmpfs', probe],
                                 capture_output=True, timeout=20).returncode == 0
        if mounted:
            subprocess.run(['umount', probe], capture_output=True, timeout=20)
        return mounted
    except (OSError, subprocess.SubprocessError):
        return False
    finally:
        os.rmdir(probe)


@contextlib.contextmanager
def small_filesystem(directory, size_bytes):
    """Mount a tmpfs of ``size_bytes`` on ``directory`` (created) for the ``with`` block."""
    os.makedirs(directory, exist_ok=True)
    subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={size_bytes}', 'tmpfs',
                    str(directory)], check=True, capture_output=True, timeout=20)
    try:
        yield directory
    finally:
        for _ in range(50):
            if subprocess.run(['umount', str(directory)], capture_output=True,
                              timeout=20).returncode == 0:
                break
            time.sleep(0.1)


def limited_allocation(monkeypatch, limit_bytes):
    """Make the writer's space reservation fail with ENOSPC beyond ``limit_bytes`` of a file."""
    from rotation_node.bag.writing import part_output as output

    def allocate(descriptor, offset, length):
        if offset + length > limit_bytes:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return True

    monkeypatch.setattr(output, 'allocate', allocate)


#: The two ways a test fills the disk: a real small file system, or the injected failure.
FULL_DISKS = ('tmpfs', 'injected')


@contextlib.contextmanager
def small_disk(kind, directory, size_bytes, monkeypatch):
    """
    Yield ``directory`` (created), where writing a bag fails beyond ``size_bytes``.

    ``kind`` is ``'tmpfs'`` (a real tmpfs of that size; the test is skipped
    where none can be mounted, the injected case covering the same code) or
    ``'injected'`` (:func:`limited_allocation`).
    """
    if kind == 'tmpfs':
        if not can_mount():
            pytest.skip('cannot mount a tmpfs here (the injected case covers the logic)')
        with small_filesystem(directory, size_bytes):
            yield directory
    else:
        os.makedirs(directory, exist_ok=True)
        limited_allocation(monkeypatch, size_bytes)
        yield directory


def linear_scan(path):
    """
    Return ``[(topic, log_time, publish_time, data)]`` of every complete message of an MCAP file.

    Reads records in file order until the first incomplete or corrupt one
    (CRCs checked), as a recovery of an unfinished recording does.
    """
    topics = {}
    messages = []
    with open(path, 'rb') as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message):
                    messages.append((topics[record.channel_id], record.log_time,
                                     record.publish_time, record.data))
        except (McapError, ValueError, EOFError):
            pass
    return messages


def wait_for(condition, timeout):
    """Poll ``condition()`` every 10 ms until true; return whether it became true in time."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return condition()
