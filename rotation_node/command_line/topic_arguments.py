"""
Topic names given by the user (``--topics``), checked before any ROS call sees them.

rclpy rejects an invalid name with a multi-line ``InvalidTopicNameException``
deep inside node or publisher creation; here the same rule (the ROS 2 topic
name rules, after expansion of ``~`` and substitutions) gives one
``BagError`` line naming the topic and what is wrong with it.
"""
from __future__ import annotations

from typing import Iterable, List

from rclpy.exceptions import InvalidTopicNameException
from rclpy.expand_topic_name import expand_topic_name
from rclpy.validate_full_topic_name import validate_full_topic_name
from rclpy.validate_topic_name import validate_topic_name
from rotation_node.errors import BagError


def checked_topic_names(topics: Iterable[str], *, node_name: str = 'node',
                        namespace: str = '/') -> List[str]:
    """
    Return ``topics`` as a list after checking that each is a valid ROS 2 topic name.

    Parameters
    ----------
    topics : iterable of str
        Absolute or relative names (``/imu``, ``chatter``, ``~/status``).
    node_name, namespace : str, optional
        Used to expand ``~`` and relative names for the full-name check.

    Returns
    -------
    list of str
        The names, unchanged.

    Raises
    ------
    BagError
        Naming the first invalid topic and the rule it breaks.

    """
    topics = list(topics)
    for topic in topics:
        try:
            if not isinstance(topic, str):
                raise InvalidTopicNameException(f'topic name must be a string, got {topic!r}')
            validate_topic_name(topic)
            validate_full_topic_name(expand_topic_name(topic, node_name, namespace))
        except InvalidTopicNameException as error:
            reason = str(error).splitlines()[0].removeprefix('Invalid topic name: ').rstrip(':')
            raise BagError(f'{topic!r} is not a valid ROS 2 topic name: {reason}') from None
    return topics
