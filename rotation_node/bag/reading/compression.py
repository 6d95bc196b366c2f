"""
rosbag2's zstd compression: ``file`` mode (``bag_0.mcap.zstd``) and ``message`` mode.

A zstd frame starts with ``28 b5 2f fd``, CDR data never does (its first byte is zero): a
compressed message is recognised without the bag's metadata.
"""
import os
import shutil
from typing import BinaryIO

import zstandard

ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'
LZ4_MAGIC = b'\x04\x22\x4d\x18'
ZstdError = zstandard.ZstdError


def is_zstd(data: bytes) -> bool:
    """Whether ``data`` (a message or the start of a file) begins with a zstd frame."""
    return data[:4] == ZSTD_MAGIC


def decompressed_message(data: bytes) -> bytes:
    """Return a message's CDR bytes, decompressed if rosbag2 compressed it (ZstdError if bad)."""
    if not is_zstd(data):
        return data
    # A streaming decompressor: rosbag2 does not always record the content size.
    return zstandard.ZstdDecompressor().decompressobj().decompress(data)


def zstd_prefix(stream: BinaryIO, size: int) -> bytes:
    """Return the first ``size`` bytes (or fewer) a zstd stream holds; ZstdError if invalid."""
    with zstandard.ZstdDecompressor().stream_reader(stream, closefd=False) as reader:
        return reader.read(size)


def decompress_file(source: str, target: str) -> None:
    """Decompress the zstd file ``source`` into the new file ``target``, streaming."""
    with open(source, 'rb') as compressed, open(target, 'xb') as plain:
        with zstandard.ZstdDecompressor().stream_reader(compressed, closefd=False) as reader:
            shutil.copyfileobj(reader, plain, 1 << 20)


def stored_name(path: str) -> str:
    """Return the name of a storage file without a ``.zstd`` file-compression suffix."""
    base = os.path.basename(path)
    return base[:-len('.zstd')] if base.endswith('.zstd') else base
