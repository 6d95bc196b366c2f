"""
ROS 1 bags (format version 2.0) read as ROS 2 messages.

The ``rosbags`` package reads the bag (``AnyReader``, every chunk
compression of ROS 1: none, bz2, lz4) and builds the bag's message types from
the definitions stored in it; each message is then converted, as
``rosbags-convert`` converts a ROS 1 bag to ROS 2, to the ROS 2 type of the
same name (``sensor_msgs/Imu`` -> ``sensor_msgs/msg/Imu``, ``tf/tfMessage``
-> ``tf2_msgs/msg/TFMessage``) and serialized as CDR: ``std_msgs/Header``
loses its ``seq``, times keep their seconds and nanoseconds, everything else
keeps its value. A type that ROS 2 (Jazzy) does not have keeps the bag's own
definition. A latched topic is given the QoS rosbags gives it (reliable,
transient local); the log time is the time the ROS 1 recorder received the
message, also used as the publish time.
"""
import contextlib
import io
from pathlib import Path
import struct

from rosbags.convert.converter import generate_message_converter, LATCH, STATIC_MSGTYPE_RENAMES
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag1 import ReaderError
from rosbags.rosbag1.reader import decompressors as ros1_decompressors
from rosbags.serde import SerdeError
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from rosbags.typesys.base import TypesysError
from rotation_node.bag.mcap_io import BagMessage, TopicMetadata
from rotation_node.bag.message_types import message_class
from rotation_node.bag.qos import rosbags_qos_yaml
from rotation_node.errors import BagError

#: The one ROS 1 bag format version there is a reader for.
SUPPORTED_VERSION = '2.0'
# What rosbags raises for a bag it cannot read or a message it cannot convert.
_FORMAT_ERRORS = (AnyReaderError, ReaderError, SerdeError, TypesysError, struct.error)


def _installed(type_name):
    """Whether the ROS 2 Python message package of ``type_name`` is installed."""
    try:
        message_class(type_name)
    except BagError:
        return False
    return True


class Ros1Bag:
    """
    Read a ROS 1 bag as ROS 2 CDR messages; a context manager.

    The interface is that of :class:`rotation_node.bag.mcap_io.BagReader`
    (``topics``, ``topic_metadata``, ``message_counts``, ``compression``,
    ``recovered``, ``messages``), with ROS 2 type names.

    Parameters
    ----------
    path : str or os.PathLike
        A ROS 1 bag, format version 2.0.

    Raises
    ------
    BagError
        If the bag cannot be read or its types cannot be converted.

    """

    def __init__(self, path):
        self.path = str(path)
        self.recovered = None
        self._reader = AnyReader([Path(self.path)])
        try:
            self._reader.open()
        except _FORMAT_ERRORS as error:
            raise BagError(f'{self.path}: cannot read ROS 1 bag: {error}') from None
        try:
            self._convert_types()
        except BaseException:
            self._reader.close()
            raise

    def _convert_types(self):
        ros2 = get_typestore(Stores.ROS2_JAZZY)
        self.topic_metadata, self.message_counts = {}, {}
        self._converters, self._connections = {}, {}
        for connection in self._reader.connections:
            ros1_type = connection.msgtype
            type_name = STATIC_MSGTYPE_RENAMES.get(ros1_type, ros1_type)
            try:
                if type_name not in ros2.fielddefs:   # as rosbags-convert: the bag's definition
                    types = get_types_from_msg(
                        self._reader.typestore.generate_msgdef(ros1_type, ros_version=2)[0],
                        type_name)
                    types.pop('std_msgs/msg/Header', None)
                    ros2.register(types)
                if ros1_type not in self._converters:
                    with contextlib.redirect_stdout(io.StringIO()):   # it prints its plans
                        self._converters[ros1_type] = generate_message_converter(
                            self._reader.typestore, ros2, ros1_type, type_name, {},
                            src_is2=False, dst_is2=True)
            except _FORMAT_ERRORS + (KeyError,) as error:   # KeyError: a type left undefined
                raise BagError(f'{self.path}: cannot convert ROS 1 type {ros1_type} to ROS 2: '
                               f'{error}') from None
            installed = _installed(type_name)
            metadata = TopicMetadata(
                name=connection.topic, type_name=type_name,
                offered_qos_profiles=rosbags_qos_yaml(LATCH if connection.ext.latching else []),
                definition=None if installed else ros2.generate_msgdef(type_name,
                                                                       ros_version=2)[0],
                type_hash=None if installed else ros2.hash_rihs01(type_name))
            known = self.topic_metadata.setdefault(connection.topic, metadata)
            if known.type_name != type_name:
                raise BagError(f'topic {connection.topic} in {self.path} has two types: '
                               f'{known.type_name} and {type_name}')
            self.message_counts[connection.topic] = (
                self.message_counts.get(connection.topic, 0) + connection.msgcount)
            self._connections.setdefault(connection.topic, []).append(connection)
        names = {decompress: name for name, decompress in ros1_decompressors.items()}
        compressions = {names.get(chunk.decompressor)
                        for reader in self._reader.readers for chunk in reader.chunks.values()}
        # The output's chunk compression: lz4 stays lz4, bz2 (not in MCAP) becomes zstd.
        self.compression = ('lz4' if 'lz4' in compressions
                            else 'zstd' if 'bz2' in compressions else 'none')
        self.topics = {topic: m.type_name for topic, m in self.topic_metadata.items()}

    def messages(self, topics=None):
        """
        Iterate over the messages in log-time order, converted to ROS 2 CDR.

        Parameters
        ----------
        topics : iterable of str, optional
            Only these topics; all by default.

        Yields
        ------
        rotation_node.bag.mcap_io.BagMessage

        Raises
        ------
        BagError
            If a topic is not in the bag (at once) or a message cannot be
            read or converted (when it is reached).

        """
        topics = list(self.topics) if topics is None else list(topics)
        missing = [topic for topic in topics if topic not in self.topics]
        if missing:
            raise BagError(f'topic {", ".join(missing)} not in {self.path} '
                           f'(it has {", ".join(sorted(self.topics)) or "no topics"})')
        connections = [c for topic in topics for c in self._connections[topic]]
        return self._messages(connections) if connections else iter(())

    def _messages(self, connections):
        type_names = self.topics
        try:
            for connection, time_ns, data in self._reader.messages(connections):
                cdr = self._converters[connection.msgtype](data)
                yield BagMessage(connection.topic, type_names[connection.topic], bytes(cdr),
                                 time_ns, time_ns)
        except _FORMAT_ERRORS + (ValueError, IndexError) as error:
            raise BagError(f'{self.path} is corrupt: {type(error).__name__}: {error}') from None

    def close(self):
        """Close the bag."""
        self._reader.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
