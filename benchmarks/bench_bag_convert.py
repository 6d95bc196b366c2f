"""
Benchmark ``rotation_bag convert`` against the naive way and the floor, on sensor_msgs/Imu bags.

All produce the same bag: every input message plus ``/imu/euler``
(geometry_msgs/Vector3Stamped, extrinsic xyz = ROS roll, pitch, yaw, radians),
from the parameters file ``config/params.yaml`` (``input_type: imu``,
``outputs: [euler]``).

- ours: ``rotation_node.bag.convert.convert``: blocks of messages decoded into
  arrays, converted with one library call per conversion and encoded for the
  whole block (``rotation_node.bag.block_convert``), results identical to the
  live node's ``ConversionPipeline``;
- per message: the same with ``blocks=False``: the node's pipeline message by
  message on ``rotation_node.wire.cdr`` views (the path before blocks);
- naive: mcap-ros2-support decoding, ``scipy.spatial.transform.Rotation`` per
  message, mcap-ros2-support encoding (``read_ros2_messages`` + ``Writer``);
- floor: the ``mcap`` library alone reading the input (``iter_messages``, log-time
  order) and writing the same output messages (their bytes computed
  beforehand): no conversion, no decoding, no bag metadata; with the garbage
  collector set as ``convert`` sets it.

Printed, all measured in this run, as CPU time of this process (the machine
may be shared; wall time would measure the neighbours too):

1. throughput of all four on the same bag (default 200 000 messages), the
   ratios naive/ours (target >= 10x) and ours/floor (target <= 2x): the best of
   ``--repeat`` runs of each, alternating (on a shared machine the neighbours
   still slow all down; the best run is the one they disturbed least);
2. where the time of ours goes, stage by stage, on a 20 000-message sample;
3. time and peak memory of ours from 10^2 to 2*10^5 messages (10^6 with
   ``--million``), each size converted in a fresh process so that its peak RSS
   is its own; memory that does not grow with the bag length means streaming;
4. each input format (a rosbag2 mcap directory with zstd chunks, a rosbag2
   sqlite3 directory, ROS 1 bags uncompressed, bz2 and lz4, beside the MCAP
   file), the same messages:
   ours (``convert``, which reads them all) against a naive pipeline that
   reads them with rosbags (``AnyReader``, messages deserialised), converts
   with scipy and serialises with rosbags, and against the floor of that
   format (the raw messages read by the library that reads the format,
   written with ``mcap``), in the same run; and the peak memory of ours at
   two bag lengths, each in a fresh process.

5. whole commands as a user runs them, each in a fresh process (imports,
   start-up and all): ``rotation_bag convert`` against the competent user's
   script (:func:`convert_competent`: rosbags ``AnyReader``, scipy
   ``Rotation`` in blocks, rosbags ``Writer``, imports included), on a
   1-message bag and on 20 000 messages (a minute of IMU at 200-400 Hz) in
   each format (MCAP file, rosbag2 mcap, rosbag2 sqlite3, ROS 1 bags
   uncompressed, bz2, lz4), or on the bags given with ``--input``: wall
   time, CPU time and peak RSS of each
   process, and the wall-time ratio script/convert (target >= 2x); with
   ``--before PATH`` also the code checked out at PATH (e.g. ``git worktree
   add /tmp/before <commit>``), for before/after in one run. On a shared
   machine compare the CPU columns: wall time counts the neighbours' work.

The CPU model and numpy's SIMD level are printed first. ``--quick`` runs
everything on smaller bags, once (about a minute).

Run: ``.venv/bin/python benchmarks/bench_bag_convert.py [--quick] [--messages N] [--repeat R]
[--million] [--formats-only [--format NAME ...]] [--whole [--before PATH] [--input BAG ...]]``.
"""
import argparse
import gc
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

from _machine import print_machine, tree_environment
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
PARAMS_FILE = os.path.join(HERE, os.pardir, 'config', 'params.yaml')
TOPIC = '/imu'
PERIOD_NS = 10_000_000   # 100 Hz
T0_NS = 1_700_000_000_000_000_000
#: Messages of the whole-command comparison: a minute of IMU at 200-400 Hz.
WHOLE_MESSAGES = 20_000


def write_imu_bag(path, count, seed=0):
    """Return an Imu bag: random orientations and angular velocities at 100 Hz."""
    from rclpy.serialization import serialize_message
    from rotation_node.bag.writing.writer import BagWriter
    from sensor_msgs.msg import Imu
    rng = np.random.default_rng(seed)
    msg = Imu()
    msg.header.frame_id = 'imu_link'
    # Uncompressed, as every bag was before chunk compression existed: the ratio stays comparable.
    with BagWriter(path, overwrite=True, compression='none') as writer:
        for start in range(0, count, 10_000):
            n = min(10_000, count - start)
            quaternions = rng.normal(size=(n, 4))
            quaternions /= np.linalg.norm(quaternions, axis=1, keepdims=True)
            rates = rng.normal(scale=0.5, size=(n, 3))
            for i, (q, w) in enumerate(zip(quaternions.tolist(), rates.tolist())):
                stamp_ns = T0_NS + (start + i) * PERIOD_NS
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
                o, v = msg.orientation, msg.angular_velocity
                o.x, o.y, o.z, o.w = q
                v.x, v.y, v.z = w
                writer.write_serialized(TOPIC, 'sensor_msgs/msg/Imu', serialize_message(msg),
                                        stamp_ns + 1_000_000)


FORMATS = ('mcap file', 'rosbag2 mcap zstd', 'rosbag2 sqlite3', 'ROS 1 bag', 'ROS 1 bag bz2',
           'ROS 1 bag lz4')


def write_format_bag(directory, fmt, count, seed=0):
    """Return the Imu bag of ``write_imu_bag`` in format ``fmt`` (written by rosbags); its path."""
    from pathlib import Path

    from rosbags.rosbag1 import Writer as Ros1Writer
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import get_typestore, Stores
    from rotation_node.bag.reading.mcap_reader import BagReader
    name = fmt.replace(' ', '_')
    mcap_path = os.path.join(directory, f'{name}.mcap')
    write_imu_bag(mcap_path, count, seed)
    if fmt == 'mcap file':
        return mcap_path
    ros2 = get_typestore(Stores.ROS2_JAZZY)
    ros1_bag = fmt.startswith('ROS 1 bag')
    path = Path(directory, name + ('.bag' if ros1_bag else ''))
    with BagReader(mcap_path) as reader:
        records = reader.messages()
        if ros1_bag:
            ros1 = get_typestore(Stores.ROS1_NOETIC)
            writer = Ros1Writer(path)
            if fmt != 'ROS 1 bag':   # chunks compressed as rosbag record --bz2 / --lz4 does
                writer.set_compression(Ros1Writer.CompressionFormat[fmt.split()[-1].upper()])
            with writer:
                connection = writer.add_connection(TOPIC, 'sensor_msgs/msg/Imu', typestore=ros1)
                for record in records:
                    writer.write(connection, record.log_time_ns,
                                 ros2.cdr_to_ros1(record.data, 'sensor_msgs/msg/Imu'))
        else:
            writer = Writer(path, version=9, storage_plugin=(
                StoragePlugin.MCAP if 'mcap' in fmt else StoragePlugin.SQLITE3))
            if 'zstd' in fmt:
                writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            with writer:
                connection = writer.add_connection(TOPIC, 'sensor_msgs/msg/Imu', typestore=ros2)
                for record in records:
                    writer.write(connection, record.log_time_ns, record.data)
    os.unlink(mcap_path)
    return str(path)


def convert_naive_rosbags(source, output):
    """Return the same output with rosbags (read, deserialise, serialise) and scipy per message."""
    from pathlib import Path

    from mcap.writer import Writer
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    from rotation_node.wire.message_types import message_definition
    from scipy.spatial.transform import Rotation
    ros2 = get_typestore(Stores.ROS2_JAZZY)
    Vector3Stamped = ros2.types['geometry_msgs/msg/Vector3Stamped']
    Vector3 = ros2.types['geometry_msgs/msg/Vector3']
    with AnyReader([Path(source)]) as reader, open(output, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='naive')
        channels = {}
        for topic, type_name in ((TOPIC, 'sensor_msgs/msg/Imu'),
                                 (TOPIC + '/euler', 'geometry_msgs/msg/Vector3Stamped')):
            schema = writer.register_schema(type_name, 'ros2msg',
                                            message_definition(type_name).encode())
            channels[topic] = writer.register_channel(topic, 'cdr', schema)
        for connection, log_time, raw in reader.messages():
            imu = reader.deserialize(raw, connection.msgtype)
            data = raw if reader.is2 else ros2.ros1_to_cdr(raw, 'sensor_msgs/msg/Imu')
            writer.add_message(channels[TOPIC], log_time=log_time, data=bytes(data),
                               publish_time=log_time)
            q = imu.orientation
            roll, pitch, yaw = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_euler('xyz')
            header = ros2.types['std_msgs/msg/Header'](stamp=imu.header.stamp,
                                                       frame_id=imu.header.frame_id)
            euler = Vector3Stamped(header=header, vector=Vector3(x=roll, y=pitch, z=yaw))
            data = ros2.serialize_cdr(euler, 'geometry_msgs/msg/Vector3Stamped')
            writer.add_message(channels[TOPIC + '/euler'], log_time=log_time,
                               publish_time=log_time, data=bytes(data))
        writer.finish()


def convert_competent(source, output, block_messages=10_000):
    """
    Convert as a competent user would: rosbags ``AnyReader``, scipy in blocks, rosbags ``Writer``.

    Every message of the input is copied (ROS 1 ones as ROS 2 CDR) and each
    Imu message gets its ``/imu/euler`` (Vector3Stamped, its header), the
    angles computed by one scipy call per block of ``block_messages``;
    written as a rosbag2 directory with MCAP storage, as ``convert`` writes.
    """
    import itertools
    from pathlib import Path

    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_typestore, Stores
    from scipy.spatial.transform import Rotation
    typestore = get_typestore(Stores.ROS2_JAZZY)
    vector3 = typestore.types['geometry_msgs/msg/Vector3']
    vector3_stamped = typestore.types['geometry_msgs/msg/Vector3Stamped']
    euler_type = 'geometry_msgs/msg/Vector3Stamped'
    with AnyReader([Path(source)], default_typestore=typestore) as reader, \
            Writer(output, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        outputs = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=typestore)
                   for c in reader.connections}
        eulers = {c.id: writer.add_connection(c.topic + '/euler', euler_type,
                                              typestore=typestore)
                  for c in reader.connections if c.msgtype == 'sensor_msgs/msg/Imu'}
        messages = reader.messages()
        while block := list(itertools.islice(messages, block_messages)):
            # As ROS 2 CDR (ROS 1 messages converted), and the Imu messages deserialised.
            datas = [bytes(raw) if reader.is2 else bytes(typestore.ros1_to_cdr(raw, c.msgtype))
                     for c, _, raw in block]
            imus = {index: typestore.deserialize_cdr(data, 'sensor_msgs/msg/Imu')
                    for index, ((c, _, _), data) in enumerate(zip(block, datas))
                    if c.id in eulers}
            q = np.array([(m.orientation.x, m.orientation.y, m.orientation.z,
                           m.orientation.w) for m in imus.values()]).reshape(-1, 4)
            angles = Rotation.from_quat(q).as_euler('xyz').tolist() if len(q) else []
            angles = dict(zip(imus, angles))
            for index, ((connection, log_time, _), data) in enumerate(zip(block, datas)):
                writer.write(outputs[connection.id], log_time, data)
                if index in imus:
                    x, y, z = angles[index]
                    euler = vector3_stamped(header=imus[index].header,
                                            vector=vector3(x=x, y=y, z=z))
                    writer.write(eulers[connection.id], log_time,
                                 bytes(typestore.serialize_cdr(euler, euler_type)))


_CONVERT_COMMAND = ('import sys; from rotation_node.bag.cli import main; '
                    'sys.exit(main(sys.argv[1:]))')


#: Runs a command (posix_spawn) and prints its wall time, CPU time, peak RSS and exit status.
_MEASURE = """
import json, os, sys, time
start = time.perf_counter()
pid = os.posix_spawn(sys.argv[1], sys.argv[1:], os.environ,
                     file_actions=[(os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0)])
_, status, usage = os.wait4(pid, 0)
print(json.dumps([time.perf_counter() - start, usage.ru_utime + usage.ru_stime,
                  usage.ru_maxrss / 1024, os.waitstatus_to_exitcode(status)]))
"""


def _process_run(command, env=None, cwd=None):
    """
    Run ``command``; return ``(wall s, CPU s, peak RSS MiB)`` of its process.

    Started by a small launcher process: the peak RSS of a process started
    from this one would count this one's (Linux keeps the larger of the
    parent's and the new program's), numba and all. ``cwd``: where it runs
    (``python -c`` imports from there first: not from a checkout).
    """
    result = subprocess.run([sys.executable, '-c', _MEASURE, *command], env=env, cwd=cwd,
                            capture_output=True, text=True)
    if result.returncode:
        raise RuntimeError(f'{command}: the launcher failed: {result.stderr}')
    wall, cpu, rss, status = json.loads(result.stdout)
    if status:
        raise RuntimeError(f'{command} failed: {result.stderr}')
    return wall, cpu, rss


def _contender_commands(before):
    """``{name: (command(source, output), environment)}`` of the whole-process contenders."""
    here = os.path.join(HERE, os.pardir)
    contenders = {}
    if before:
        contenders['before'] = (lambda source, output: [
            sys.executable, '-c', _CONVERT_COMMAND, 'convert', source, output, '--params',
            PARAMS_FILE, '--force'], tree_environment(before))
    contenders['convert'] = (lambda source, output: [
        sys.executable, '-c', _CONVERT_COMMAND, 'convert', source, output, '--params',
        PARAMS_FILE, '--force'], tree_environment(here))
    contenders['script'] = (lambda source, output: [
        sys.executable, __file__, '--competent', source, output], None)
    return contenders


def whole_commands(directory, count, repeat, before=None, names=FORMATS, inputs=()):
    """
    Each format at ``count`` messages and a 1-message bag: each contender as a whole process.

    With ``inputs`` (paths of bags), those bags instead, as they are.

    ``convert`` (``rotation_bag convert IN OUT --params config/params.yaml``,
    imports and all), the same with the code at ``before`` (a checkout of an
    earlier commit, put first on PYTHONPATH), and the competent user's script
    (:func:`convert_competent`, in its own process, scipy and rosbags imports
    included); wall time, CPU time and peak RSS of the process, best of
    ``repeat`` alternating runs (the best run is the one the machine's other
    jobs disturbed least), and the ratio script/convert of the wall times.
    """
    contenders = _contender_commands(before)
    print(f'\n## Whole commands, fresh process each (best of {repeat}; wall s, CPU s, '
          'peak RSS MiB); script = rosbags AnyReader + scipy in blocks + rosbags Writer')
    columns = ' '.join(f'{name + " wall":>12s} {"CPU":>6s} {"RSS":>5s}' for name in contenders)
    ratios = f' {"script/convert":>15s}' + (f' {"before/convert":>15s}' if before else '')
    print(f'{"input":24s} {columns}{ratios}  load average (1 min) after the row')
    rows = [('1 message, mcap file', 'mcap file', 1)] + [
        (f'{count} msgs, {name}', name, count) for name in names]
    if inputs:
        rows = [(os.path.basename(path.rstrip(os.sep)), path, None) for path in inputs]
    for label, fmt, size in rows:
        source = fmt if size is None else write_format_bag(directory, fmt, size)
        outputs = {name: os.path.join(directory, f'whole_{name}') for name in contenders}
        for name, (command, env) in contenders.items():   # warm: numba caches, page cache
            _process_run(command(source, outputs[name]), env, directory)
            _remove(outputs[name])
        runs = {name: [] for name in contenders}
        for _ in range(repeat):
            for name, (command, env) in contenders.items():
                runs[name].append(_process_run(command(source, outputs[name]), env, directory))
                _remove(outputs[name])
        best = {name: tuple(min(run[i] for run in results) for i in range(3))
                for name, results in runs.items()}
        line = f'{label:24s} ' + ' '.join(f'{wall:12.2f} {cpu:6.2f} {rss:5.0f}'
                                          for wall, cpu, rss in best.values())
        line += f' {best["script"][0] / best["convert"][0]:14.2f}x'
        if before:
            line += f' {best["before"][0] / best["convert"][0]:14.2f}x'
        print(f'{line}  {os.getloadavg()[0]:.1f}', flush=True)
        if size is not None:
            _remove(source)


def formats(directory, count, repeat, sizes, names=FORMATS):
    """Each input format of ``names``: ours against the rosbags naive pipeline; memory."""
    print(f'\n## Input formats, {count} Imu messages -> + /imu/euler (best of {repeat}, CPU s)')
    print(f'{"format":20s} {"ours":>7s} {"us/msg":>7s} {"naive":>7s} {"us/msg":>7s} '
          f'{"floor":>7s} {"us/msg":>7s} {"naive/ours":>10s} {"ours/floor":>10s}')
    for fmt in names:
        source = write_format_bag(directory, fmt, count)
        convert_ours(source, os.path.join(directory, 'warm.mcap'))   # numba compilation
        euler_datas = output_datas(os.path.join(directory, 'warm.mcap'))
        floor = floor_mcap if fmt == 'mcap file' else floor_rosbags

        def floor_run(source, output):
            floor(source, output, euler_datas)

        runs = {'ours': [], 'naive': [], 'floor': []}
        for _ in range(repeat):
            for name, function in (('ours', convert_ours), ('naive', convert_naive_rosbags),
                                   ('floor', floor_run)):
                seconds, _ = _timed(function, source, os.path.join(directory, f'{name}.mcap'))
                runs[name].append(seconds)
        ours, naive, least = min(runs['ours']), min(runs['naive']), min(runs['floor'])
        print(f'{fmt:20s} {ours:7.2f} {ours / count * 1e6:7.1f} {naive:7.2f} '
              f'{naive / count * 1e6:7.1f} {least:7.2f} {least / count * 1e6:7.1f} '
              f'{naive / ours:9.2f}x {ours / least:9.2f}x')
        _remove(source)
    print('floor: mcap (MCAP file) or rosbags (the others) reading, mcap writing, no work '
          '(ROS 1: converted to CDR by rosbags)')
    print('\n## Input formats: peak memory growth of ours (fresh process each; MiB)')
    print(f'{"format":20s} ' + ' '.join(f'{f"{n} msgs":>16s}' for n in sizes))
    for fmt in names:
        growth = []
        for size in sizes:
            source = write_format_bag(directory, fmt, size, seed=3)
            stats = _run_child(source, os.path.join(directory, 'child_out.mcap'))
            growth.append(stats['peak_mib'] - stats['baseline_mib'])
            _remove(source)
        print(f'{fmt:20s} ' + ' '.join(f'{g:16.1f}' for g in growth))


def _remove(path):
    import shutil
    if os.path.isdir(path):
        shutil.rmtree(path)
    elif os.path.exists(path):
        os.unlink(path)


def convert_ours(source, output, blocks=True):
    """``rotation_bag convert SOURCE OUTPUT --params config/params.yaml --force``."""
    from rotation_node.bag.convert import convert
    from rotation_node.parameters import parameters_from_yaml
    convert(source, output, parameters_from_yaml(PARAMS_FILE), overwrite=True, blocks=blocks)


def convert_per_message(source, output):
    """``convert`` message by message (``blocks=False``): the path before blocks."""
    convert_ours(source, output, blocks=False)


def convert_naive(source, output):
    """Return the same output bag with mcap-ros2-support and scipy, message by message."""
    from mcap_ros2.reader import read_ros2_messages
    from mcap_ros2.writer import Writer
    from rotation_node.wire.message_types import message_definition
    from scipy.spatial.transform import Rotation
    with open(output, 'wb') as stream:
        writer = Writer(stream)
        imu_schema = writer.register_msgdef(
            'sensor_msgs/msg/Imu', message_definition('sensor_msgs/msg/Imu'))
        euler_schema = writer.register_msgdef(
            'geometry_msgs/msg/Vector3Stamped',
            message_definition('geometry_msgs/msg/Vector3Stamped'))
        for record in read_ros2_messages(source):
            imu = record.ros_msg
            writer.write_message(TOPIC, imu_schema, imu, record.log_time_ns,
                                 record.publish_time_ns)
            q = imu.orientation
            roll, pitch, yaw = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_euler('xyz')
            writer.write_message(
                TOPIC + '/euler', euler_schema,
                {'header': imu.header, 'vector': {'x': roll, 'y': pitch, 'z': yaw}},
                record.log_time_ns, record.publish_time_ns)
        writer.finish()


def output_datas(path):
    """Return the CDR data of the ``/imu/euler`` messages of a converted bag (for the floors)."""
    from rotation_node.bag.reading.mcap_reader import BagReader
    with BagReader(path) as reader:
        return [record.data for record in reader.messages([TOPIC + '/euler'])]


def _floor_writer(stream):
    """Return an ``mcap`` writer of the output's two channels, as the converters write them."""
    from mcap.writer import CompressionType, Writer

    from rotation_node.wire.message_types import message_definition
    writer = Writer(stream, compression=CompressionType.NONE)
    writer.start(profile='ros2', library='floor')
    channels = []
    for topic, type_name in ((TOPIC, 'sensor_msgs/msg/Imu'),
                             (TOPIC + '/euler', 'geometry_msgs/msg/Vector3Stamped')):
        schema = writer.register_schema(type_name, 'ros2msg',
                                        message_definition(type_name).encode())
        channels.append(writer.register_channel(topic, 'cdr', schema))
    return writer, channels


def floor_mcap(source, output, euler_datas):
    """Read the input with ``mcap`` (log-time order) and write the output's messages: no work."""
    from mcap.reader import make_reader

    from rotation_node.bag.block_convert import collections_deferred
    with collections_deferred(), open(source, 'rb') as stream, open(output, 'wb') as out:
        writer, (imu, euler) = _floor_writer(out)
        add, datas = writer.add_message, iter(euler_datas)
        for _, _, message in make_reader(stream).iter_messages():
            add(imu, message.log_time, message.data, message.publish_time)
            add(euler, message.log_time, next(datas), message.publish_time)
        writer.finish()


def floor_rosbags(source, output, euler_datas):
    """
    Read the raw messages with rosbags (any format) and write the output's with ``mcap``.

    A ROS 1 bag's messages are converted to CDR (``ros1_to_cdr``, as the naive
    pipeline does): the output holds ROS 2 messages.
    """
    from pathlib import Path

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from rotation_node.bag.block_convert import collections_deferred
    ros2 = get_typestore(Stores.ROS2_JAZZY)
    with collections_deferred(), AnyReader([Path(source)]) as reader, open(output, 'wb') as out:
        writer, (imu, euler) = _floor_writer(out)
        add, datas = writer.add_message, iter(euler_datas)
        for _, log_time, raw in reader.messages():
            data = raw if reader.is2 else ros2.ros1_to_cdr(raw, 'sensor_msgs/msg/Imu')
            add(imu, log_time, bytes(data), log_time)
            add(euler, log_time, next(datas), log_time)
        writer.finish()


def _timed(function, *args):
    """``(CPU seconds, result)`` of ``function(*args)``; CPU time ignores other jobs."""
    start = time.process_time()
    result = function(*args)
    return time.process_time() - start, result


def _same_messages(path, other):
    """Whether two bags hold the same messages (topic, bytes, times) in the same order."""
    from rotation_node.bag.reading.mcap_reader import BagReader
    with BagReader(path) as a, BagReader(other) as b:
        return all((x.topic, x.data, x.log_time_ns, x.publish_time_ns)
                   == (y.topic, y.data, y.log_time_ns, y.publish_time_ns)
                   for x, y in zip(a.messages(), b.messages(), strict=True))


def _euler_values(path):
    from rotation_node.bag.reading.mcap_reader import BagReader
    with BagReader(path) as reader:
        return np.array([(m.vector.x, m.vector.y, m.vector.z) for m in
                         (r.message() for r in reader.messages([TOPIC + '/euler']))])


def compare(directory, count, repeat):
    """Throughput of ours, per message, naive and floor on one bag, best of ``repeat`` each."""
    source = os.path.join(directory, 'imu.mcap')
    write_imu_bag(source, count)
    convert_ours(source, os.path.join(directory, 'warm.mcap'))   # numba compilation
    euler_datas = output_datas(os.path.join(directory, 'warm.mcap'))

    def floor(source, output):
        floor_mcap(source, output, euler_datas)

    contenders = (('ours', convert_ours), ('per msg', convert_per_message),
                  ('naive', convert_naive), ('floor', floor))
    runs = {name: [] for name, _ in contenders}
    for _ in range(repeat):
        for name, function in contenders:
            seconds, _ = _timed(function, source, os.path.join(directory, f'{name}.mcap'))
            runs[name].append(seconds)
    sample = min(count, 2000)
    difference = (_euler_values(os.path.join(directory, 'ours.mcap'))[:sample]
                  - _euler_values(os.path.join(directory, 'naive.mcap'))[:sample])
    difference = np.abs((difference + np.pi) % (2 * np.pi) - np.pi)   # modulo 2 pi
    print(f'\n## Throughput, {count} Imu messages -> + /imu/euler (best of {repeat})')
    print(f'{"":8s} {"CPU s":>9s} {"us/msg":>9s} {"msg/s":>10s}  every run, CPU s')
    for name, seconds in runs.items():
        best = min(seconds)
        print(f'{name:8s} {best:9.2f} {best / count * 1e6:9.1f} {count / best:10.0f}  '
              + ' '.join(f'{s:.2f}' for s in seconds))
    best = {name: min(seconds) for name, seconds in runs.items()}
    print(f'ratio naive/ours: {best["naive"] / best["ours"]:.2f}x (target >= 10x); '
          f'ours/floor: {best["ours"] / best["floor"]:.2f}x (target <= 2x); '
          f'per message/ours: {best["per msg"] / best["ours"]:.2f}x')
    same = _same_messages(os.path.join(directory, 'ours.mcap'),
                          os.path.join(directory, 'per msg.mcap'))
    print(f'ours and per message write the same messages, byte for byte: {same}')
    print(f'largest |ours - naive| Euler angle (mod 2 pi), first {sample} messages: '
          f'{difference.max():.1e} rad')


def breakdown(directory, count=20_000):
    """Microseconds per input message spent in each stage of ``convert``, and in rclpy's."""
    from rclpy.serialization import serialize_message
    from rotation_node import registry
    from rotation_node.bag.block_convert import BLOCK_MESSAGES
    from rotation_node.bag.block_codec import InputBlockDecoder, OutputBlockEncoder
    from rotation_node.bag.reading.mcap_reader import BagReader
    from rotation_node.bag.writing.writer import BagWriter
    from rotation_node.parameters import parameters_from_yaml
    from rotation_node.pipeline import ConversionPipeline

    source = os.path.join(directory, 'sample.mcap')
    write_imu_bag(source, count, seed=1)
    params = parameters_from_yaml(PARAMS_FILE)
    encoder = OutputBlockEncoder(registry.OUTPUTS['euler'].message)

    def write(records, encoded):
        with BagWriter(os.path.join(directory, 'sample_out.mcap'), overwrite=True,
                       compression='none') as writer:
            outputs = (data for block in encoded for data in block)
            # In blocks, as convert() writes: each input message, then its output.
            for start in range(0, len(records), BLOCK_MESSAGES):
                written = []
                for record in records[start:start + BLOCK_MESSAGES]:
                    written.append((TOPIC, record.type_name, record.data, record.log_time_ns,
                                    record.publish_time_ns))
                    written.append((TOPIC + '/euler', 'geometry_msgs/msg/Vector3Stamped',
                                    next(outputs), record.log_time_ns, record.publish_time_ns))
                writer.write_serialized_block(written)

    convert_ours(source, os.path.join(directory, 'sample_warm.mcap'))   # numba compilation
    total, _ = _timed(convert_ours, source, os.path.join(directory, 'sample_convert.mcap'))
    # Stage by stage, each over the whole sample held in lists, which convert()
    # never does: with the cyclic collector paused, so that its passes over
    # those lists are not charged to whichever stage triggers them.
    gc.disable()
    with BagReader(source) as reader:
        read, records = _timed(lambda: list(reader.messages()))
    blocks = [records[i:i + BLOCK_MESSAGES] for i in range(0, count, BLOCK_MESSAGES)]
    pipeline = ConversionPipeline(params)
    decoder = InputBlockDecoder(registry.INPUTS['imu'], pipeline.reads_angular_velocity)
    decode, decoded = _timed(lambda: [decoder.decode([r.data for r in b]) for b in blocks])
    process, outputs = _timed(lambda: [pipeline.process_block(sample) for sample, _ in decoded])
    encoding, encoded = _timed(lambda: [
        encoder.encode(headers, out.present['euler'], out.numbers['euler'])
        for (_, headers), out in zip(decoded, outputs)])
    written, _ = _timed(write, records, encoded)
    # What the block stages replace: rclpy messages through the per-message pipeline.
    deserialise, rclpy_messages = _timed(lambda: [r.message() for r in records])
    per_message = ConversionPipeline(params)
    rclpy_process, rclpy_outputs = _timed(lambda: [per_message.process(m)
                                                   for m in rclpy_messages])
    serialise, _ = _timed(
        lambda: [[serialize_message(out) for _, out in result] for result in rclpy_outputs])
    gc.enable()
    stages = [
        ('read (BagReader, log-time order)', read),
        (f'decode Imu blocks of {BLOCK_MESSAGES}', decode),
        ('ConversionPipeline.process_block', process),
        ('encode Vector3Stamped blocks', encoding),
        ('write input + output (BagWriter)', written),
    ]
    print(f'\n## Where the time goes ({count} messages, us per input message)')
    for name, seconds in stages:
        print(f'{name:36s} {seconds / count * 1e6:7.1f}  {seconds / total:5.0%}')
    print(f'{"sum of stages":36s} {sum(s for _, s in stages) / count * 1e6:7.1f}')
    print(f'{"convert() end to end":36s} {total / count * 1e6:7.1f}')
    print('instead with rclpy messages, one at a time (not used):')
    for name, seconds in (('deserialise Imu (rclpy)', deserialise),
                          ('ConversionPipeline.process', rclpy_process),
                          ('serialise Vector3Stamped (rclpy)', serialise)):
        print(f'{name:36s} {seconds / count * 1e6:7.1f}')


class RssSampler(threading.Thread):
    """Samples the resident set size every 10 ms while active; Linux (/proc) only."""

    def __init__(self):
        super().__init__(daemon=True)
        self._done = threading.Event()
        self.baseline_mib = self.peak_mib = self._rss_mib()

    @staticmethod
    def _rss_mib():
        with open('/proc/self/statm') as statm:
            return int(statm.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 2**20

    def run(self):
        while not self._done.wait(0.01):
            self.peak_mib = max(self.peak_mib, self._rss_mib())

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self._done.set()
        self.join()
        self.peak_mib = max(self.peak_mib, self._rss_mib())


def _child(source, output):
    """In a fresh process: convert once, print time and memory as JSON."""
    warm = output + '.warm.mcap'
    tiny = output + '.tiny.mcap'
    write_imu_bag(tiny, 10)
    convert_ours(tiny, warm)
    sampler = RssSampler()
    with sampler:
        seconds, _ = _timed(convert_ours, source, output)
    print(json.dumps({'seconds': seconds, 'baseline_mib': sampler.baseline_mib,
                      'peak_mib': sampler.peak_mib}))


def _run_child(source, output):
    result = subprocess.run([sys.executable, __file__, '--child', source, output],
                            check=True, capture_output=True, text=True)
    _remove(output)
    return json.loads(result.stdout.strip().splitlines()[-1])


def scaling(directory, sizes):
    """Time and peak memory of ``convert`` against the number of messages."""
    print('\n## Scaling (each size in a fresh process)')
    print(f'{"messages":>9s} {"CPU s":>9s} {"us/msg":>8s} {"RSS before MiB":>15s} '
          f'{"peak growth MiB":>16s}')
    for count in sizes:
        source = os.path.join(directory, f'scale_{count}.mcap')
        write_imu_bag(source, count, seed=2)
        stats = _run_child(source, source + '.out.mcap')
        print(f'{count:9d} {stats["seconds"]:9.2f} {stats["seconds"] / count * 1e6:8.1f} '
              f'{stats["baseline_mib"]:15.1f} {stats["peak_mib"] - stats["baseline_mib"]:16.1f}')
        os.unlink(source)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--messages', type=int, default=200_000)
    parser.add_argument('--repeat', type=int, default=3, help='runs of each in the comparison')
    parser.add_argument('--million', action='store_true', help='also scale to 10^6 messages')
    parser.add_argument('--formats-only', action='store_true',
                        help='only the input-format comparison (section 4)')
    parser.add_argument('--format', action='append', choices=FORMATS, dest='formats',
                        help='an input format of section 4 (repeatable; default all)')
    parser.add_argument('--quick', action='store_true',
                        help='20 000 messages, one run each, small scaling sizes (~1 min)')
    parser.add_argument('--whole', action='store_true',
                        help='only the whole-command comparison (section 5), at 20 000 '
                             'messages unless --messages says otherwise')
    parser.add_argument('--input', action='append', default=[], metavar='BAG',
                        help='section 5 on this bag (repeatable) instead of the generated ones; '
                             'its Imu topics converted, every topic copied')
    parser.add_argument('--before', metavar='PATH',
                        help='section 5 also runs the code checked out at PATH (e.g. '
                             '`git worktree add /tmp/before <commit>`) as "before"')
    parser.add_argument('--child', nargs=2, metavar=('SOURCE', 'OUTPUT'), help=argparse.SUPPRESS)
    parser.add_argument('--competent', nargs=2, metavar=('SOURCE', 'OUTPUT'),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(*args.child)
        return
    if args.competent:
        convert_competent(*args.competent)
        return
    sizes = [100, 1_000, 10_000, 100_000, 200_000] + ([1_000_000] if args.million else [])
    whole_messages = WHOLE_MESSAGES
    if args.whole and '--messages' in sys.argv:
        whole_messages = args.messages
    if args.quick:
        args.messages, args.repeat, sizes = min(args.messages, 20_000), 1, [1_000, 20_000]
    print_machine()
    with tempfile.TemporaryDirectory() as directory:
        if not (args.formats_only or args.whole):
            compare(directory, args.messages, args.repeat)
            breakdown(directory)
            scaling(directory, sizes)
        if not args.whole:
            formats(directory, args.messages, args.repeat, [args.messages // 10, args.messages],
                    args.formats or FORMATS)
        if not args.formats_only:
            whole_commands(directory, whole_messages, args.repeat, args.before,
                           args.formats or FORMATS, [os.path.abspath(p) for p in args.input])


if __name__ == '__main__':
    main()
