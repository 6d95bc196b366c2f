"""
sqlite3 storage and ROS 1 bags, read with a ``rosbags``-style reader, as ``BagReader`` reads.

Both formats store one time per message (when the recorder received it): the log time and the
publish time.
"""
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Tuple

from rotation_node.bag.reading.mcap_reader import add_topic, checked_topics
from rotation_node.bag.records import BagMessage, TopicMetadata
from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_definition


def is_installed(type_name: str) -> bool:
    """Whether the definition of ``type_name`` is installed (not its class: that imports more)."""
    try:
        message_definition(type_name)
    except BagError:
        return False
    return True


class RosbagsInput:
    """
    A bag opened with a rosbags reader yielding ``(connection, time, data)`` in time order.

    ``topics``: every connection, its topic's metadata and its ``to_cdr``; ``errors``: what they
    raise for damaged data. ``compression``: its copy's, as MCAP names it; ``stored_compression``:
    the bag's own (a ROS 1 bag's ``'bz2'``).
    """

    def __init__(self, path: str, reader: Any, errors: tuple,
                 topics: Iterable[Tuple[Any, TopicMetadata, Callable[[bytes], bytes]]],
                 compression: str = 'none', *,
                 stored_compression: Optional[str] = None) -> None:
        self.path = path
        self.recovered: Optional[int] = None
        self.compression = compression
        self.stored_compression = stored_compression or compression
        self.notes: List[str] = []
        self.message_compression: Optional[str] = None
        self._reader, self._errors = reader, errors
        self.topic_metadata: Dict[str, TopicMetadata] = {}
        self.message_counts: Dict[str, int] = {}
        self._connections: Dict[str, List[Any]] = {}
        self._to_cdr: Dict[int, Callable[[bytes], bytes]] = {}
        for connection, metadata, to_cdr in topics:
            add_topic(self.topic_metadata, self.message_counts, connection.topic, metadata,
                      connection.msgcount, path)
            self._connections.setdefault(connection.topic, []).append(connection)
            self._to_cdr[connection.id] = to_cdr
        self.topics = {topic: m.type_name for topic, m in self.topic_metadata.items()}

    def messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[BagMessage]:
        """Iterate as ``BagReader.messages``; a message that cannot be read raises BagError."""
        topics = checked_topics(self.topics if topics is None else topics, self.topics, self.path)
        connections = [c for topic in topics for c in self._connections[topic]]
        return self._messages(connections) if connections else iter(())

    def _messages(self, connections):
        type_names = self.topics
        for connection, time_ns, data in self._read(self._reader.messages(connections)):
            yield BagMessage(connection.topic, type_names[connection.topic],
                             self.cdr(connection, time_ns, data), time_ns, time_ns)

    def _read(self, items: Iterator[Any]) -> Iterator[Any]:
        """Yield what the reader yields; BagError for what it raises for damage (it says where)."""
        try:
            yield from items
        except self._errors as error:
            raise BagError(f'{self.path} is corrupt: {error}') from None

    def cdr(self, connection: Any, time_ns: int, data: bytes) -> bytes:
        """Return the CDR data of a message stored as ``data``; BagError naming it if it fails."""
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
