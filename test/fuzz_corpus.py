"""
A seeded corpus of damaged bags, run through ``rotation_bag`` in-process, and its outcome table.

Sources are bags of a few dozen ``sensor_msgs/msg/Imu`` messages on ``/imu``
and some ``std_msgs/msg/String`` on ``/status``, written by writers the
package did not write: the ``mcap`` library (a plain ``.mcap``, chunks
uncompressed, lz4 or zstd, or no chunks), the ``rosbags`` rosbag2 writer
(mcap directories, with and without zstd chunks; sqlite3 directories, with and
without zstd message compression) and the ``rosbags`` ROS 1 writer (chunks
uncompressed, bz2 or lz4); the messages are serialized by rosbags. Each case
is a copy of a source with one seeded mutation of a storage file (or of
``metadata.yaml``): flipped bytes (anywhere, or one bit in a record's first
48 bytes), truncation, a length field set to 2^31..2^64-1 (the fields found
by parsing the file: :func:`mcap_layout`, :func:`ros1_layout`,
:func:`sqlite_layout`, and the string lengths of the messages stored
uncompressed), zeroed regions, swapped records, rows of the sqlite3 tables
that are not what rosbag2 writes (TEXT, INTEGER, empty or short data, an
unknown topic), garbage in ``metadata.yaml``.

Every case runs ``rotation_bag convert``, the read path of ``play`` (with a
stand-in for rclpy's publishers: no ROS graph) and, for a subset,
``plot``, through :func:`rotation_node.bag.cli.main`, in a forked child whose
address space is limited to 1 GB above what it holds when it starts
(:func:`run_cases`). Each run is classified (:func:`classify`); the accepted
outcomes are exit 0 with every message written read (``clean``), exit 0 with
a note for what was not read (``note``), and exit 1 with one line naming the
input (``error line``). Everything else is a failure: an exception escaping
``main`` (``traceback``; ``memory`` for a MemoryError, an allocation beyond
the limit), fewer messages than written without a note (``silent loss``),
a converted topic with fewer messages than its input and no reason printed,
printed counts that disagree with the output read back by rosbags (``counts
disagree``), a changed input, something left in the output directory or the
temporary directory, a hang or a crash of the child. Cases are seeded by their
place in the corpus, which only grows at its end (:func:`corpus`).
Informational, not a failure: an exit 0 that read fewer messages than
independent readers read and decode from the same damaged input
(:func:`oracle_counts`).

``python tools/fuzz_outcomes.py`` prints the table (:func:`outcome_table`).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import io
import json
import os
import re
import resource
import select
import shutil
import signal
import sqlite3
import struct
import tempfile
import time
import traceback
import types
from typing import Callable, Dict, List, Tuple

import numpy as np

IMU_TOPIC = '/imu'
STATUS_TOPIC = '/status'
IMU_COUNT = 40
STATUS_COUNT = 8
WRITTEN = {IMU_TOPIC: IMU_COUNT, STATUS_TOPIC: STATUS_COUNT}
#: convert's output: a single MCAP file (rosbags reads it back as the oracle).
CONVERTED = 'converted.mcap'
#: "Never more than 1 GB": what a child may map beyond what it maps when it starts.
MEMORY_LIMIT = 10**9
CASE_TIMEOUT_S = 60.0
#: One case in PLOT_EVERY of each source (and its metadata.yaml) is plotted too.
PLOT_EVERY = 24
ACCEPTED = ('clean', 'note', 'error line')
COLUMNS = ('clean', 'note', 'error line', 'traceback', 'silent loss', 'memory')
PARAMS_YAML = 'rotation_node:\n  ros__parameters:\n    input_type: imu\n    outputs: [euler]\n'


# --- Sources: bags of independent writers ------------------------------------------------

@dataclasses.dataclass
class Source:
    """One undamaged bag: ``path`` (a file or rosbag2 directory), its storage file, payloads."""

    name: str
    bag_format: str
    path: str
    storage_file: str
    #: ``[(message bytes as stored, offset of a string length field in them)]``
    payloads: List[Tuple[bytes, int]]


def _rows(seed, store_name):
    """
    ``[(topic, type name, serialized bytes, log time)]`` in log-time order.

    Serialized by rosbags: CDR with the Jazzy types, or ROS 1 with the Noetic
    types (rclpy's CDR leaves its alignment padding uninitialised: not
    reproducible). Random unit orientations and angular velocities at 100 Hz,
    a String on ``/status`` every 50 ms.
    """
    store = _typestore(store_name)
    types_ = store.types
    ros1 = store_name == 'ROS1_NOETIC'
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    rng = np.random.default_rng(seed)
    quaternions = rng.normal(size=(IMU_COUNT, 4))
    quaternions /= np.linalg.norm(quaternions, axis=1, keepdims=True)
    rates = rng.normal(size=(IMU_COUNT, 3))
    vector = types_['geometry_msgs/msg/Vector3']
    start_ns = 1_700_000_000 * 10**9
    rows = []
    for k, (q, w) in enumerate(zip(quaternions.tolist(), rates.tolist())):
        stamp_ns = start_ns + k * 10_000_000
        header = {'stamp': types_['builtin_interfaces/msg/Time'](*divmod(stamp_ns, 10**9)),
                  'frame_id': 'imu_link', **({'seq': k} if ros1 else {})}
        value = types_['sensor_msgs/msg/Imu'](
            header=types_['std_msgs/msg/Header'](**header),
            orientation=types_['geometry_msgs/msg/Quaternion'](*q),
            orientation_covariance=np.diag([1e-6, 2e-6, 4e-6]).ravel(),
            angular_velocity=vector(*w), angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vector(0.0, 0.0, 9.81),
            linear_acceleration_covariance=np.zeros(9))
        rows.append((IMU_TOPIC, 'sensor_msgs/msg/Imu',
                     bytes(serialize(value, 'sensor_msgs/msg/Imu')), stamp_ns + 1_000_000))
    for k in range(STATUS_COUNT):
        value = types_['std_msgs/msg/String'](data=f'status {k}: ok')
        rows.append((STATUS_TOPIC, 'std_msgs/msg/String',
                     bytes(serialize(value, 'std_msgs/msg/String')),
                     start_ns + 4_000_000 + k * 50_000_000))
    return sorted(rows, key=lambda row: row[3])


#: Where a string length field is in a message: CDR (4-byte encapsulation header first),
#: ROS 1 (Imu: seq, stamp, then frame_id).
_CDR_LENGTH_AT = {IMU_TOPIC: 12, STATUS_TOPIC: 4}
_ROS1_LENGTH_AT = {IMU_TOPIC: 12, STATUS_TOPIC: 0}


def _write_mcap_file(path, rows, compression, chunked):
    """Write a ``.mcap`` with the mcap library: ros2 profile, ros2msg schemas, 2 kB chunks."""
    from mcap.writer import CompressionType, Writer

    from rotation_node.wire.message_types import message_definition
    with open(path, 'wb') as stream:
        writer = Writer(stream, chunk_size=2048, compression=CompressionType[compression],
                        use_chunking=chunked)
        writer.start(profile='ros2', library='fuzz-corpus')
        channels = {}
        for topic, type_name, data, log_time in rows:
            if topic not in channels:
                schema = writer.register_schema(type_name, 'ros2msg',
                                                message_definition(type_name).encode())
                channels[topic] = writer.register_channel(
                    topic, 'cdr', schema, metadata={'offered_qos_profiles': ''})
            writer.add_message(channels[topic], log_time=log_time, data=data,
                               publish_time=log_time)
        writer.finish()


def _write_ros1_bag(path, rows, compression):
    """Write a ROS 1 bag with rosbags' writer, in small chunks."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS1_NOETIC)
    writer = Writer(path)
    writer.chunk_threshold = 2048
    if compression != 'none':
        writer.set_compression(Writer.CompressionFormat[compression.upper()])
    with writer:
        connections = {}
        for topic, type_name, data, time_ns in rows:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, type_name, typestore=store)
            writer.write(connections[topic], time_ns, data)


def _storage_file(directory):
    name, = [n for n in os.listdir(directory) if n.endswith(('.mcap', '.db3'))]
    return os.path.join(directory, name)


def build_sources(directory, seed=2311) -> Dict[str, Source]:
    """Write every source bag into ``directory``; return them by name."""
    from bag_helpers import write_rosbag2
    from pathlib import Path
    os.makedirs(directory, exist_ok=True)
    rows, ros1_rows = _rows(seed, 'ROS2_JAZZY'), _rows(seed, 'ROS1_NOETIC')
    cdr_payloads = [(data, _CDR_LENGTH_AT[topic]) for topic, _, data, _ in rows]
    ros1_payloads = [(data, _ROS1_LENGTH_AT[topic]) for topic, _, data, _ in ros1_rows]
    sources = {}

    def add(name, fmt, path, storage_file, payloads):
        sources[name] = Source(name, fmt, str(path), str(storage_file), payloads)

    for compression, chunked in (('NONE', True), ('LZ4', True), ('ZSTD', True),
                                 ('NONE', False)):
        name = f'mcap-{compression.lower()}' + ('' if chunked else '-unchunked')
        path = os.path.join(directory, name + '.mcap')
        _write_mcap_file(path, rows, compression, chunked)
        add(name, 'mcap file', path, path, cdr_payloads)
    for storage, compression in (('mcap', None), ('mcap', 'storage'), ('sqlite3', None)):
        name = f'rosbag2-{storage}' + (f'-{compression}' if compression else '')
        path = write_rosbag2(Path(directory) / name, rows,
                             storage=storage, compression=compression)
        add(name, f'rosbag2 {storage}', path, _storage_file(path), cdr_payloads)
    for compression in ('none', 'bz2', 'lz4'):
        name = f'ros1-{compression}'
        path = os.path.join(directory, name + '.bag')
        _write_ros1_bag(path, ros1_rows, compression)
        add(name, 'ROS 1 bag', path, path, ros1_payloads)
    # rosbag2's message compression: each row a zstd frame
    path = write_rosbag2(Path(directory) / 'rosbag2-sqlite3-message', rows, storage='sqlite3',
                         compression='message')
    add('rosbag2-sqlite3-message', 'rosbag2 sqlite3', path, _storage_file(path), [])
    return sources


# --- Layouts: where the records and the length fields are ---------------------------------

@dataclasses.dataclass
class Layout:
    """Records ``[(start, end, kind)]``, length fields ``[(offset, width, byte order, what)]``."""

    records: List[Tuple[int, int, str]]
    lengths: List[Tuple[int, int, str, str]]


_MCAP_MAGIC = b'\x89MCAP0\r\n'
_MCAP_NAMES = {1: 'header', 2: 'footer', 3: 'schema', 4: 'channel', 5: 'message', 6: 'chunk',
               7: 'message index', 8: 'chunk index', 9: 'attachment', 10: 'attachment index',
               11: 'statistics', 12: 'metadata', 13: 'metadata index', 14: 'summary offset',
               15: 'data end'}
# The fields of an MCAP record up to the last length field worth damaging: u<n>
# fixed fields, 'str'/'bytes'/'map' (a u32 length and what it counts), 'L<n>'
# fixed fields that are lengths, offsets or counts, 'records' (u64 length of a
# chunk's records).
_MCAP_FIELDS = {
    1: ['str', 'str'],
    2: ['L8', 'L8'],
    3: [2, 'str', 'str', 'bytes'],
    4: [2, 2, 'str', 'str', 'map'],
    6: [8, 8, 'L8', 4, 'str', 'records'],
    7: [2, 'map'],
    8: [8, 8, 'L8', 'L8', 'map', 'L8', 'str', 'L8', 'L8'],
    11: ['L8', 2, 'L4', 'L4', 'L4', 'L4', 8, 8, 'map'],
    12: ['str', 'map'],
    13: ['L8', 'L8', 'str'],
    14: [1, 'L8', 'L8'],
}


def _mcap_records(data, start, end, layout, inside=''):
    position = start
    while position + 9 <= end:
        opcode, length = struct.unpack_from('<BQ', data, position)
        kind = inside + _MCAP_NAMES.get(opcode, f'opcode {opcode}')
        body, record_end = position + 9, position + 9 + length
        if record_end > end:
            break
        if not inside:
            layout.records.append((position, record_end, kind))
        layout.lengths.append((position + 1, 8, '<', f'{kind} record length'))
        field = body
        compression = None
        for spec in _MCAP_FIELDS.get(opcode, []):
            if isinstance(spec, int):
                field += spec
            elif spec.startswith('L'):
                layout.lengths.append((field, int(spec[1]), '<',
                                       f'{kind} field at {field - body}'))
                field += int(spec[1])
            elif spec == 'records':
                layout.lengths.append((field, 8, '<', f'{kind} records length'))
                records_length, = struct.unpack_from('<Q', data, field)
                if compression == '':
                    _mcap_records(data, field + 8, min(field + 8 + records_length, record_end),
                                  layout, inside='chunked ')
            else:
                layout.lengths.append((field, 4, '<', f'{kind} {spec} length'))
                size, = struct.unpack_from('<I', data, field)
                if spec == 'str' and opcode == 6:
                    compression = bytes(data[field + 4:field + 4 + size]).decode()
                field += 4 + size
        position = record_end
        if opcode == 2:   # footer: the closing magic follows
            break


def mcap_layout(data: bytes) -> Layout:
    """Parse an MCAP file: its top-level records and every length field (also in plain chunks)."""
    layout = Layout([], [])
    _mcap_records(data, len(_MCAP_MAGIC), len(data), layout)
    return layout


_ROS1_MAGIC = b'#ROSBAG V2.0\n'
_ROS1_OPS = {2: 'message data', 3: 'bag header', 4: 'index data', 5: 'chunk', 6: 'chunk info',
             7: 'connection'}
#: Header fields of ROS 1 records that are lengths, offsets or counts.
_ROS1_LENGTH_FIELDS = {'index_pos': 8, 'conn_count': 4, 'chunk_count': 4, 'size': 4,
                       'count': 4, 'chunk_pos': 8}


def _ros1_records(data, start, end, layout, inside=''):
    position = start
    while position + 4 <= end:
        header_length, = struct.unpack_from('<I', data, position)
        header_end = position + 4 + header_length
        if header_end + 4 > end:
            break
        fields, field = {}, position + 4
        while field + 4 <= header_end:
            size, = struct.unpack_from('<I', data, field)
            name, _, value = bytes(data[field + 4:field + 4 + size]).partition(b'=')
            fields[name.decode('latin-1')] = (field + 4 + len(name) + 1, value)
            layout.lengths.append((field, 4, '<', f'{inside}header field length'))
            field += 4 + size
        op = fields.get('op', (0, b'\0'))[1][:1]
        kind = inside + _ROS1_OPS.get(op[0] if op else 0, 'record')
        data_length, = struct.unpack_from('<I', data, header_end)
        record_end = header_end + 4 + data_length
        if record_end > end:
            break
        if not inside:
            layout.records.append((position, record_end, kind))
        layout.lengths.append((position, 4, '<', f'{kind} header length'))
        layout.lengths.append((header_end, 4, '<', f'{kind} data length'))
        for name, width in _ROS1_LENGTH_FIELDS.items():
            if name in fields and len(fields[name][1]) == width:
                layout.lengths.append((fields[name][0], width, '<', f'{kind} {name}'))
        if kind == 'chunk' and fields.get('compression', (0, b''))[1] == b'none':
            _ros1_records(data, header_end + 4, record_end, layout, inside='chunked ')
        position = record_end


def ros1_layout(data: bytes) -> Layout:
    """Parse a ROS 1 bag: its records, header and data lengths, sizes, counts and positions."""
    layout = Layout([], [])
    _ros1_records(data, len(_ROS1_MAGIC), len(data), layout)
    return layout


def sqlite_layout(data: bytes) -> Layout:
    """Return the layout of a SQLite file: its pages, the header's page count and freelist."""
    page_size, = struct.unpack_from('>H', data, 16)
    page_size = 65536 if page_size == 1 else page_size
    records = [(start, min(start + page_size, len(data)), f'page {start // page_size + 1}')
               for start in range(0, len(data), page_size)]
    lengths = [(28, 4, '>', 'database size in pages'), (32, 4, '>', 'first freelist page'),
               (36, 4, '>', 'freelist pages'), (56, 4, '>', 'text encoding'),
               (40, 4, '>', 'schema cookie')]
    return Layout(records, lengths)


def _payload_lengths(data, payloads):
    """Return the string length fields of the messages stored as they are (uncompressed)."""
    found = []
    for payload, length_at in payloads:
        at = bytes(data).find(payload)
        if at >= 0:
            found.append((at + length_at, 4, '<', 'message string length'))
    return found


def layout_of(source: Source, data: bytes) -> Layout:
    """Return the layout of a source's storage file, with the message string lengths in it."""
    if data.startswith(_MCAP_MAGIC):
        layout = mcap_layout(data)
    elif data.startswith(_ROS1_MAGIC):
        layout = ros1_layout(data)
    else:
        layout = sqlite_layout(data)
    layout.lengths.extend(_payload_lengths(data, source.payloads))
    return layout


# --- Damage ----------------------------------------------------------------------------------

def _flip(data, rng, layout):
    data = bytearray(data)
    flips = int(rng.integers(1, 9))
    for offset in rng.integers(0, len(data), flips).tolist():
        data[offset] ^= int(rng.integers(1, 256))
    return bytes(data), f'{flips} bytes flipped'


def _flip_header(data, rng, layout):
    # Where the structure is: the first 48 bytes of a record (lengths, names, offsets).
    data = bytearray(data)
    start, end, kind = layout.records[int(rng.integers(len(layout.records)))]
    offset = int(rng.integers(start, min(end, start + 48)))
    data[offset] ^= 1 << int(rng.integers(8))
    return bytes(data), f'a bit of byte {offset} flipped ({kind} at {start})'


def _truncate(data, rng, layout):
    # Half anywhere, half in the last quarter (where an interrupted writer stops).
    low = 0 if rng.random() < 0.5 else len(data) * 3 // 4
    at = int(rng.integers(low, len(data)))
    return data[:at], f'cut at {at} of {len(data)}'


def _large_value(rng, width):
    top = 8 * width
    choice = int(rng.integers(4))
    if choice == 0:
        return 2**31
    if choice == 1:
        return 2**top - 1
    return int(rng.integers(2**31, 2**top - 1, dtype=np.uint64, endpoint=True)) if top == 64 \
        else int(rng.integers(2**31, 2**32))


def _length(data, rng, layout):
    offset, width, order, what = layout.lengths[int(rng.integers(len(layout.lengths)))]
    value = _large_value(rng, width)
    data = bytearray(data)
    data[offset:offset + width] = value.to_bytes(width, 'little' if order == '<' else 'big')
    return bytes(data), f'{what} at {offset} set to {value}'


def _zero(size):
    def zero(data, rng, layout):
        at = int(rng.integers(0, max(1, len(data) - size)))
        data = bytearray(data)
        data[at:at + size] = bytes(len(data[at:at + size]))
        return bytes(data), f'{size} bytes zeroed at {at}'
    return zero


def _swap(data, rng, layout):
    records = layout.records
    chunks = [r for r in records if r[2] == 'chunk']
    pool = chunks if len(chunks) >= 2 and rng.random() < 0.5 else records
    first, second = sorted(rng.choice(len(pool), 2, replace=False).tolist())
    (a0, a1, a_kind), (b0, b1, b_kind) = pool[first], pool[second]
    swapped = data[:a0] + data[b0:b1] + data[a1:b0] + data[a0:a1] + data[b1:]
    return swapped, f'{a_kind} at {a0} swapped with {b_kind} at {b0}'


DAMAGE: Dict[str, Callable] = {
    'flip': _flip, 'flip header': _flip_header, 'truncate': _truncate, 'length': _length,
    'zero 64': _zero(64), 'zero 512': _zero(512), 'zero 4096': _zero(4096), 'swap': _swap,
}
#: Cases per source and damage.
CASES_PER_DAMAGE = {'flip': 5, 'truncate': 4, 'length': 6, 'zero 64': 2, 'zero 512': 2,
                    'zero 4096': 2, 'swap': 3}
#: Damages and sources added later: their cases come after the others, which keep their seeds.
LATER_CASES_PER_DAMAGE = {'flip header': 3}
LATER_SOURCES = ('rosbag2-sqlite3-message',)

# Rows of the sqlite3 messages table that are not what rosbag2 writes.
_SQL_ROWS = [
    ('data TEXT', "UPDATE messages SET data = 'not a message' WHERE id = ?"),
    ('data TEXT of the bytes', 'UPDATE messages SET data = CAST(data AS TEXT) WHERE id = ?'),
    ('data empty', 'UPDATE messages SET data = zeroblob(0) WHERE id = ?'),
    ('data short', 'UPDATE messages SET data = substr(data, 1, 10) WHERE id = ?'),
    ('data INTEGER', 'UPDATE messages SET data = 42 WHERE id = ?'),
    ('timestamp TEXT', "UPDATE messages SET timestamp = 'yesterday' WHERE id = ?"),
    ('topic_id unknown', 'UPDATE messages SET topic_id = 99 WHERE id = ?'),
    ('topic name TEXT of bytes', "UPDATE topics SET name = CAST(X'2F696DFF75' AS TEXT) "
                                 'WHERE ? > 0'),
    ('type INTEGER', "UPDATE topics SET type = 7 WHERE name = '/imu' AND ? > 0"),
]

_METADATA_GARBAGE = [
    ('binary garbage', lambda text, rng: bytes(rng.integers(0, 256, 300, dtype=np.uint8))),
    ('not UTF-8', lambda text, rng: text.replace(b'rosbag2', b'ros\xffbag2')),
    ('a list', lambda text, rng: b'- 1\n- 2\n'),
    ('cut short', lambda text, rng: text[:int(rng.integers(1, len(text)))]),
    ('unknown storage', lambda text, rng: re.sub(rb'storage_identifier: \w+',
                                                 b'storage_identifier: 7', text)),
    ('no file list', lambda text, rng: re.sub(rb'relative_file_paths:\n(  - .*\n)+', b'',
                                              text)),
    ('file list is a number', lambda text, rng: re.sub(
        rb'relative_file_paths:\n(  - .*\n)+', b'relative_file_paths: 3\n', text)),
    ('path outside the bag', lambda text, rng: re.sub(rb'(relative_file_paths:\n  - ).*\n',
                                                      rb'\1../../../etc/passwd\n', text)),
    ('huge message count', lambda text, rng: re.sub(rb'message_count: \d+',
                                                    b'message_count: 18446744073709551615',
                                                    text)),
    ('alias bomb', lambda text, rng: text + b''.join(
        b'x%d: &x%d [%s]\n' % (i, i, b', '.join([b'*x%d' % (i - 1)] * 9) if i else b'a')
        for i in range(9))),
    ('compression format', lambda text, rng: re.sub(rb'compression_mode: .*', b'compression_mode: '
                                                    b'file\n  compression_format: ""', text, 1)),
    ('tab characters', lambda text, rng: text.replace(b'  ', b'\t', 3)),
]


@dataclasses.dataclass
class Case:
    """One damaged copy of a source: ``damage`` applied with ``seed``; ``commands`` to run."""

    case_id: str
    source: str
    bag_format: str
    damage: str
    seed: int
    commands: Tuple[str, ...]


def _entries(name, source, damages):
    entries = [('none', 0)]
    entries += [(damage, k) for damage, count in damages.items() for k in range(count)]
    if source.bag_format == 'rosbag2 sqlite3':
        entries += [('sql ' + label, k) for k, (label, _) in enumerate(_SQL_ROWS)]
    if source.bag_format.startswith('rosbag2') and 'storage' not in name:
        entries += [('metadata ' + label, k) for k, (label, _) in enumerate(_METADATA_GARBAGE)]
    return entries


def corpus(sources: Dict[str, Source], seed: int = 23) -> List[Case]:
    """
    Return every case, in a fixed order: per source, an undamaged control and each damage.

    A case's seed is its place in the corpus: the damages and sources added
    later (``LATER_CASES_PER_DAMAGE``, ``LATER_SOURCES``) come after the
    others, which keep their seeds.
    """
    cases: List[Case] = []
    first = [(name, source) for name, source in sources.items() if name not in LATER_SOURCES]
    later = [(name, source) for name, source in sources.items() if name in LATER_SOURCES]
    for number, (name, source) in enumerate(first):
        _add_cases(cases, number, name, source, _entries(name, source, CASES_PER_DAMAGE), seed)
    for number, (name, source) in enumerate(first):
        _add_cases(cases, number, name, source, [
            (damage, k) for damage, count in LATER_CASES_PER_DAMAGE.items()
            for k in range(count)], seed, plots=False)
    for number, (name, source) in enumerate(later, len(first)):
        _add_cases(cases, number, name, source, _entries(
            name, source, {**CASES_PER_DAMAGE, **LATER_CASES_PER_DAMAGE}), seed)
    return cases


def _add_cases(cases, number, name, source, entries, seed, plots=True):
    groups: Dict[str, list] = {}   # by the format of the table: storage or metadata.yaml
    for damage, k in entries:
        bag_format = 'metadata.yaml' if damage.startswith('metadata') else source.bag_format
        groups.setdefault(bag_format, []).append((damage, k))
    for bag_format, group in groups.items():
        # A plot costs ten conversions: one case in PLOT_EVERY of each group, at least
        # one, a different damage for each source.
        plotted = (1 + 7 * number) % min(PLOT_EVERY, len(group)) if plots else -1
        for position, (damage, k) in enumerate(group):
            cases.append(Case(
                f'{name}.{damage.replace(" ", "_")}.{k}', name, bag_format, damage,
                seed * 100_003 + len(cases), ('convert', 'play', 'plot')
                if position % PLOT_EVERY == plotted else ('convert', 'play')))


def damage_class(case: Case) -> str:
    """Return the row of the outcome table: the damage without its variant (sql, metadata)."""
    if case.damage.startswith('sql '):
        return 'sqlite3 rows'
    if case.damage.startswith('metadata '):
        return 'garbage'
    return case.damage


def materialize(case: Case, sources: Dict[str, Source], directory: str) -> Tuple[str, str]:
    """
    Write the damaged copy of the case's source into ``directory``.

    Returns
    -------
    input_path : str
        What to pass to ``rotation_bag``.
    description : str
        What the damage was (offset, field, value), for a reproduction.

    """
    source = sources[case.source]
    rng = np.random.default_rng(case.seed)
    os.makedirs(directory, exist_ok=True)
    if os.path.isdir(source.path):
        target_dir = os.path.join(directory, os.path.basename(source.path))
        shutil.copytree(source.path, target_dir)
        input_path = target_dir
        storage = os.path.join(target_dir, os.path.basename(source.storage_file))
    else:
        input_path = os.path.join(directory, os.path.basename(source.path))
        shutil.copyfile(source.path, input_path)
        storage = input_path
    if case.damage == 'none':
        return input_path, 'undamaged'
    if case.damage.startswith('sql '):
        label, statement = _SQL_ROWS[[label for label, _ in _SQL_ROWS].index(case.damage[4:])]
        row = int(rng.integers(1, IMU_COUNT + STATUS_COUNT + 1))
        with contextlib.closing(sqlite3.connect(storage)) as database:
            database.execute(statement, (row,))
            database.commit()
        return input_path, f'{label} in row {row}'
    if case.damage.startswith('metadata '):
        metadata = os.path.join(input_path, 'metadata.yaml')
        labels = [label for label, _ in _METADATA_GARBAGE]
        label, change = _METADATA_GARBAGE[labels.index(case.damage[9:])]
        with open(metadata, 'rb') as stream:
            text = stream.read()
        with open(metadata, 'wb') as stream:
            stream.write(change(text, rng))
        return input_path, label
    with open(storage, 'rb') as stream:
        data = stream.read()
    damaged, description = DAMAGE[case.damage](data, rng, layout_of(source, data))
    with open(storage, 'wb') as stream:
        stream.write(damaged)
    return input_path, f'{os.path.basename(storage)}: {description}'


# --- Running a case and classifying what happened --------------------------------------------

def tree_hash(path: str) -> str:
    """SHA-256 over the names and contents of a file or of every file under a directory."""
    digest = hashlib.sha256()
    paths = [path] if not os.path.isdir(path) else sorted(
        os.path.join(root, name) for root, _, names in os.walk(path) for name in names)
    for name in paths:
        digest.update(os.path.relpath(name, path).encode())
        with open(name, 'rb') as stream:
            digest.update(stream.read())
    return digest.hexdigest()


class _Publisher:
    def __init__(self, counts, msg_type, topic, qos):
        self.counts, self.msg_type, self.topic, self.qos_profile = counts, msg_type, topic, qos

    def publish(self, data):
        if not isinstance(data, (bytes, self.msg_type)):   # as rclpy's Publisher.publish
            raise TypeError(f'Expected {self.msg_type}, got {type(data)}')
        self.counts[self.topic] = self.counts.get(self.topic, 0) + 1

    def get_subscription_count(self):
        return 1

    def wait_for_all_acked(self, timeout):
        return True


def _stand_in_rclpy(counts):
    """Return what ``play`` uses of rclpy, without a ROS graph: publishers that count."""
    logger = types.SimpleNamespace(info=lambda text: None)
    node = types.SimpleNamespace(
        create_publisher=lambda cls, topic, qos: _Publisher(counts, cls, topic, qos),
        get_logger=lambda: logger, destroy_node=lambda: None)
    return types.SimpleNamespace(init=lambda **kwargs: None, create_node=lambda name: node,
                                 try_shutdown=lambda: None)


def _escape_site(error):
    """``(innermost frame, innermost frame of rotation_node)`` of an exception, as text."""
    frames = traceback.extract_tb(error.__traceback__)
    own = [f for f in frames if '/rotation_node/' in f.filename]

    def text(frame):
        return f'{os.path.relpath(frame.filename)}:{frame.lineno} in {frame.name}' \
            if frame else ''
    return text(frames[-1] if frames else None), text(own[-1] if own else None)


def run_main(argv: List[str], play_counts: Dict[str, int]) -> tuple:
    """Run ``rotation_bag argv`` in-process: ``(exit status, stderr, escaped exception)``."""
    from unittest import mock

    from rotation_node.bag import cli, play
    stderr, stdout = io.StringIO(), io.StringIO()
    status, escaped = None, None
    with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(stdout), \
            mock.patch.object(play, 'rclpy', _stand_in_rclpy(play_counts)):
        try:
            status = cli.main(argv)
        except SystemExit as error:
            status = error.code
        except BaseException as error:   # noqa: B902 -- what escapes main is what is tested
            escaped = error
    return status, stderr.getvalue(), escaped


def _rosbags_counts(path):
    """``{topic: messages}`` of a rosbag2 output as rosbags reads it (the oracle)."""
    from rosbags.rosbag2 import Reader
    counts = {}
    with Reader(path) as reader:
        for connection, _, _ in reader.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
    return counts


_TOPIC_LINE = re.compile(r'^(\S+): (\d+) messages -> (\S+): (\d+) messages(;.*)?$')
_DESCRIPTION = re.compile(r'^(.*): (.*), (\d+) messages$')
_PLOTTED = re.compile(r'^plotted (\d+) messages of (\S+) to ')


def _loss_class(read, written, notes):
    if read < written:
        return 'note' if notes else 'silent loss'
    if read > written:
        return 'counts disagree'
    return 'note' if notes else 'clean'


def classify(command: str, input_path: str, status, stderr: str, escaped, out_dir: str,
             play_counts: Dict[str, int]) -> Tuple[str, str]:
    """
    Return ``(class, detail)`` of one run (see the module's docstring for the classes).

    The output directory ``out_dir`` held nothing before the run.
    """
    lines = stderr.splitlines()
    if escaped is not None:
        where, own = _escape_site(escaped)
        kind = 'memory' if isinstance(escaped, MemoryError) else 'traceback'
        return kind, f'{type(escaped).__name__}: {str(escaped)[:160]} at {where}' + (
            f' (from {own})' if own and own != where else '')
    if 'Traceback (most recent call last)' in stderr:
        return 'traceback', 'a traceback printed: ' + ' | '.join(lines[-3:])[:300]
    left = sorted(os.listdir(out_dir))
    if status == 1:
        if left:
            return 'left behind', f'exit 1 and {out_dir} holds {left}'
        prefix = f'rotation_bag {command}: error: '
        errors = [line for line in lines if line.startswith(prefix)]
        # play reports the input's notes before it publishes: they may precede the error.
        allowed = len(lines) == 1 or (command == 'play' and len(errors) == 1
                                      and lines[-1] == errors[0])
        if not (errors and allowed):
            return 'bad error line', f'{len(lines)} lines: ' + ' | '.join(lines)[:300]
        if input_path not in errors[0]:
            return 'bad error line', f'does not name the input: {errors[0][:300]}'
        return 'error line', errors[0][len(prefix):]
    if status != 0:
        return 'bad exit', f'exit {status!r}: ' + ' | '.join(lines)[:300]
    written = sum(WRITTEN.values())
    if command == 'convert':
        output = os.path.join(out_dir, CONVERTED)
        if left != [CONVERTED]:
            return 'left behind', f'exit 0 and {out_dir} holds {left}'
        try:
            counts = _rosbags_counts(output)
        except Exception as error:   # noqa: B902 -- rosbags' errors have no common base
            return 'bad output', f'rosbags cannot read the output: {type(error).__name__}: {error}'
        described, notes, outputs = None, [], {}
        for line in lines:
            topic_line, description = _TOPIC_LINE.match(line), _DESCRIPTION.match(line)
            if topic_line:
                outputs[topic_line[1]] = (int(topic_line[2]), topic_line[3], int(topic_line[4]),
                                          topic_line[5])
            elif description and described is None and description[1] == input_path:
                described = int(description[3])
            elif line != f'wrote {output}':
                notes.append(line)
        for topic, (received, out_topic, published, reasons) in outputs.items():
            if counts.get(topic, 0) != received or counts.get(out_topic, 0) != published:
                return 'counts disagree', (
                    f'printed {topic} {received} -> {published}, the output holds '
                    f'{counts.get(topic, 0)} -> {counts.get(out_topic, 0)}')
            if published < received and not reasons:   # each message skipped has its reason
                return 'silent loss', f'{topic}: {received} messages, {published} converted'
        converted = {out_topic for _, out_topic, _, _ in outputs.values()}
        read = sum(count for topic, count in counts.items() if topic not in converted)
        klass = _loss_class(read, written, notes)
        if klass == 'clean' and described != read:
            return 'counts disagree', f'described {described} messages, read {read}, no note'
        return klass, f'read {read} of {written}' + (
            f'; notes: {" | ".join(notes)}' if notes else '')
    if command == 'plot':
        plotted = [_PLOTTED.match(line) for line in lines]
        count = next((int(m[1]) for m in plotted if m), None)
        notes = [line for line, m in zip(lines, plotted) if not m]
        if count is None:
            return 'bad output', 'exit 0 without a plotted line: ' + ' | '.join(lines)[:300]
        if left != ['plot.png']:
            return 'left behind', f'exit 0 and {out_dir} holds {left}'
        klass = _loss_class(count, WRITTEN[IMU_TOPIC], notes)
        return klass, f'plotted {count} of {WRITTEN[IMU_TOPIC]}' + (
            f'; notes: {" | ".join(notes)}' if notes else '')
    read = sum(play_counts.values())
    if left:
        return 'left behind', f'play wrote {left} into {out_dir}'
    return _loss_class(read, written, lines), f'published {read} of {written}' + (
        f'; notes: {" | ".join(lines)}' if lines else '')


@functools.lru_cache(maxsize=None)
def _typestore(name):
    """Return a rosbags type store, made once (it compiles its deserializers as they are used)."""
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(getattr(Stores, name))


def _decodable(typestore, type_name, data, ros1=False):
    try:
        (typestore.deserialize_ros1 if ros1 else typestore.deserialize_cdr)(data, type_name)
    except Exception:   # noqa: B902 -- the oracle: whatever rosbags cannot decode
        return False
    return True


def _counted(messages, counts):
    """Count ``(topic, decodable)`` into ``counts`` until the reader fails; return ``counts``."""
    try:
        for topic, decodable in messages:
            if decodable:
                counts[topic] = counts.get(topic, 0) + 1
    except (Exception, MemoryError):   # noqa: B902 -- where the oracle stops
        pass
    return counts


def _mcap_scan(path, typestore):
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader
    schemas, channels = {}, {}
    with open(path, 'rb') as stream:
        for record in StreamReader(stream, validate_crcs=True).records:
            if isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel):
                channels[record.id] = (record.topic, schemas.get(record.schema_id, ''))
            elif isinstance(record, Message) and record.channel_id in channels:
                topic, type_name = channels[record.channel_id]
                yield topic, _decodable(typestore, type_name, record.data)


def _mcap_indexed(path, typestore):
    from mcap.reader import make_reader
    with open(path, 'rb') as stream:
        for schema, channel, message in make_reader(stream, validate_crcs=True).iter_messages():
            yield channel.topic, _decodable(typestore, schema.name if schema else '', message.data)


def _rosbags_messages(path, typestore, reader_class, ros1=False):
    with reader_class(path) as reader:
        for connection, _, data in reader.messages():
            yield connection.topic, isinstance(data, (bytes, memoryview)) and _decodable(
                typestore, connection.msgtype, bytes(data), ros1)


def oracle_counts(input_path: str, source: Source) -> Dict[str, int]:
    """
    Return ``{topic: messages}`` that independent readers read and rosbags decodes, at best.

    A lower bound of what is readable in a damaged input: the mcap library
    (a linear scan, CRCs checked, and its indexed reader) for MCAP, rosbags'
    readers for rosbag2 directories and ROS 1 bags, each counted up to where
    it fails; the best of them.
    """
    from rosbags.rosbag1 import Reader as Ros1Reader
    from rosbags.rosbag2 import Reader as Rosbag2Reader
    if source.bag_format == 'ROS 1 bag':
        store = _typestore('ROS1_NOETIC')
        readings = [_rosbags_messages(input_path, store, Ros1Reader, ros1=True)]
    else:
        store = _typestore('ROS2_JAZZY')
        readings = [_rosbags_messages(input_path, store, Rosbag2Reader)] \
            if os.path.isdir(input_path) else []
        storage = (os.path.join(input_path, os.path.basename(source.storage_file))
                   if os.path.isdir(input_path) else input_path)
        if storage.endswith('.mcap'):
            readings += [_mcap_scan(storage, store), _mcap_indexed(storage, store)]
    counts = [_counted(reading, {}) for reading in readings]
    return max(counts, key=lambda c: sum(c.values()), default={})


_READ = re.compile(r'^(?:read|published|plotted) (\d+) of ')


def command_line(command: str, input_path: str, out_dir: str, params: str) -> List[str]:
    """Return the arguments of ``rotation_bag`` for a run; its output goes into ``out_dir``."""
    return {'convert': ['convert', input_path, os.path.join(out_dir, CONVERTED),
                        '--params', params],
            # play's read path: the stand-in publishers, no waiting between messages
            'play': ['play', input_path, '--rate', '1e300'],
            'plot': ['plot', input_path, '--topic', IMU_TOPIC, '-o',
                     os.path.join(out_dir, 'plot.png')]}[command]


def run_case(case: Case, sources: Dict[str, Source], directory: str, params: str) -> List[dict]:
    """Materialize a case under ``directory``, run its commands, return one result per command."""
    case_dir = os.path.join(directory, case.case_id)
    os.makedirs(case_dir)
    results = []
    try:
        input_path, description = materialize(case, sources, case_dir)
        before = tree_hash(input_path)
        for command in case.commands:
            out_dir = os.path.join(case_dir, f'out_{command}')
            os.makedirs(out_dir)
            argv = command_line(command, input_path, out_dir, params)
            play_counts: Dict[str, int] = {}
            started = time.process_time()
            status, stderr, escaped = run_main(argv, play_counts)
            seconds = time.process_time() - started
            klass, detail = classify(command, input_path, status, stderr, escaped, out_dir,
                                     play_counts)
            if tree_hash(input_path) != before:
                klass, detail = 'input changed', f'{input_path} changed ({klass}: {detail})'
            leftovers = os.listdir(tempfile.gettempdir())
            if leftovers:
                klass, detail = 'left behind', f'temporary files {leftovers} ({klass}: {detail})'
                for name in leftovers:
                    shutil.rmtree(os.path.join(tempfile.gettempdir(), name), ignore_errors=True)
            results.append({**_result_fields(case, command), 'mutation': description,
                            'status': status, 'klass': klass, 'detail': detail,
                            'seconds': seconds})
        # Informational: exit 0 with fewer messages than independent readers read and decode.
        oracle = oracle_counts(input_path, sources[case.source]) if any(
            result['status'] == 0 for result in results) else {}
        for result in results:
            read = _READ.match(result['detail']) if result['status'] == 0 else None
            readable = (oracle.get(IMU_TOPIC, 0) if result['command'] == 'plot'
                        else sum(oracle.values()))
            result['below_oracle'] = bool(read) and int(read[1]) < readable
            result['oracle'] = readable
    finally:
        shutil.rmtree(case_dir, ignore_errors=True)
    return results


# --- The forked runner: 1 GB more address space, a watchdog ---------------------------------

def _address_space():
    with open('/proc/self/status') as stream:
        for line in stream:
            if line.startswith('VmSize:'):
                return int(line.split()[1]) * 1024
    raise RuntimeError('no VmSize in /proc/self/status')


def limit_address_space(extra: int = MEMORY_LIMIT) -> None:
    """Let this process map at most ``extra`` bytes more than it has mapped now."""
    limit = _address_space() + extra
    resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))


def _child(cases, sources, directory, params, pipe, tmp):
    """Run ``cases`` in this (forked) process, one JSON line per event on ``pipe``."""
    os.makedirs(tmp, exist_ok=True)
    tempfile.tempdir = tmp
    os.environ['TMPDIR'] = tmp
    limit_address_space()
    # What a damaged input does is under test, not durability: the outputs' fsync
    # and fdatasync calls (a third of a conversion's time here) are skipped.
    os.fsync = os.fdatasync = lambda descriptor: None
    with os.fdopen(pipe, 'w') as stream:
        for case in cases:
            stream.write(json.dumps({'start': case.case_id}) + '\n')
            stream.flush()
            results = run_case(case, sources, directory, params)
            stream.write(json.dumps({'results': results}) + '\n')
            stream.flush()


def _result_fields(case, command):
    return {'case': case.case_id, 'source': case.source, 'format': case.bag_format,
            'damage': case.damage, 'damage_class': damage_class(case), 'seed': case.seed,
            'command': command}


def _broken(case, klass, detail):
    return [{**_result_fields(case, command), 'mutation': '', 'status': None, 'klass': klass,
             'detail': detail, 'seconds': None, 'below_oracle': False, 'oracle': None}
            for command in case.commands]


def _warm_up(sources, directory, params):
    """
    Convert and plot an undamaged source in this process, before forking.

    The children inherit the loaded libraries and the compiled kernels (a
    first compilation, in a fresh checkout, can take a minute on a loaded
    machine: no case's time).
    """
    source = next(iter(sources.values()))
    out_dir = os.path.join(directory, 'warm-up')
    os.makedirs(out_dir)
    for command in ('convert', 'plot'):
        status, stderr, escaped = run_main(command_line(command, source.path, out_dir, params), {})
        if status != 0 or escaped is not None:
            raise RuntimeError(f'{command} of the undamaged {source.path} failed: {stderr}') \
                from escaped
    shutil.rmtree(out_dir)


class _Worker:
    """A forked child running a list of cases; restarted after the case that killed it."""

    def __init__(self, cases, sources, directory, params, tmp):
        self.pending = list(cases)
        self.results: List[dict] = []
        self._args = (sources, directory, params)
        self._tmp = tmp
        self.pid = None
        self._start()

    def _start(self):
        self.started, self._buffer = None, b''
        self.last_event = time.monotonic()
        if not self.pending:
            self.pid = None
            return
        read_end, write_end = os.pipe()
        pid = os.fork()
        if pid == 0:   # pragma: no cover -- the child
            status = 0
            try:
                os.close(read_end)
                _child(self.pending, *self._args, write_end, self._tmp)
            except BaseException:   # noqa: B902 -- the child must never return into pytest
                traceback.print_exc()
                status = 3
            finally:
                os._exit(status)
        os.close(write_end)
        self.pid, self.fd = pid, read_end

    def read(self):
        """Take what the child wrote; at its end, account for it and start the next child."""
        data = os.read(self.fd, 1 << 16)
        self.last_event = time.monotonic()
        self._buffer += data
        *lines, self._buffer = self._buffer.split(b'\n')
        for line in lines:
            event = json.loads(line)
            if 'start' in event:
                self.started = self.pending[0]
            else:
                self.results.extend(event['results'])
                self.started = None
                self.pending.pop(0)
        if not data:
            self._ended(None)

    def stop(self):
        """Kill the child and reap it, without accounting for its case."""
        os.kill(self.pid, signal.SIGKILL)
        os.waitpid(self.pid, 0)
        os.close(self.fd)
        self.pid = None

    def kill(self, timeout_s):
        os.kill(self.pid, signal.SIGKILL)
        self._ended(f'no result within {timeout_s} s')

    def _ended(self, hang):
        os.close(self.fd)
        _, wait_status = os.waitpid(self.pid, 0)
        started = self.started
        if started is not None:
            self.results.extend(_broken(started, 'hang', hang) if hang else _broken(
                started, 'crash', f'the child ended with wait status {wait_status}'))
            shutil.rmtree(os.path.join(self._args[1], started.case_id), ignore_errors=True)
            self.pending.pop(0)
        elif self.pending:
            raise RuntimeError(f'the fuzz child failed outside a case (status {wait_status})')
        self._start()


def run_cases(cases: List[Case], sources: Dict[str, Source], directory: str, *,
              timeout_s: float = CASE_TIMEOUT_S, warm_up: bool = True,
              jobs: int = 2) -> List[dict]:
    """
    Run every case in ``jobs`` forked children, each allowed ``MEMORY_LIMIT`` more address space.

    A child that dies (a crash) or takes longer than ``timeout_s`` for one case
    (killed: a hang) costs that case; a new child goes on with the next.
    ``warm_up``: convert and plot an undamaged source here first. Returns the
    results in the order of ``cases``.
    """
    os.makedirs(directory, exist_ok=True)
    params = os.path.join(directory, 'params.yaml')
    with open(params, 'w') as stream:
        stream.write(PARAMS_YAML)
    if warm_up:
        _warm_up(sources, directory, params)
    workers: List[_Worker] = []
    try:
        for job in range(jobs):
            workers.append(_Worker(cases[job::jobs], sources, directory, params,
                                   os.path.join(directory, f'tmp{job}')))
        while True:
            running = {worker.fd: worker for worker in workers if worker.pid is not None}
            if not running:
                break
            wait = min(worker.last_event for worker in running.values()) + timeout_s
            ready, _, _ = select.select(list(running), [], [], max(0.0, wait - time.monotonic()))
            for fd in ready:
                running[fd].read()
            for worker in running.values():
                if worker.pid is not None and time.monotonic() - worker.last_event > timeout_s:
                    worker.kill(timeout_s)
    finally:   # interrupted (Ctrl-C): no child outlives the run
        for worker in workers:
            if worker.pid is not None:
                worker.stop()
    order = {case.case_id: index for index, case in enumerate(cases)}
    return sorted((result for worker in workers for result in worker.results),
                  key=lambda result: order[result['case']])


# --- The table ----------------------------------------------------------------------------------

def outcome_table(results: List[dict], command: str) -> str:
    """
    Return a markdown table of the runs of ``command``: format x damage by outcome.

    The last column, informational, counts the runs that ended with exit 0
    having read fewer messages than independent readers (:func:`oracle_counts`).
    """
    rows: Dict[Tuple[str, str], Dict[str, int]] = {}
    for result in results:
        if result['command'] != command:
            continue
        row = rows.setdefault((result['format'], result['damage_class']), {})
        row[result['klass']] = row.get(result['klass'], 0) + 1
    below: Dict[Tuple[str, str], int] = {}
    for result in results:
        if result['command'] == command and result.get('below_oracle'):
            key = (result['format'], result['damage_class'])
            below[key] = below.get(key, 0) + 1
    others = sorted({k for row in rows.values() for k in row} - set(COLUMNS))
    header = ['format', 'damage', 'cases', *COLUMNS, *others, '(exit 0, < independent readers)']
    body = [[fmt, damage, str(sum(row.values())), *(str(row.get(k, 0) or '') for k in COLUMNS),
             *(str(row.get(k, 0) or '') for k in others), str(below.get((fmt, damage), '') or '')]
            for (fmt, damage), row in sorted(rows.items())]
    totals = [sum(row.get(k, 0) for row in rows.values()) for k in (*COLUMNS, *others)]
    body.append(['**all**', '', str(sum(sum(row.values()) for row in rows.values())),
                 *map(str, totals), str(sum(below.values()))])
    return '\n'.join('| ' + ' | '.join(cells) + ' |'
                     for cells in [header, ['---'] * len(header), *body])


def below_oracle_summary(results: List[dict]) -> str:
    """One line per exit-0 run that read fewer messages than the independent readers did."""
    return '\n'.join(
        f'{r["case"]} [{r["command"]}] (seed {r["seed"]}; {r["mutation"]}): {r["klass"]}, '
        f'{r["detail"]}; independent readers read {r["oracle"]}'
        for r in results if r.get('below_oracle'))


def failures(results: List[dict]) -> List[dict]:
    """Return the runs whose outcome is not accepted."""
    return [result for result in results if result['klass'] not in ACCEPTED]


def failure_summary(results: List[dict], limit: int = 40) -> str:
    """One line per distinct failure (class, command, exception and place), with a first case."""
    seen: Dict[tuple, List[dict]] = {}
    for result in failures(results):
        detail = re.sub(r'\d{3,}', 'N', result['detail'].split(' at ')[-1]
                        if result['klass'] in ('traceback', 'memory') else result['klass'])
        key = (result['klass'], result['command'], result['format'],
               result['detail'].split(':')[0] if result['klass'] in ('traceback', 'memory')
               else '', detail)
        seen.setdefault(key, []).append(result)
    lines = []
    for (klass, command, fmt, _, _), group in sorted(seen.items())[:limit]:
        first = group[0]
        lines.append(f'{klass} x{len(group)} [{command}, {fmt}] e.g. {first["case"]} '
                     f'(seed {first["seed"]}; {first["mutation"]}): {first["detail"]}')
    return '\n'.join(lines)
