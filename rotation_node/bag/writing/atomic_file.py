"""
Output files (JSON, CSV, PNG) that appear complete or not at all.

Written to a hidden temporary file beside the destination and renamed to it once complete
(atomically: ``RENAME_NOREPLACE`` without ``overwrite``); removed on failure or a signal.
Bags differ: :mod:`~rotation_node.bag.writing.part_output` leaves a crash's ``.part``.
"""
from __future__ import annotations

import contextlib
import os
import secrets
from typing import Optional, TYPE_CHECKING

from rotation_node.bag.writing.part_output import rename_exclusive
from rotation_node.errors import BagError

if TYPE_CHECKING:
    from types import TracebackType

    from rotation_node.type_aliases import StrPath


class AtomicFile:
    """
    A binary file (``stream``) written to a temporary name and renamed on ``commit()``.

    As a context manager it commits on success and discards on an exception. BagError,
    before anything is written, if the destination is a directory, exists (without
    ``overwrite``) or its directory cannot be written.
    """

    def __init__(self, path: StrPath, *, overwrite: bool = False) -> None:
        self.path = os.fspath(path)
        self.overwrite = overwrite
        if os.path.isdir(self.path):
            raise BagError(f'output {self.path} is a directory')
        if not overwrite and os.path.lexists(self.path):
            raise BagError(
                f'output {self.path} already exists (--force, overwrite=True, replaces it)')
        directory, name = os.path.split(os.path.abspath(self.path))
        self.temporary_path = os.path.join(directory, f'.{name}.{secrets.token_hex(4)}.tmp')
        try:
            # O_EXCL: never follow or reuse someone else's file; mode 0o666 so
            # that the umask applies, as for any other newly created file.
            descriptor = os.open(self.temporary_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except OSError as error:
            raise BagError(f'cannot create output {self.path}: {error.strerror}') from None
        self.stream = os.fdopen(descriptor, 'wb')

    @property
    def closed(self) -> bool:
        """Whether the file was committed or discarded."""
        return self.stream.closed

    def commit(self) -> None:
        """Flush to disk and rename the temporary file to the destination."""
        if self.closed:
            return
        try:
            self.stream.flush()
            os.fsync(self.stream.fileno())
            self.stream.close()
            if self.overwrite:
                os.replace(self.temporary_path, self.path)
            else:
                rename_exclusive(self.temporary_path, self.path)
        except FileExistsError:
            self.discard()
            raise BagError(f'output {self.path} was created by another process while this one '
                           'wrote it') from None
        except OSError as error:
            self.discard()
            raise BagError(f'cannot write output {self.path}: {error.strerror}') from None

    def discard(self) -> None:
        """Close and remove the temporary file; the destination is untouched."""
        self.stream.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.temporary_path)

    def __enter__(self) -> AtomicFile:
        return self

    def __exit__(self, exc_type: Optional[type[BaseException]], exc: Optional[BaseException],
                 traceback: Optional[TracebackType]) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()
