"""
What every bag format is read into and written from: :class:`TopicMetadata`, :class:`BagMessage`.

The readers of ``reading`` yield them and the writer of ``writing`` takes them, so both
import this module and neither imports the other.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable, Optional, Tuple, Type

from rotation_node.errors import BagError
from rotation_node.wire.message_types import message_class

MESSAGE_ENCODING = 'cdr'   # how ROS 2 messages are serialized in a bag


@dataclasses.dataclass(frozen=True)
class TopicMetadata:
    """What a bag records about one topic (None: the installed type's definition, hash)."""

    name: str                                  # '/imu'
    type_name: str                             # 'pkg/msg/Type'
    offered_qos_profiles: str = '[]'           # rosbag2's YAML of the publishers' QoS
    definition: Optional[str] = None           # the schema text
    definition_encoding: str = 'ros2msg'       # or 'ros2idl'
    type_hash: Optional[str] = None            # REP-2011
    serialization_format: str = MESSAGE_ENCODING   # other recorders' bags: copied as is


class BagMessage:
    """One message read from a bag: its CDR ``data``, receive and publish times in ns."""

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
        Return the message deserialised by rclpy, or by ``decode(data)`` (a cdr codec's).

        BagError if the type is not installed or the bytes are not a valid message.
        """
        errors: Tuple[Type[BaseException], ...] = (BagError,)   # a cdr codec's own
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
