"""
rosbag2's file and message compression: recognising and undoing it.

rosbag2 compresses a bag in one of three ways (``ros2 bag record
--compression-mode``): ``file`` compresses each storage file as a whole
(``bag_0.mcap.zstd``), ``message`` compresses each message's serialized bytes
(inside an ordinary storage file), and MCAP storage may compress its chunks
(``zstd`` or ``lz4``), which the mcap library undoes. rosbag2's compressor for
the first two is zstd. A zstd frame starts with the magic number
``28 b5 2f fd``, and CDR data never does (its first byte is zero), so a
message can be recognised as compressed without the bag's metadata.
"""
import os
import shutil
from typing import BinaryIO

import zstandard

#: The first four bytes of a zstd frame.
ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'
#: The first four bytes of an lz4 frame.
LZ4_MAGIC = b'\x04\x22\x4d\x18'
_COPY_BUFFER = 1 << 20

#: What zstandard raises for data that is not a valid zstd frame.
ZstdError = zstandard.ZstdError


def is_zstd(data: bytes) -> bool:
    """Whether ``data`` (a message or the start of a file) begins with a zstd frame."""
    return data[:4] == ZSTD_MAGIC


def decompressed_message(data: bytes) -> bytes:
    """
    Return a message's serialized bytes, undoing rosbag2's message compression.

    Parameters
    ----------
    data : bytes
        As stored: CDR, or CDR compressed into one zstd frame.

    Returns
    -------
    bytes
        ``data`` itself if it is not compressed.

    Raises
    ------
    zstandard.ZstdError
        If ``data`` starts like a zstd frame but is not a valid one.

    """
    if not is_zstd(data):
        return data
    # A streaming decompressor: rosbag2 does not always record the content size.
    return zstandard.ZstdDecompressor().decompressobj().decompress(data)


def zstd_prefix(stream: BinaryIO, size: int) -> bytes:
    """
    Return the first ``size`` bytes (or fewer) that a zstd-compressed stream holds.

    Enough to recognise what a ``.zstd`` file contains before decompressing it
    whole.

    Raises
    ------
    zstandard.ZstdError
        If the stream is not valid zstd.

    """
    with zstandard.ZstdDecompressor().stream_reader(stream, closefd=False) as reader:
        return reader.read(size)


def decompress_file(source: str, target: str) -> None:
    """
    Decompress the zstd file ``source`` (rosbag2's file compression) into ``target``.

    Streams: memory does not grow with the file.

    Raises
    ------
    zstandard.ZstdError
        If ``source`` is not valid zstd.
    OSError
        If a file cannot be read or written.

    """
    with open(source, 'rb') as compressed, open(target, 'xb') as plain:
        with zstandard.ZstdDecompressor().stream_reader(compressed, closefd=False) as reader:
            shutil.copyfileobj(reader, plain, _COPY_BUFFER)


def stored_name(path: str) -> str:
    """Return the name of a storage file without a ``.zstd`` file-compression suffix."""
    base = os.path.basename(path)
    return base[:-len('.zstd')] if base.endswith('.zstd') else base
