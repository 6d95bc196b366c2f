"""
Topic names given by the user (``--topics``), checked before any ROS call sees them.

rclpy rejects an invalid name with a multi-line exception deep inside node creation; here
the same rules give one ``BagError`` line naming the topic and what is wrong with it.
"""
from __future__ import annotations

from typing import Iterable, List

from rclpy.exceptions import InvalidTopicNameException
from rclpy.expand_topic_name import expand_topic_name
from rclpy.validate_full_topic_name import validate_full_topic_name
from rclpy.validate_topic_name import validate_topic_name
from rotation_node.errors import BagError


def checked_topic_names(topics: Iterable[str]) -> List[str]:
    """
    Return ``topics`` (``/imu``, ``chatter``, ``~/status``) as a list, each a valid topic name.

    BagError naming the first invalid one and the rule it breaks (checked expanded too).
    """
    topics = list(topics)
    for topic in topics:
        try:
            if not isinstance(topic, str):
                raise InvalidTopicNameException(f'topic name must be a string, got {topic!r}')
            validate_topic_name(topic)
            validate_full_topic_name(expand_topic_name(topic, 'node', '/'))
        except InvalidTopicNameException as error:
            reason = str(error).splitlines()[0].removeprefix('Invalid topic name: ').rstrip(':')
            raise BagError(f'{topic!r} is not a valid ROS 2 topic name: {reason}') from None
    return topics
