"""
Bags read with a reader of the ``rosbags`` package, behind the interface of ``BagReader``.

rosbag2 sqlite3 storage files (:mod:`rotation_node.bag.reading.reader`) and ROS 1 bags
(:mod:`rotation_node.bag.reading.ros1`) are read this way: the rosbags reader yields
``(connection, time, data)`` in time order; each topic's connections get their
:class:`~rotation_node.bag.records.TopicMetadata` and a function that turns
the stored data into the ROS 2 CDR bytes passed on. Both formats store one
time per message, the time the recorder received it: it is the log time and
the publish time.
"""
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Tuple

from rotation_node.bag.reading.mcap_reader import checked_topics

from rotation_node.bag.records import BagMessage, TopicMetadata
from rotation_node.errors import BagError


class RosbagsInput:
    """
    A bag opened with a rosbags reader; a context manager.

    The interface of :class:`rotation_node.bag.reading.mcap_reader.BagReader`:
    ``topics``, ``topic_metadata``, ``message_counts``, ``compression``,
    ``recovered`` (always None) and ``messages``; and ``notes``.

    Parameters
    ----------
    path : str
        Named in errors.
    reader : rosbags reader
        Open; ``messages(connections)`` yields ``(connection, time_ns, data)``.
    errors : tuple of exception types
        What the reader (and ``to_cdr``) raise for damaged data.
    topics : iterable of (connection, TopicMetadata, to_cdr)
        Every connection of the bag with the metadata of its topic and the
        function that turns its stored data into CDR bytes.
    compression : str, optional
        The chunk compression its copy gets, as MCAP names it (``'zstd'``,
        ``'lz4'``, ``'none'``).
    stored_compression : str, optional
        The compression of the bag itself, as its format names it (a ROS 1
        bag's ``'bz2'``); default ``compression``.

    Raises
    ------
    BagError
        If a topic has connections of two types.

    """

    def __init__(self, path: str, reader: Any, errors: tuple,
                 topics: Iterable[Tuple[Any, TopicMetadata, Callable[[bytes], bytes]]],
                 compression: str = 'none', *,
                 stored_compression: Optional[str] = None) -> None:
        self.path = path
        self.recovered: Optional[int] = None
        self.compression = compression
        self.stored_compression = stored_compression or compression
        #: One line for each thing the user should know (messages that cannot be read).
        self.notes: List[str] = []
        #: ``'zstd'`` if the messages are compressed one by one (rosbag2's ``message`` mode).
        self.message_compression: Optional[str] = None
        self._reader, self._errors = reader, errors
        self.topic_metadata: Dict[str, TopicMetadata] = {}
        self.message_counts: Dict[str, int] = {}
        self._connections: Dict[str, List[Any]] = {}
        self._to_cdr: Dict[int, Callable[[bytes], bytes]] = {}
        for connection, metadata, to_cdr in topics:
            known = self.topic_metadata.setdefault(connection.topic, metadata)
            if known.type_name != metadata.type_name:
                raise BagError(f'topic {connection.topic} in {path} has two types: '
                               f'{known.type_name} and {metadata.type_name}')
            self.message_counts[connection.topic] = (
                self.message_counts.get(connection.topic, 0) + connection.msgcount)
            self._connections.setdefault(connection.topic, []).append(connection)
            self._to_cdr[connection.id] = to_cdr
        self.topics = {topic: m.type_name for topic, m in self.topic_metadata.items()}

    def messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[BagMessage]:
        """
        Iterate over the messages of the given topics (default all) in time order, as CDR.

        As :meth:`rotation_node.bag.reading.mcap_reader.BagReader.messages`; a message
        that cannot be read or converted raises BagError when it is reached.
        """
        topics = checked_topics(self.topics if topics is None else topics, self.topics, self.path)
        connections = [c for topic in topics for c in self._connections[topic]]
        return self._messages(connections) if connections else iter(())

    def _messages(self, connections):
        type_names = self.topics
        stored = self._reader.messages(connections)
        while True:
            try:
                connection, time_ns, data = next(stored)
            except StopIteration:
                return
            except self._errors as error:   # the reader names where
                raise self.corrupt(error) from None
            yield BagMessage(connection.topic, type_names[connection.topic],
                             self.cdr(connection, time_ns, data), time_ns, time_ns)

    def corrupt(self, error: Exception) -> BagError:
        """Return the error to raise for one of ``errors`` that the reader raised."""
        return BagError(f'{self.path} is corrupt: {error}')

    def cdr(self, connection: Any, time_ns: int, data: bytes) -> bytes:
        """
        Return the CDR data of a message of ``connection`` stored as ``data``.

        Raises
        ------
        BagError
            If it cannot be converted, naming its topic and log time.

        """
        try:
            return self._to_cdr[connection.id](data)
        except self._errors as error:
            raise BagError(f'{self.path} is corrupt: the message of {connection.topic} at '
                           f'log time {time_ns} ns cannot be read: '
                           f'{type(error).__name__}: {error}') from None

    def close(self) -> None:
        """Close the reader."""
        self._reader.close()

    def __enter__(self) -> 'RosbagsInput':
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
