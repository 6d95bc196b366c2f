"""
What every bag format is read into and written from: topics and messages.

:class:`TopicMetadata` is what a bag records about one topic, :class:`BagMessage`
one message as CDR bytes with its times. The readers of ``reading`` yield them
and the writer of ``writing`` takes them, so both import this module and
neither imports the other.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable, Optional, Tuple, Type

from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_class

#: How ROS 2 messages are serialized in a bag.
MESSAGE_ENCODING = 'cdr'


@dataclasses.dataclass(frozen=True)
class TopicMetadata:
    """
    What a bag records about one topic.

    Attributes
    ----------
    name : str
        The topic, e.g. ``'/imu'``.
    type_name : str
        ``'pkg/msg/Type'``.
    offered_qos_profiles : str
        The publishers' QoS profiles as rosbag2's YAML (``'[]'`` if unknown).
    definition : str or None
        The schema text; None means the installed definition of ``type_name``.
    definition_encoding : str
        ``'ros2msg'`` or ``'ros2idl'``.
    type_hash : str or None
        REP-2011 hash; None means the installed type's hash.
    serialization_format : str
        How the messages are serialized: ``'cdr'`` for ROS 2 (other values
        only in bags of other recorders, whose topics are copied as they are).

    """

    name: str
    type_name: str
    offered_qos_profiles: str = '[]'
    definition: Optional[str] = None
    definition_encoding: str = 'ros2msg'
    type_hash: Optional[str] = None
    serialization_format: str = MESSAGE_ENCODING


class BagMessage:
    """
    One message read from a bag.

    Attributes
    ----------
    topic : str
    type_name : str
        ``'pkg/msg/Type'``.
    data : bytes
        The CDR-serialised message.
    log_time_ns : int
        Receive time, nanoseconds.
    publish_time_ns : int
        Publish time, nanoseconds.

    """

    __slots__ = ('topic', 'type_name', 'data', 'log_time_ns', 'publish_time_ns')

    def __init__(self, topic: str, type_name: str, data: bytes, log_time_ns: int,
                 publish_time_ns: int) -> None:
        self.topic = topic
        self.type_name = type_name
        self.data = data
        self.log_time_ns = log_time_ns
        self.publish_time_ns = publish_time_ns

    def message(self, decode: Optional[Callable[[bytes], Any]] = None) -> Any:
        """
        Deserialise the message.

        Parameters
        ----------
        decode : callable, optional
            ``decode(data) -> message`` to use instead of rclpy, e.g. the
            ``decode`` of a :func:`rotation_node.wire.cdr.fixed_layout_codec`.

        Returns
        -------
        object
            An instance of the rclpy message class of ``type_name``, or what
            ``decode`` returns.

        Raises
        ------
        BagError
            If the type is not installed or the bytes are not a valid message.

        """
        # a decode's own error (rotation_node.wire.cdr)
        errors: Tuple[Type[BaseException], ...] = (BagError,)
        if decode is None:   # rclpy, imported only here: reading bags does not need it
            from rclpy.serialization import deserialize_message
            from rotation_node.rclpy_private import RMWError
            decode = functools.partial(deserialize_message,
                                       message_type=message_class(self.type_name))
            errors = (RMWError, BagError)   # rclpy's for bad CDR
        try:
            return decode(self.data)
        except errors as error:
            raise BagError(
                f'message on {self.topic} at {self.log_time_ns} ns is not a valid '
                f'{self.type_name}: {error}') from None

    def __repr__(self) -> str:
        return (f'BagMessage({self.topic!r}, {self.type_name!r}, <{len(self.data)} bytes>, '
                f'log_time_ns={self.log_time_ns}, publish_time_ns={self.publish_time_ns})')
