"""
Bag outputs that are created exclusively, survive crashes and appear whole (docs/recording.md).

``<output>.part`` is created with ``O_EXCL`` or ``mkdir`` (a second writer fails at once)
and renamed to the output when complete, atomically (``RENAME_NOREPLACE``, or ``rename``
and ``RENAME_EXCHANGE`` to replace). The space to close the bag is reserved beyond the end
of the file (``fallocate``), so a full disk fails the reservation before any write does.
"""
from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import shutil
from typing import Optional, TYPE_CHECKING

from rotation_node.errors import BagError

if TYPE_CHECKING:
    from rotation_node.type_aliases import StrPath

PART_SUFFIX = '.part'
STORAGE_SUFFIX = '.mcap'
METADATA_FILE = 'metadata.yaml'

_AT_FDCWD = -100
_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2
_FALLOC_FL_KEEP_SIZE = 1
_UNSUPPORTED = (errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL)

_LIBC: Optional[ctypes.CDLL]
try:   # the C library the interpreter runs on (no ctypes.util.find_library: ldconfig)
    _LIBC = ctypes.CDLL(None, use_errno=True)
except OSError:
    _LIBC = None


def _libc_function(name, *argtypes):
    function = getattr(_LIBC, name, None)
    if function is not None:
        function.argtypes = argtypes
        function.restype = ctypes.c_int
    return function


_renameat2 = _libc_function('renameat2', ctypes.c_int, ctypes.c_char_p, ctypes.c_int,
                            ctypes.c_char_p, ctypes.c_uint)
_fallocate = _libc_function('fallocate', ctypes.c_int, ctypes.c_int, ctypes.c_int64,
                            ctypes.c_int64)


def _rename2(source, destination, flags):
    """``renameat2``; OSError, ENOSYS when the C library lacks it."""
    if _renameat2 is None:
        raise OSError(errno.ENOSYS, os.strerror(errno.ENOSYS))
    if _renameat2(_AT_FDCWD, os.fsencode(source), _AT_FDCWD, os.fsencode(destination),
                  flags) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code), destination)


def rename_exclusive(source: str, destination: str) -> None:
    """Rename ``source`` to ``destination`` atomically; FileExistsError if it exists at all."""
    try:
        _rename2(source, destination, _RENAME_NOREPLACE)
        return
    except OSError as error:
        if error.errno not in _UNSUPPORTED:
            raise
    if os.path.isdir(source):
        # No RENAME_NOREPLACE (an old kernel or a file system without it): a
        # directory cannot be hard-linked, so this check and rename can race.
        if os.path.lexists(destination):
            raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), destination)
        os.rename(source, destination)
        return
    os.link(source, destination)   # fails with EEXIST atomically
    os.unlink(source)


def rename_replacing(source: str, destination: str) -> None:
    """
    Rename ``source`` to ``destination``, atomically replacing whatever is there.

    A file replaces a file with ``rename``; with a directory on either side the two are
    exchanged (``RENAME_EXCHANGE``) and the old one, now at ``source``, removed.
    """
    try:
        return rename_exclusive(source, destination)
    except FileExistsError:
        pass
    if not os.path.isdir(source) and not os.path.isdir(destination):
        os.replace(source, destination)
        return
    try:
        _rename2(source, destination, _RENAME_EXCHANGE)
    except OSError as error:
        if error.errno not in _UNSUPPORTED:
            raise
        _remove(destination)
        os.rename(source, destination)
        return
    _remove(source)


def _remove(path):
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)


def allocate(descriptor: int, offset: int, length: int) -> bool:
    """
    Allocate ``[offset, offset + length)`` of a file on disk without changing its size.

    False if the file system cannot (nothing reserved); OSError ``ENOSPC`` without space.
    """
    if _fallocate is None:
        return False
    if _fallocate(descriptor, _FALLOC_FL_KEEP_SIZE, offset, length) == 0:
        return True
    code = ctypes.get_errno()
    if code in _UNSUPPORTED:
        return False
    raise OSError(code, os.strerror(code))


def _sync_directory(path):
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass
    finally:
        os.close(descriptor)


def _part_exists_message(path):
    return (f'{path}{PART_SUFFIX} exists: another process is writing {path}, or an earlier '
            'one was killed and left its unfinished bag there (read it, or move it away)')


class BagOutput:
    """
    The files of one bag being written: ``<path>.part``, renamed to ``path`` on ``finish()``.

    A ``.mcap`` path is one file, any other a rosbag2 directory of ``<name>_0.mcap``
    (``storage_name``) and ``metadata.yaml``. BagError if the output exists (without
    ``overwrite``; again, atomically, on ``finish()``), ``<path>.part`` exists, or the
    directory cannot be written.
    """

    def __init__(self, path: StrPath, *, overwrite: bool = False) -> None:
        self.path = os.fspath(path).rstrip(os.sep) or os.fspath(path)
        self.overwrite = overwrite
        self.single_file = self.path.endswith(STORAGE_SUFFIX)
        self.part_path = self.path + PART_SUFFIX
        self.check_absent(self.path, overwrite=overwrite)
        name = os.path.basename(self.path)
        self.storage_name = name if self.single_file else f'{name}_0{STORAGE_SUFFIX}'
        try:
            if self.single_file:
                self.storage_path = self.part_path
            else:
                os.mkdir(self.part_path)
                self.storage_path = os.path.join(self.part_path, self.storage_name)
            # O_EXCL: never follow or reuse someone else's file; mode 0o666 so
            # that the umask applies, as for any other newly created file.
            descriptor = os.open(self.storage_path,
                                 os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            raise BagError(_part_exists_message(self.path)) from None
        except BaseException as error:   # also Ctrl-C, SIGTERM between the directory and the file
            if not self.single_file and os.path.isdir(self.part_path):
                _remove(self.part_path)
            if isinstance(error, OSError):
                raise BagError(f'cannot create output {self.path}: {error.strerror}') from None
            raise
        self.stream = os.fdopen(descriptor, 'wb')
        self._can_reserve = True
        self.closed = False

    @staticmethod
    def check_absent(path: StrPath, *, overwrite: bool = False) -> None:
        """Raise BagError if ``path`` exists (without ``overwrite``) or has a ``.part``."""
        path = os.fspath(path)
        if not overwrite and os.path.lexists(path):
            raise BagError(f'output {path} already exists (--force, overwrite=True, replaces it)')
        if os.path.lexists(path + PART_SUFFIX):
            raise BagError(_part_exists_message(path))

    def reserve(self, length: int) -> None:
        """Allocate ``length`` bytes beyond what is written (OSError ENOSPC), where it can."""
        if self._can_reserve:
            self._can_reserve = allocate(self.stream.fileno(), self.stream.tell(), length)

    def sync(self) -> None:
        """Write what is buffered and flush it to disk (``fdatasync``)."""
        self.stream.flush()
        os.fdatasync(self.stream.fileno())

    def finish(self, metadata_yaml: Optional[str] = None) -> None:
        """
        Close the storage file, write ``metadata.yaml`` (directories) and rename to ``path``.

        BagError if the output appeared meanwhile (without ``overwrite``) or writing failed;
        the ``.part`` is left for ``keep()`` or ``discard()``.
        """
        if self.closed:
            return
        try:
            self.stream.flush()
            os.ftruncate(self.stream.fileno(), self.stream.tell())   # frees the reservation
            os.fsync(self.stream.fileno())
            self.stream.close()
            if not self.single_file:
                if metadata_yaml is not None:
                    with open(os.path.join(self.part_path, METADATA_FILE), 'x') as stream:
                        stream.write(metadata_yaml)
                        stream.flush()
                        os.fsync(stream.fileno())
                _sync_directory(self.part_path)
            if self.overwrite:
                rename_replacing(self.part_path, self.path)
            else:
                rename_exclusive(self.part_path, self.path)
        except FileExistsError:
            raise BagError(f'output {self.path} was created by another process while this '
                           'one wrote it') from None
        except OSError as error:
            raise BagError(f'cannot write output {self.path}: {error.strerror}') from None
        self.closed = True
        _sync_directory(os.path.dirname(os.path.abspath(self.path)))

    def keep(self) -> None:
        """Close and leave the unfinished bag in ``part_path`` (after a failure)."""
        self._close_quietly()

    def discard(self) -> None:
        """Close and remove ``part_path``; the output is left as it was."""
        self._close_quietly()
        _remove(self.part_path)

    def _close_quietly(self):
        self.closed = True
        with contextlib.suppress(OSError):
            self.stream.close()   # flushes what is buffered, and closes the file even if not
