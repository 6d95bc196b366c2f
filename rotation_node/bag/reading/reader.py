"""
Every input bag as one stream of ROS 2 messages (:func:`open_bag`; the formats: docs/bags.md).

Inputs are recognised by their first bytes, not their names. The storage files of a split bag
are merged in log-time order (ties in file order), so that one pipeline per topic runs across
the splits. Topics whose names are not valid in ROS 2 are renamed (``topic_names``); topics
that cannot be decoded are listed and read as stored. The input is only ever read.
"""
import contextlib
import dataclasses
import heapq
import operator
import os
import re
from typing import Callable, Dict, Iterable, Iterator, List, Optional, Tuple, Union

from rotation_node.bag import metadata_yaml
from rotation_node.bag.mcap_layout import MCAP_MAGIC
from rotation_node.bag.reading.compression import (
    decompress_file, LZ4_MAGIC, stored_name, ZSTD_MAGIC, zstd_prefix, ZstdError)
from rotation_node.bag.reading.mcap_reader import (
    add_topic, BagReader, checked_topics, compression_name)
from rotation_node.bag.reading.topic_names import topic_renames
from rotation_node.bag.records import BagMessage, TopicMetadata
from rotation_node.errors import BagError

METADATA_FILE = 'metadata.yaml'
STORAGE_PLUGINS = ('mcap', 'sqlite3')
_SQLITE_MAGIC = b'SQLite format 3\x00'
_ROS1_MAGIC = re.compile(rb'#ROSBAG V(\d+\.\d+)\n')
_SNIFF_SIZE = 64
_STORAGE_SUFFIXES = ('.mcap', '.db3', '.mcap.zstd', '.db3.zstd')
_KINDS = ((LZ4_MAGIC, 'lz4-compressed file (rosbag2 compresses files with zstd)'),
          (b'\x1f\x8b', 'gzip-compressed file'), (b'BZh', 'bzip2-compressed file'),
          (b'PK\x03\x04', 'zip archive'))


def _file_kind(prefix: bytes) -> str:
    """Say what a file that is not a bag is, from its first bytes (for the error line)."""
    for magic, kind in _KINDS:
        if prefix.startswith(magic):
            return kind
    try:
        text = prefix.decode('utf-8')
    except UnicodeDecodeError:   # a multi-byte character cut at the end is still text
        text = prefix[:-3].decode('utf-8', 'ignore') if len(prefix) > 3 else ''
    if text and all(c.isprintable() or c in '\t\r\n' for c in text):
        return 'text file'
    return 'binary file of unknown format'


def _natural_key(name):
    """Sort key that puts ``bag_2`` before ``bag_10``."""
    return [int(part) if part.isdigit() else part for part in re.split(r'(\d+)', name)]


def _directory_layout(path: str) -> Tuple[List[str], str, str, Optional[str]]:
    """Return a rosbag2 directory's storage files, storage plugin, compression mode and note."""
    metadata_path = os.path.join(path, METADATA_FILE)
    if not os.path.exists(metadata_path):
        files = sorted((name for name in os.listdir(path) if name.endswith(_STORAGE_SUFFIXES)),
                       key=_natural_key)
        if not files:
            raise BagError(f'{path}: directory without {METADATA_FILE} or storage files '
                           f'({", ".join("*" + s for s in _STORAGE_SUFFIXES)}), not a bag')
        return [os.path.join(path, name) for name in files], '', '', f'no {METADATA_FILE}'
    try:
        with open(metadata_path, encoding='utf-8') as stream:
            info = metadata_yaml.load(stream)['rosbag2_bagfile_information']
        storage = info['storage_identifier']
        names = [os.path.basename(name) for name in info['relative_file_paths']]
        mode = str(info.get('compression_mode') or '').lower()
        compression_format = str(info.get('compression_format') or '').lower()
    except (OSError, UnicodeDecodeError) as error:
        raise BagError(f'cannot read {metadata_path}: {error}') from None
    except (metadata_yaml.YAMLError, TypeError, KeyError) as error:
        raise BagError(f'{metadata_path}: not rosbag2 bag metadata '
                       f'({type(error).__name__}: {error})') from None
    if storage not in STORAGE_PLUGINS:
        raise BagError(f'{path}: rosbag2 storage plugin {storage!r} is not installed '
                       f'(readable: {", ".join(STORAGE_PLUGINS)})')
    if mode in ('file', 'message') and compression_format != 'zstd':
        raise BagError(f'{path}: rosbag2 compression format {compression_format!r} is not '
                       'supported (readable: zstd)')
    missing = [name for name in names if not os.path.isfile(os.path.join(path, name))]
    if missing:
        raise BagError(f'{path}: storage file {", ".join(missing)} listed in {METADATA_FILE} '
                       'is missing')
    return ([os.path.join(path, name) for name in names], storage,
            '' if mode == 'none' else mode, None)


class InputBag:
    """
    One input bag (a file, a rosbag2 directory, a ROS 1 bag) read as one stream; closes it.

    Made by :func:`open_bag`; ``description`` says what it is (``'MCAP file (zstd chunks)'``).
    ``topics``, ``topic_metadata`` and ``message_counts`` use the names of ``renames`` (``{name
    in the bag: name used}``); ``compression`` is the input's as MCAP chunk compression
    (rosbag2's and ROS 1's bz2 count as zstd); ``recovered``: the messages of an unfinished
    recording, else None; ``notes``: one line for each thing the user should know (an MCAP
    file read through its index adds what it could not read once read to the end).
    """

    def __init__(self, path: str, description: str, opener: '_Opener', *,
                 compression: Optional[str] = None, note: Optional[str] = None) -> None:
        self.path = path
        self.description = description
        self._opener = opener
        sources = opener.sources
        topic_metadata: Dict[str, TopicMetadata] = {}
        message_counts: Dict[str, int] = {}
        for source in sources:
            for topic, metadata in source.topic_metadata.items():
                add_topic(topic_metadata, message_counts, topic, metadata,
                          source.message_counts.get(topic, 0), path)
        self._source_topics = [set(source.topic_metadata) for source in sources]
        self.renames = topic_renames(topic_metadata)
        self._original = {self.renames.get(topic, topic): topic for topic in topic_metadata}
        self.topic_metadata = {new: dataclasses.replace(topic_metadata[old], name=new)
                               for new, old in self._original.items()}
        self.message_counts = {new: message_counts[old] for new, old in self._original.items()}
        self.topics = {topic: m.type_name for topic, m in self.topic_metadata.items()}
        self.compression = compression or compression_name({s.compression for s in sources})
        unfinished = note is not None or any(s.recovered is not None for s in sources)
        self.recovered = sum(self.message_counts.values()) if unfinished else None
        self.notes = []
        if self.recovered is not None:
            self.notes.append(f'{path}: unfinished recording, recovered {self.recovered} messages'
                              + (f' ({note})' if note else ''))
        self.notes.extend(note for source in sources for note in source.notes)
        self.notes.extend(f'{path}: topic {original!r} is not a valid ROS 2 name; using {new}'
                          for original, new in sorted(self.renames.items()))

    def topic_name(self, name: str) -> str:
        """Return the name a topic (named here or in the bag) has here; BagError if none."""
        name, = checked_topics([self.renames.get(name, name)], self.topics, self.path)
        return name

    def report_contents(self, report: Optional[Callable[[str], None]]) -> None:
        """Pass to ``report`` what this bag is (its description, how many messages), its notes."""
        if report is not None:
            report(f'{self.path}: {self.description}, '
                   f'{sum(self.message_counts.values())} messages')
        self.report_notes(report)

    def report_notes(self, report: Optional[Callable[[str], None]]) -> None:
        """Pass each of this bag's notes to ``report``, if there is one."""
        if report is not None:
            for note in self.notes:
                report(note)

    @contextlib.contextmanager
    def reporting_new_notes(self, report: Optional[Callable[[str], None]]) -> Iterator[None]:
        """Pass to ``report``, after the block, the notes added in it (none if it raises)."""
        noted = len(self.notes)
        yield
        if report is not None:
            for note in self.notes[noted:]:
                report(note)

    def naming_this_bag(self, error: BagError) -> BagError:
        """Return ``error`` if it names this bag (or one of its files), else ``<path>: error``."""
        text = str(error)
        named = re.search(rf'(^|\s){re.escape(self.path)}(\W|$)', text) is not None
        return error if named else BagError(f'{self.path}: {text}')

    def messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[BagMessage]:
        """
        Iterate over the messages in log-time order across all storage files, as CDR.

        Ties keep the order of the files, then the order within a file. Topic names are the
        ones used here; ``topics`` (named here or in the bag) selects topics, as
        :meth:`~rotation_node.bag.reading.mcap_reader.BagReader.messages` does. Topics of
        another serialization format are as stored.
        """
        wanted = (set(self._original) if topics is None
                  else {self.topic_name(topic) for topic in topics})
        originals = {self._original[topic] for topic in wanted}
        streams = [source.messages(sorted(originals & source_topics))
                   for source, source_topics in zip(self._opener.sources, self._source_topics)
                   if originals & source_topics]
        if len(streams) <= 1:
            merged = streams[0] if streams else iter(())
        else:
            merged = heapq.merge(*streams, key=operator.attrgetter('log_time_ns'))
        return self._noted(self._renamed(merged) if self.renames else merged)

    def _renamed(self, records):
        renames = self.renames
        for record in records:
            record.topic = renames.get(record.topic, record.topic)
            yield record

    def _noted(self, records):
        """Yield ``records``; then add to ``notes`` what reading them found could not be read."""
        yield from records
        for source in self._opener.sources:
            self.notes.extend(note for note in source.notes if note not in self.notes)

    def close(self) -> None:
        """Close every storage file and remove decompressed temporary copies."""
        self._opener.close()

    def __enter__(self) -> 'InputBag':
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Opener:
    """Opens the storage files of one input; owns the temporary directory of decompressed files."""

    def __init__(self, strict):
        self.strict = strict
        self.tmpdir = None
        self.sources = []

    def open_file(self, path: str, *, shown: Optional[str] = None, compressed: bool = False):
        """Open one storage file by its content; ``shown`` is the path named in errors."""
        shown = shown or path
        try:
            with open(path, 'rb') as stream:
                prefix = stream.read(_SNIFF_SIZE)
        except OSError as error:
            raise BagError(f'cannot open bag {shown}: {error.strerror}') from None
        if not prefix:
            raise BagError(f'{shown}: empty file (0 bytes), not a bag')
        if prefix.startswith(MCAP_MAGIC):
            return self._add(BagReader(path, strict=self.strict)), 'mcap'
        if prefix.startswith(_SQLITE_MAGIC):   # apsw, imported only for sqlite3
            from rotation_node.bag.reading.rosbag2_sqlite3 import open_sqlite3_file
            return self._add(open_sqlite3_file(path, shown=shown, strict=self.strict)), 'sqlite3'
        version = _ROS1_MAGIC.match(prefix)
        if version is not None:
            from rotation_node.bag.reading.ros1 import open_ros1_bag, SUPPORTED_VERSION
            if version[1].decode() != SUPPORTED_VERSION:
                raise BagError(f'{shown}: ROS 1 bag, version {version[1].decode()} '
                               f'(supported: {SUPPORTED_VERSION})')
            return self._add(open_ros1_bag(path)), 'ROS 1'
        if prefix.startswith(ZSTD_MAGIC) and not compressed:
            return self._open_zstd(path, shown)
        kind = _file_kind(prefix)
        if compressed:
            raise BagError(f'{shown}: zstd-compressed file that does not hold a bag '
                           f'(it holds a {kind})')
        raise BagError(f'{shown}: {kind}, not a bag (readable: rosbag2 directories, MCAP, '
                       'sqlite3 and ROS 1 bags)')

    def _add(self, source):
        self.sources.append(source)
        return source

    def _open_zstd(self, path, shown):
        """rosbag2's file compression: decompress to a temporary file, then open that."""
        try:
            with open(path, 'rb') as stream:
                inner = zstd_prefix(stream, _SNIFF_SIZE)
        except ZstdError as error:
            raise BagError(f'{shown}: damaged zstd file: {error}') from None
        if not inner.startswith((MCAP_MAGIC, _SQLITE_MAGIC)):
            kind = 'nothing (empty)' if not inner else 'a ' + _file_kind(inner)
            raise BagError(f'{shown}: zstd-compressed file that does not hold a bag '
                           f'(it holds {kind})')
        if self.tmpdir is None:
            import tempfile   # only for zstd-compressed files
            self.tmpdir = tempfile.TemporaryDirectory(prefix='rotation_bag.')
        target = os.path.join(self.tmpdir.name, f'{len(self.sources)}_{stored_name(path)}')
        try:
            decompress_file(path, target)
        except ZstdError as error:
            raise BagError(f'{shown}: damaged zstd file: {error}') from None
        except OSError as error:
            raise BagError(f'cannot decompress {shown} to {self.tmpdir.name}: '
                           f'{error.strerror}') from None
        source, storage = self.open_file(target, shown=shown, compressed=True)
        source.path = shown
        return source, storage

    def close(self):
        """Close every storage file and remove the temporary directory; again does nothing."""
        for source in self.sources:
            source.close()
        self.sources = []
        if self.tmpdir is not None:
            self.tmpdir.cleanup()
            self.tmpdir = None


def open_bag(path: Union[str, os.PathLike], *, strict: bool = False) -> InputBag:
    """
    Open any bag for reading: a rosbag2 directory, a storage file, a ROS 1 bag; only read.

    ``strict`` refuses an unfinished recording (``--strict``) instead of reading what it holds.
    BagError with one line naming what the input is if it cannot be read (``<path>: text file,
    not a bag...``, ``<path>: ROS 1 bag, version 1.2 (supported: 2.0)``...; docs/bags.md lists
    them), or if it is damaged.
    """
    path = os.fspath(path)
    opener = _Opener(strict)
    directory = os.path.isdir(path)
    try:
        if directory:
            files, storage, mode, note = _directory_layout(path)
            if note and strict:
                raise BagError(f'{path}: unfinished recording ({note}); refused (--strict)')
            storages = [opener.open_file(file)[1] for file in files]
            if storage and any(s != storage for s in storages):
                raise BagError(f'{path}: {METADATA_FILE} names storage {storage!r}, '
                               f'but the files hold {", ".join(sorted(set(storages)))}')
            count = len(files)
            details = [storage or storages[0], f'{count} file{"s" if count != 1 else ""}']
        else:
            _, storage = opener.open_file(path)
            mode, note, details = '', None, []
        if not mode:   # without metadata.yaml, the files say it
            mode = ('file' if opener.tmpdir is not None else 'message' if any(
                getattr(source, 'message_compression', None) for source in opener.sources)
                else '')
        if mode:
            details.append(f'zstd {mode} compression')
        # A ROS 1 bag says what it stores (bz2) apart from what its copy gets (zstd).
        chunks = sorted({getattr(source, 'stored_compression', source.compression)
                         for source in opener.sources} - {'none'})
        if chunks:
            details.append(f'{"/".join(chunks)} chunks')
        if directory:
            description = f'rosbag2 directory ({", ".join(details)})'
        else:
            description = {'mcap': 'MCAP file', 'sqlite3': 'sqlite3 file',
                           'ROS 1': 'ROS 1 bag'}[storage] + (
                f' ({", ".join(details)})' if details else '')
        return InputBag(path, description, opener, compression='zstd' if mode else None,
                        note=note)
    except BaseException:
        opener.close()
        raise
