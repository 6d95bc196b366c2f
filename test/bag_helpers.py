"""
Shared helpers of the bag tests: random ROS messages and field-by-field comparison.

``random_message`` fills every field of any rosidl message class (nested
messages, fixed arrays, bounded and unbounded sequences, strings) from a seeded
generator, with values that survive CDR exactly (float32 fields hold float32
values). ``plain`` turns an rclpy, rosbags or mcap-ros2-support message into nested
Python lists/dicts so that two independent decoders can be compared with ``==``.
"""
import array
import dataclasses
import os
import shutil
import string
import types

import numpy as np
from rosidl_parser.definition import (
    AbstractGenericString, AbstractNestedType, AbstractSequence, Array, BasicType,
    BoundedSequence, BoundedString, NamespacedType)

from rotation_node.wire.message_types import message_class
from rotation_node.wire.qos_yaml import profiles_yaml

_INTEGER_RANGES = {
    'int8': (-2**7, 2**7), 'uint8': (0, 2**8), 'int16': (-2**15, 2**15), 'uint16': (0, 2**16),
    'int32': (-2**31, 2**31), 'uint32': (0, 2**32), 'int64': (-2**63, 2**63),
    'uint64': (0, 2**64),
}
_LETTERS = np.array(list(string.ascii_letters + string.digits + '_ /'))


def _random_basic(typename, rng):
    if typename == 'double':
        return float(rng.normal() * 10.0 ** rng.integers(-3, 4))
    if typename == 'float':
        return float(np.float32(rng.normal()))
    if typename == 'boolean':
        return bool(rng.integers(2))
    if typename == 'octet':
        return bytes([int(rng.integers(256))])
    if typename == 'char':
        return str(rng.choice(_LETTERS))
    low, high = _INTEGER_RANGES[typename]
    return int(rng.integers(low, high, dtype=np.int64 if high <= 2**63 else np.uint64))


def _random_value(slot, rng):
    if isinstance(slot, NamespacedType):
        return random_message(message_class('/'.join([*slot.namespaces, slot.name])), rng)
    if isinstance(slot, BasicType):
        return _random_basic(slot.typename, rng)
    if isinstance(slot, AbstractGenericString):
        length = int(rng.integers(0, 12))
        if isinstance(slot, BoundedString):
            length = min(length, slot.maximum_size)
        return ''.join(rng.choice(_LETTERS, length))
    if isinstance(slot, AbstractNestedType):
        if isinstance(slot, Array):
            length = slot.size
        else:
            # Never empty: for an empty sequence of 8-byte values Fast CDR emits
            # alignment padding that rosbags' strict size check rejects.
            length = int(rng.integers(1, 4))
            if isinstance(slot, BoundedSequence):
                length = min(length, slot.maximum_size)
        values = [_random_value(slot.value_type, rng) for _ in range(length)]
        if isinstance(slot.value_type, BasicType) and slot.value_type.typename == 'octet':
            return b''.join(values) if isinstance(slot, AbstractSequence) else values
        return values
    raise TypeError(f'unsupported field type {slot!r}')


def random_message(msg_class, rng):
    """Return an instance of ``msg_class`` with every field set to a random value."""
    msg = msg_class()
    for name, slot in zip(msg_class.get_fields_and_field_types(), msg_class.SLOT_TYPES):
        setattr(msg, name, _random_value(slot, rng))
    return msg


def plain(value):
    """Nested dicts/lists of Python scalars for an rclpy, rosbags or mcap-ros2 message."""
    if hasattr(type(value), 'get_fields_and_field_types'):
        return {name: plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, types.SimpleNamespace):   # mcap-ros2-support's dynamic classes
        return {name: plain(getattr(value, name)) for name in type(value).__slots__}
    if dataclasses.is_dataclass(value):
        # rosbags: skip its __msgtype__ and the constants (upper case in ROS 2).
        return {field.name: plain(getattr(value, field.name))
                for field in dataclasses.fields(value)
                if not (field.name.startswith('__') or field.name.isupper())}
    if isinstance(value, bytes):
        return list(value)
    if isinstance(value, (np.ndarray, array.array, list, tuple)):
        return [plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def imu_messages(rng, count, *, period_ns=10_000_000, start_ns=1_700_000_000_000_000_000,
                 frame_id='imu_link', orientation_variance=(1e-6, 2e-6, 4e-6)):
    """
    Return Imu messages at a fixed rate: random unit orientations, angular velocities.

    The orientation covariance is ``diag(orientation_variance)`` (rad^2).
    """
    from sensor_msgs.msg import Imu
    messages = []
    quaternions = rng.normal(size=(count, 4))
    quaternions /= np.linalg.norm(quaternions, axis=1, keepdims=True)
    for i, (q, w) in enumerate(zip(quaternions.tolist(), rng.normal(size=(count, 3)).tolist())):
        msg = Imu()
        msg.header.frame_id = frame_id
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(start_ns + i * period_ns, 10**9)
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = q
        msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = w
        msg.orientation_covariance[0::4] = orientation_variance
        messages.append(msg)
    return messages


def stamp_ns(msg):
    """Header stamp of a message in integer nanoseconds."""
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


# Bags written by independent writers: the rosbags package (rosbag2 directories,
# ROS 1 bags) and the mcap library, from messages serialized by rclpy.

def serialized_rows(topic, messages, *, log_offset_ns=1_000_000):
    """``[(topic, type name, rclpy CDR bytes, log time)]``; log time = stamp + offset."""
    from rclpy.serialization import serialize_message

    from rotation_node.wire.message_types import type_name_of
    return [(topic, type_name_of(type(msg)), serialize_message(msg),
             stamp_ns(msg) + log_offset_ns) for msg in messages]


def interleaved(*row_lists):
    """Rows of several topics in log-time order (ties in argument order)."""
    return sorted((row for rows in row_lists for row in rows), key=lambda row: row[3])


def write_rosbag2(path, rows, *, storage='mcap', compression=None, qos=None):
    """
    Write ``rows`` with the rosbags writer as a rosbag2 directory (metadata version 9).

    ``compression``: None, ``'file'``, ``'message'`` (zstd, as rosbag2) or
    ``'storage'`` (zstd chunks, mcap only). ``qos``: {topic: [rosbags Qos]}.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore
    typestore = get_typestore(Stores.ROS2_JAZZY)
    writer = Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()])
    if compression:
        writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
    connections = {}
    with writer:
        for topic, type_name, data, log_time in rows:
            if topic not in connections:
                connections[topic] = writer.add_connection(
                    topic, type_name, typestore=typestore,
                    offered_qos_profiles=(qos or {}).get(topic, ()))
            writer.write(connections[topic], log_time, data)
    return path


def write_split_rosbag2(path, rows, parts, **options):
    """
    Return a rosbag2 directory of ``parts`` storage files (as ``ros2 bag record --max-bag-size``).

    Each part is written by :func:`write_rosbag2`; ``metadata.yaml`` lists them
    in order, with the per-file and per-topic counts rosbag2 writes.
    """
    import yaml
    bounds = np.linspace(0, len(rows), parts + 1).astype(int)
    path.mkdir()
    info, files = None, []
    for index, (start, stop) in enumerate(zip(bounds[:-1], bounds[1:])):
        part = write_rosbag2(path.parent / f'{path.name}.part{index}', rows[start:stop],
                             **options)
        part_info = yaml.safe_load((part / 'metadata.yaml').read_text())[
            'rosbag2_bagfile_information']
        name, = part_info['relative_file_paths']
        new_name = f'{path.name}_{index}' + name[len(part.name):]
        (part / name).rename(path / new_name)
        files.append({**part_info['files'][0], 'path': new_name})
        if info is None:
            info = part_info
        else:
            counts = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
            for topic in part_info['topics_with_message_count']:
                known = counts.get(topic['topic_metadata']['name'])
                if known is None:
                    info['topics_with_message_count'].append(topic)
                else:
                    known['message_count'] += topic['message_count']
        shutil.rmtree(part)
    start = min(f['starting_time']['nanoseconds_since_epoch'] for f in files)
    end = max(f['starting_time']['nanoseconds_since_epoch'] + f['duration']['nanoseconds']
              for f in files)
    info.update(relative_file_paths=[f['path'] for f in files], files=files,
                message_count=len(rows), starting_time={'nanoseconds_since_epoch': start},
                duration={'nanoseconds': end - start})
    (path / 'metadata.yaml').write_text(
        yaml.safe_dump({'rosbag2_bagfile_information': info}, sort_keys=False))
    return path


def rosbags_rows(path):
    """``[(topic, data, log time)]`` of a bag as the rosbags reader reads it (an oracle)."""
    from rosbags.rosbag2 import Reader
    with Reader(path) as reader:
        return [(connection.topic, bytes(data), time_ns)
                for connection, time_ns, data in reader.messages()]


def main_in(directory, argv):
    """Run ``rotation_bag`` with ``argv`` in ``directory`` (relative paths); its exit status."""
    from rotation_node.bag.cli import main
    cwd = os.getcwd()
    os.chdir(directory)
    try:
        return main(argv)
    finally:
        os.chdir(cwd)


def file_snapshot(directory):
    """Return every file under ``directory`` with its bytes (an input must stay untouched)."""
    return {os.path.relpath(os.path.join(root, name), directory):
            open(os.path.join(root, name), 'rb').read()
            for root, _, names in os.walk(directory) for name in names}


def rosbags_qos_yaml(profiles):
    """
    Serialise QoS profiles as the ``rosbags`` package parses them to rosbag2's YAML.

    Parameters
    ----------
    profiles : list of rosbags.interfaces.Qos
        E.g. the ``offered_qos_profiles`` of a rosbags connection.

    Returns
    -------
    str
        A YAML list in the format of :func:`profiles_yaml`, ``'[]'`` for none.

    """
    from rosbags.rosbag2.metadata import dump_qos_v9
    return profiles_yaml(dump_qos_v9(list(profiles)))
