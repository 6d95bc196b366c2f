"""
rosbag2's ``sqlite3`` storage files (``.db3``) read with ``apsw``, as ``rosbags`` reads them.

Without importing rosbags' rosbag2 modules (a twentieth of a second). Damage met in any layer
(a damaged page, text not UTF-8, QoS profiles not rosbag2's, a row of the wrong types) becomes
a :class:`DamagedStorage` naming the table and the row id. The file is opened read-only.
"""
import contextlib
import os
from pathlib import Path
import sqlite3
from typing import Any, Collection, Dict, Generator, List, NamedTuple, Optional, Tuple
import urllib.parse

import apsw
from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability
from rotation_node.bag import metadata_yaml
from rotation_node.bag.reading.compression import decompressed_message, is_zstd, ZstdError
from rotation_node.bag.reading.rosbags_input import is_installed, RosbagsInput
from rotation_node.bag.records import TopicMetadata
from rotation_node.errors import BagError
from rotation_node.wire.qos_yaml import profiles_yaml

_ROSBAG2_TABLES = {'topics', 'messages'}
# Damaged topics and message_definitions: not UTF-8, unknown encoding, QoS YAML not profiles.
_DAMAGED_TABLE_ERRORS = (UnicodeDecodeError, KeyError, TypeError, AttributeError, ValueError)
#: Definition encodings rosbag2 writes.
_ENCODINGS = ('ros2msg', 'ros2idl')


class DamagedStorage(Exception):
    """A sqlite3 storage file that cannot be read as rosbag2 storage, and where."""


def sqlite_tables(path: str, shown: str) -> set:
    """Return the table names of a SQLite database, read-only; BagError naming ``shown``."""
    uri = f'file:{urllib.parse.quote(os.path.abspath(path))}?mode=ro&immutable=1'
    try:
        with contextlib.closing(sqlite3.connect(uri, uri=True)) as database:
            return {row[0] for row in database.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'")}
    except sqlite3.DatabaseError as error:
        raise BagError(f'{shown}: damaged sqlite3 database: {error}') from None


class StoredTopic(NamedTuple):
    """One row of the ``topics`` table, as rosbags reads it (a rosbags ``Connection``'s fields)."""

    id: int   # noqa: A003  (rosbags names it so)
    topic: str
    msgtype: str
    #: ``(encoding, text)`` of the type's row of ``message_definitions``, or ``(None, '')``.
    msgdef: Tuple[Optional[str], str]
    digest: str
    msgcount: int
    serialization_format: str
    #: The offered QoS profiles, normalised as rosbags normalises them, as rosbag2's YAML.
    offered_qos_profiles: str


def _policy(policy: Any, item: Any, key: str) -> str:
    """Return a QoS policy of a profile by name, as rosbags reads it (``unknown`` if neither)."""
    try:
        value = item[key]
        member = (policy(value) if isinstance(value, int)
                  else policy.__members__[value.upper()])
    except (KeyError, ValueError):
        member = policy(policy.UNKNOWN)
    return member.name.lower()


def qos_profiles_yaml(stored: Any) -> str:
    """
    Return a topic's ``offered_qos_profiles`` as rosbags reads and then writes them (version 9).

    Policies given by number or by name, unknown ones ``unknown``. DamagedStorage if the text is
    not YAML; KeyError, TypeError or AttributeError if it is not a list of QoS profiles.
    """
    if not stored:
        return profiles_yaml([])
    try:
        items = metadata_yaml.load(stored) if isinstance(stored, str) else stored
    except metadata_yaml.YAMLError as error:
        raise DamagedStorage(f'Could not load YAML from offered_qos_profiles: {error}') from None
    return profiles_yaml([{
        'history': _policy(QosHistory, item, 'history'),
        'depth': item['depth'],
        'reliability': _policy(QosReliability, item, 'reliability'),
        'durability': _policy(QosDurability, item, 'durability'),
        'deadline': {'sec': item['deadline']['sec'], 'nsec': item['deadline']['nsec']},
        'lifespan': {'sec': item['lifespan']['sec'], 'nsec': item['lifespan']['nsec']},
        'liveliness': _policy(QosLiveliness, item, 'liveliness'),
        'liveliness_lease_duration': {'sec': item['liveliness_lease_duration']['sec'],
                                      'nsec': item['liveliness_lease_duration']['nsec']},
        'avoid_ros_namespace_conventions': item['avoid_ros_namespace_conventions'],
    } for item in items])


class Sqlite3Storage:
    """
    A rosbag2 sqlite3 storage file: its topics (``connections``), and its messages by time.

    ``message_count``: the rows of the ``messages`` table, also those of no topic.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.dbconn: Optional[apsw.Connection] = None
        self.connections: List[StoredTopic] = []
        self.message_count = 0

    def open(self) -> None:  # noqa: A003  (rosbags names it so)
        """Open the database and read its topics; DamagedStorage if they are damaged."""
        try:
            self.dbconn = apsw.Connection(f'file:{self.path}?immutable=1',
                                          flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)
            self._read_topics(self.dbconn)
        except apsw.Error as error:
            self.close()
            raise DamagedStorage(f'{error}{_damaged_table(self.path)}') from None
        except _DAMAGED_TABLE_ERRORS as error:
            self.close()
            raise DamagedStorage(f'the topics or message_definitions table is damaged: '
                                 f'{type(error).__name__}: {error}') from None
        except BaseException:
            self.close()
            raise

    def _read_topics(self, database: apsw.Connection) -> None:
        """Read the topics as rosbags' reader does, by the schema version of the file."""
        tables = next(database.execute("SELECT count(*) FROM sqlite_master WHERE type = 'table' "
                                       "AND name IN ('messages', 'topics')"))[0]
        if tables != 2:
            raise DamagedStorage(f'Cannot open database {self.path} or database missing tables.')
        if database.execute('PRAGMA table_info(schema)').fetchall():
            schema, = database.execute('SELECT schema_version FROM schema').fetchone() or (-1,)
        elif any(column[1] == 'offered_qos_profiles'
                 for column in database.execute('PRAGMA table_info(topics)')):
            schema = 2
        else:
            schema = 1
        definitions: Dict[str, Tuple[str, str]] = {}
        if schema >= 4:
            for name, encoding, text, _ in database.execute(
                    'SELECT topic_type, encoding, encoded_message_definition, '
                    'type_description_hash FROM message_definitions ORDER BY id'):
                definitions.setdefault(name, (encoding, text))
        columns = ['serialization_format']
        if schema >= 2:
            columns.append('offered_qos_profiles')
        if schema >= 4:
            columns.append('type_description_hash')
        self.connections = []
        for topic_id, topic, type_name, count, serialization_format, *more in database.execute(
                'SELECT topics.id, name, type, count(messages.id), '
                f'{", ".join(columns)} FROM topics '
                'LEFT JOIN messages ON topics.id == messages.topic_id '
                'GROUP BY topics.id ORDER BY topics.id'):
            encoding, text = definitions.get(type_name, (None, ''))
            if encoding is not None and encoding not in _ENCODINGS:
                raise KeyError(encoding)
            self.connections.append(StoredTopic(
                topic_id, topic, type_name, (encoding, text), more[1] if schema >= 4 else '',
                count, serialization_format,
                qos_profiles_yaml(more[0]) if schema >= 2 else profiles_yaml([])))
        _, _, self.message_count = next(database.execute(
            'SELECT MIN(timestamp), MAX(timestamp) + 1, COUNT(*) FROM messages'))

    def close(self) -> None:
        """Close the database."""
        database, self.dbconn = self.dbconn, None
        if database is not None:
            database.close()

    def messages(self, connections: Collection[StoredTopic]
                 ) -> Generator[Tuple[StoredTopic, int, bytes], None, None]:
        """
        Yield ``(connection, timestamp, data)`` of the messages of ``connections`` as rosbags.

        By ``timestamp``; ``data`` always ``bytes``, ``timestamp`` always an int >= 0.
        DamagedStorage when a damaged page or row is reached (``messages table, row id 12: data
        is TEXT, not a BLOB``; ``... after row id 40: database disk image is malformed``).
        """
        assert self.dbconn is not None
        ids = sorted({connection.id for connection in connections})
        query = ('SELECT messages.id, topics.id, messages.timestamp, messages.data '
                 'FROM messages JOIN topics ON messages.topic_id = topics.id '
                 f'WHERE topics.id IN ({",".join("?" * len(ids))})')
        by_id = {connection.id: connection for connection in self.connections}
        row_id = None
        try:
            for row_id, topic_id, timestamp, data in self.dbconn.execute(
                    query + ' ORDER BY timestamp', ids):
                if type(data) is not bytes:
                    raise DamagedStorage(f'messages table, row id {row_id}: data is '
                                         f'{_sqlite_type(data)}, not a BLOB')
                if type(timestamp) is not int or timestamp < 0:
                    raise DamagedStorage(f'messages table, row id {row_id}: timestamp '
                                         f'{timestamp!r} is not a time (an INTEGER >= 0 ns)')
                yield by_id[topic_id], timestamp, data
        except (apsw.Error, UnicodeDecodeError) as error:   # a damaged page; text not UTF-8
            where = 'before its first row' if row_id is None else f'after row id {row_id}'
            raise DamagedStorage(f'messages table, {where}: {error}') from None


def _damaged_table(path: object) -> str:
    """Say where SQLite met damage, reading each table in row order: ``' (messages table...)'``."""
    try:
        database = apsw.Connection(f'file:{path}?immutable=1',
                                   flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)
    except apsw.Error:
        return ''
    try:
        for table in ('topics', 'message_definitions', 'messages'):
            row_id = None
            try:
                for row_id, *_ in database.execute(f'SELECT rowid, * FROM {table} NOT INDEXED'):
                    pass
            except apsw.SQLError:   # no such table (older schema)
                continue
            except (apsw.Error, UnicodeDecodeError):
                where = 'before its first row' if row_id is None else f'after row id {row_id}'
                return f' ({table} table, {where})'
        return ''
    finally:
        database.close()


def _sqlite_type(value: Any) -> str:
    """Return the SQLite storage class of a value apsw read: ``'TEXT'``, ``'NULL'``..."""
    return {str: 'TEXT', int: 'INTEGER', float: 'REAL', bytes: 'BLOB'}.get(type(value), 'NULL')


def _rows_without_topic(reader: Sqlite3Storage, path: str) -> Optional[str]:
    """Say how many message rows name no topic of the ``topics`` table (None if none)."""
    lost = reader.message_count - sum(c.msgcount for c in reader.connections)
    if lost <= 0 or reader.dbconn is None:
        return None
    row_id, topic_id = next(iter(reader.dbconn.execute(
        'SELECT id, topic_id FROM messages WHERE topic_id NOT IN (SELECT id FROM topics) '
        'ORDER BY id LIMIT 1')), (None, None))
    rows = f'{lost} messages of the messages table name' if lost != 1 else \
        '1 message of the messages table names'
    return f'{path}: {rows} no topic (the first: row id {row_id}, topic_id {topic_id!r})'


def open_sqlite3_file(path: str, *, shown: Optional[str] = None,
                      strict: bool = False) -> RosbagsInput:
    """
    Open one rosbag2 sqlite3 storage file (named ``shown`` in errors and notes, default ``path``).

    Messages compressed by rosbag2 (``message`` mode) are decompressed. Messages whose
    ``topic_id`` is not a topic cannot be read: a note says how many (with ``strict``, a BagError).
    """
    shown = shown or path
    if not _ROSBAG2_TABLES <= sqlite_tables(path, shown):
        raise BagError(f'{shown}: sqlite3 database without rosbag2 tables')
    reader = Sqlite3Storage(Path(path))
    try:
        reader.open()
    except DamagedStorage as error:
        raise BagError(f'{shown}: cannot read rosbag2 sqlite3 storage: '
                       f'{str(error).replace(path, shown)}') from None
    try:
        assert reader.dbconn is not None   # open
        lost = _rows_without_topic(reader, shown)
        first, = next(iter(reader.dbconn.execute('SELECT data FROM messages ORDER BY id LIMIT 1')),
                      (None,))
        if lost is not None and strict:
            raise BagError(f'{lost}; refused (--strict)')
        source = RosbagsInput(shown, reader, (DamagedStorage, ZstdError), [
            (connection, TopicMetadata(
                name=connection.topic, type_name=connection.msgtype,
                offered_qos_profiles=connection.offered_qos_profiles,
                type_hash=connection.digest,
                serialization_format=connection.serialization_format,
                **_definition(connection.msgtype, connection.msgdef)), decompressed_message)
            for connection in reader.connections])
    except apsw.Error as error:   # met by the query for rows without topic
        reader.close()
        raise BagError(f'{shown}: cannot read rosbag2 sqlite3 storage: {error}') from None
    except BaseException:
        reader.close()
        raise
    if lost is not None:
        source.notes.append(f'{lost}, not read')
    # A zstd frame: rosbag2's message compression, also without metadata.yaml.
    source.message_compression = 'zstd' if isinstance(first, bytes) and is_zstd(first) else None
    return source


def _definition(type_name, msgdef):
    """Return ``definition`` and ``definition_encoding``: the row's, the installed, or unknown."""
    encoding, text = msgdef
    if encoding is not None:
        return {'definition': text, 'definition_encoding': encoding}
    if not is_installed(type_name):
        return {'definition': '', 'definition_encoding': 'unknown'}
    return {'definition': None, 'definition_encoding': 'ros2msg'}
