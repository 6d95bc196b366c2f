"""
rosbag2's ``sqlite3`` storage files (``.db3``), read with the ``rosbags`` package.

rosbags' reader (:class:`rosbags.rosbag2.storage_sqlite3.Sqlite3Reader`) reads
the ``topics`` (and ``message_definitions``) tables when it opens the file and
the ``messages`` table row by row. A damaged file surfaces from several layers:
SQLite's own errors (``apsw.CorruptError`` for a damaged page, met only when a
query reaches it), text that is not UTF-8, QoS profiles that are not what
rosbag2 writes, a message row whose ``data`` is not a BLOB or whose
``timestamp`` is not a time (a non-negative integer). :class:`Sqlite3Storage`
turns each into a :class:`rosbags.rosbag2.errors.ReaderError` naming the table
and the row (``messages`` rows by their ``id``), so that a bag read through
:class:`~rotation_node.bag.reading.rosbags_input.RosbagsInput` fails with one line.
The file is opened read-only and immutable: it is never changed.
"""
import contextlib
import os
from pathlib import Path
import sqlite3
from typing import Any, Collection, Generator, Optional, Tuple
import urllib.parse

import apsw
from rosbags.interfaces import Connection
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
from rotation_node.bag.reading.compression import decompressed_message, is_zstd, ZstdError
from rotation_node.bag.reading.rosbags_input import RosbagsInput
from rotation_node.bag.records import TopicMetadata
from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_definition
from rotation_node.wire.qos_yaml import rosbags_qos_yaml

_ROSBAG2_TABLES = {'topics', 'messages'}
# What rosbags' Sqlite3Reader.open raises, besides ReaderError, for tables whose text is
# damaged: a name or definition that is not UTF-8 (apsw decodes TEXT), an unknown definition
# encoding (KeyError), QoS profiles that are YAML but not a list of mappings (TypeError,
# AttributeError from its parse_qos).
_DAMAGED_TABLE_ERRORS = (UnicodeDecodeError, KeyError, TypeError, AttributeError, ValueError)


def sqlite_tables(path: str, shown: Optional[str] = None) -> set:
    """
    Return the table names of a SQLite database, read-only (the file is never changed).

    ``shown`` is the path named in errors (default ``path``).

    Raises
    ------
    BagError
        If the file is not a readable SQLite database.

    """
    uri = f'file:{urllib.parse.quote(os.path.abspath(path))}?mode=ro&immutable=1'
    try:
        with contextlib.closing(sqlite3.connect(uri, uri=True)) as database:
            return {row[0] for row in database.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'")}
    except sqlite3.DatabaseError as error:
        raise BagError(f'{shown or path}: damaged sqlite3 database: {error}') from None


class Sqlite3Storage(Sqlite3Reader):
    """
    rosbags' sqlite3 storage reader whose errors on damaged data name the table and row.

    ``messages`` yields what rosbags' yields, in the same order (by
    ``timestamp``), ``data`` always ``bytes`` and ``timestamp`` always an
    ``int`` >= 0.
    """

    def open(self) -> None:  # noqa: A003  (rosbags names it so)
        """
        Open the database and read its topics.

        Raises
        ------
        rosbags.rosbag2.errors.ReaderError
            If it cannot be opened or its topics or message definitions are damaged.

        """
        try:
            super().open()
        except ReaderError as error:
            if not isinstance(error.__cause__, apsw.Error):
                raise
            raise ReaderError(f'{error.__cause__}{_damaged_table(self.path)}') from None
        except _DAMAGED_TABLE_ERRORS as error:
            raise ReaderError(f'the topics or message_definitions table is damaged: '
                              f'{type(error).__name__}: {error}') from None

    def messages(self, connections: Collection[Connection], start: Optional[int] = None,
                 stop: Optional[int] = None
                 ) -> Generator[Tuple[Connection, int, bytes], None, None]:
        """
        Yield ``(connection, timestamp, data)`` of the messages of ``connections`` by time.

        Raises
        ------
        rosbags.rosbag2.errors.ReaderError
            When a damaged page or row is reached: ``messages table, row id
            12: data is TEXT, not a BLOB``; ``... after row id 40: database
            disk image is malformed``.

        """
        if self.dbconn is None:
            raise ReaderError('Rosbag is not open.')
        ids = sorted({connection.id for connection in connections})
        query = ('SELECT messages.id, topics.id, messages.timestamp, messages.data '
                 'FROM messages JOIN topics ON messages.topic_id = topics.id '
                 f'WHERE topics.id IN ({",".join("?" * len(ids))})')
        arguments: list = list(ids)
        if start is not None:
            query += ' AND messages.timestamp >= ?'
            arguments.append(start)
        if stop is not None:
            query += ' AND messages.timestamp < ?'
            arguments.append(stop)
        by_id = {connection.id: connection for connection in self.connections}
        row_id = None
        try:
            for row_id, topic_id, timestamp, data in self.dbconn.execute(
                    query + ' ORDER BY timestamp', arguments):
                if type(data) is not bytes:
                    raise ReaderError(f'messages table, row id {row_id}: data is '
                                      f'{_sqlite_type(data)}, not a BLOB')
                if type(timestamp) is not int or timestamp < 0:
                    raise ReaderError(f'messages table, row id {row_id}: timestamp '
                                      f'{timestamp!r} is not a time (an INTEGER >= 0 ns)')
                yield by_id[topic_id], timestamp, data
        except (apsw.Error, UnicodeDecodeError) as error:   # a damaged page; text not UTF-8
            where = 'before its first row' if row_id is None else f'after row id {row_id}'
            raise ReaderError(f'messages table, {where}: {error}') from None


def _damaged_table(path: object) -> str:
    """
    Say where SQLite met damage: ``' (messages table, after row id 199)'``, or ``''``.

    Each rosbag2 table is read whole (not through an index), in row id order, until
    its damaged page.
    """
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


def _with_rosbag2_extension(connections, path):
    """Give ``(connection, its rosbag2 extension)``: what sqlite3 storage records per topic."""
    from rosbags.interfaces import ConnectionExtRosbag2
    for connection in connections:
        if not isinstance(connection.ext, ConnectionExtRosbag2):   # never from sqlite3 storage
            raise BagError(f'{path}: topic {connection.topic} has no rosbag2 metadata')
        yield connection, connection.ext


def _rows_without_topic(reader: Sqlite3Storage, path: str) -> Optional[str]:
    """
    Say which message rows name no topic of the ``topics`` table, or None if none does.

    Such rows cannot be read as messages of any topic: rosbags counts every
    row (``metadata.message_count``) but the topics only theirs.
    """
    lost = reader.metadata.message_count - sum(c.msgcount for c in reader.connections)
    if lost <= 0 or reader.dbconn is None:
        return None
    row_id, topic_id = next(iter(reader.dbconn.execute(
        'SELECT id, topic_id FROM messages WHERE topic_id NOT IN (SELECT id FROM topics) '
        'ORDER BY id LIMIT 1')), (None, None))
    rows = f'{lost} messages of the messages table name' if lost != 1 else \
        '1 message of the messages table names'
    return f'{path}: {rows} no topic (the first: row id {row_id}, topic_id {topic_id!r})'


def _message_compression(reader: Sqlite3Storage) -> Optional[str]:
    """Return ``'zstd'`` if the first message is a zstd frame (rosbag2's ``message`` mode)."""
    if reader.dbconn is None:
        return None
    first, = next(iter(reader.dbconn.execute('SELECT data FROM messages ORDER BY id LIMIT 1')),
                  (None,))
    return 'zstd' if isinstance(first, bytes) and is_zstd(first) else None


def open_sqlite3_file(path: str, *, shown: Optional[str] = None,
                      strict: bool = False) -> RosbagsInput:
    """
    Open one rosbag2 sqlite3 storage file (named ``shown`` in errors and notes, default ``path``).

    Messages compressed by rosbag2 (``message`` mode) are decompressed (and
    ``message_compression`` says so, also without ``metadata.yaml``).
    Messages whose ``topic_id`` is not a topic cannot be read: a note
    (``notes``) says how many, or with ``strict`` an error.

    Raises
    ------
    BagError
        If the database has no rosbag2 tables or cannot be read.

    """
    shown = shown or path
    if not _ROSBAG2_TABLES <= sqlite_tables(path, shown):
        raise BagError(f'{shown}: sqlite3 database without rosbag2 tables')
    reader = Sqlite3Storage(Path(path))
    try:
        reader.open()
    except ReaderError as error:
        raise BagError(f'{shown}: cannot read rosbag2 sqlite3 storage: '
                       f'{str(error).replace(path, shown)}') from None
    try:
        lost = _rows_without_topic(reader, shown)
        first_message_compression = _message_compression(reader)
        if lost is not None and strict:
            raise BagError(f'{lost}; refused (--strict)')
        source = RosbagsInput(shown, reader, (ReaderError, ZstdError), [
            (connection, TopicMetadata(
                name=connection.topic, type_name=connection.msgtype,
                offered_qos_profiles=rosbags_qos_yaml(ext.offered_qos_profiles),
                type_hash=connection.digest, serialization_format=ext.serialization_format,
                **_definition(connection.msgtype, connection.msgdef)), decompressed_message)
            for connection, ext in _with_rosbag2_extension(reader.connections, shown)])
    except apsw.Error as error:   # met by the query for rows without topic
        reader.close()
        raise BagError(f'{shown}: cannot read rosbag2 sqlite3 storage: {error}') from None
    except BaseException:
        reader.close()
        raise
    if lost is not None:
        source.notes.append(f'{lost}, not read')
    source.message_compression = first_message_compression
    return source


def _definition(type_name, msgdef):
    """
    ``definition`` and ``definition_encoding`` of a topic from a rosbags definition.

    A bag without definitions (sqlite3 before Iron) gets the installed one;
    if the type is not installed either, the encoding ``unknown`` that rosbag2
    records then.
    """
    from rosbags.interfaces import MessageDefinitionFormat
    encodings = {MessageDefinitionFormat.MSG: 'ros2msg', MessageDefinitionFormat.IDL: 'ros2idl'}
    if msgdef.format in encodings:
        return {'definition': msgdef.data, 'definition_encoding': encodings[msgdef.format]}
    try:
        message_definition(type_name)
    except BagError:
        return {'definition': '', 'definition_encoding': 'unknown'}
    return {'definition': None, 'definition_encoding': 'ros2msg'}
