#!/usr/bin/env python3
"""
Cold start: the node's first and later starts, a 1-message convert, the library's imports.

Four measurements, each in fresh processes, repeated (``--rounds``) with the
trees compared interleaved round by round (``--tree`` several times: the
package of each tree is put first on ``PYTHONPATH``, e.g. ``--tree
/work/main --tree .`` for before and after):

1. **node, first start after installing**: ``rotation_node --ros-args -p
   input_type:=imu`` with an empty numba cache (``NUMBA_CACHE_DIR`` a new
   directory, as after ``colcon build``), a publisher of Imu messages on
   ``/input`` (every 20 ms) and a subscriber of ``/euler`` in this process:
   seconds from the launch to the node's first log line and to the first
   converted message;
2. **node, warm start**: the same with the cache the first start filled;
3. **``rotation_bag convert`` of a 1-message Imu bag** (warm cache): wall,
   CPU (user + system) and peak RSS of the process (``/usr/bin/time``), and
   in the same rounds the floor under it: ``python -c "import numpy"`` and
   ``python -c pass`` (ratios to the numpy floor are printed: they move less
   with the machine's load than the seconds do);
4. **library import + first calls vs scipy**: a new process imports
   ``rotation_node.conversions`` and calls a conversion for 5 shapes, against
   scipy's same calls (from before its first import to after its last call).

Every node start gets a ROS domain of its own (``ROS_DOMAIN_ID``) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; the node is stopped (SIGINT) once
it has converted a message. Medians and ranges (min-max) over the rounds are
printed, with the machine and its load (``_machine``) before and after.
``--only`` picks measurements (``--only convert`` for the tools' start-up alone).
Each tree's Python files are compiled to bytecode first (``compileall``), as
``pip install`` and ``colcon build`` leave them: a process never pays for
compiling the sources, even where ``PYTHONDONTWRITEBYTECODE`` is set.

Usage::

    python benchmarks/bench_cold_start.py [--rounds 3] [--tree DIR ...] [--skip-first-start]
        [--only node|convert|library ...] [--json results.json]
"""
import argparse
import json
import os
import platform
import queue
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

from _machine import cpu_model, load_line, print_machine, tree_environment

HERE = os.path.dirname(os.path.abspath(__file__))
VENV_BIN = os.path.dirname(sys.executable)
TARGET = 2.0
START_TIMEOUT_S = 900.0
PARAMS_FILE = os.path.join(HERE, os.pardir, 'config', 'params.yaml')

# conversion -> (package call, scipy call), both of a float64 array ``x`` of quaternions,
# rotation matrices or Euler angles as the conversion takes (``x`` is built by _PROGRAM).
CONVERSIONS = {
    'euler_from_quaternion': ('rc.euler_from_quaternion(x, "xyz")',
                              'Rotation.from_quat(x).as_euler("xyz")'),
    'matrix_from_quaternion': ('rc.matrix_from_quaternion(x)',
                               'Rotation.from_quat(x).as_matrix()'),
    'quaternion_from_matrix': ('rc.quaternion_from_matrix(x)',
                               'Rotation.from_matrix(x).as_quat()'),
    'quaternion_from_euler': ('rc.quaternion_from_euler(x, "ZYX")',
                              'Rotation.from_euler("ZYX", x).as_quat()'),
    'rotation_vector_from_quaternion': ('rc.rotation_vector_from_quaternion(x)',
                                        'Rotation.from_quat(x).as_rotvec()'),
}
_SAMPLE = {'euler_from_quaternion': 'q', 'matrix_from_quaternion': 'q',
           'quaternion_from_matrix': 'm', 'quaternion_from_euler': 'a',
           'rotation_vector_from_quaternion': 'q'}

_PROGRAM = """
import time
start = time.perf_counter()
import numpy as np
{import_line}
imported = time.perf_counter()
one = {{'q': [0.1, 0.2, 0.3, 0.9], 'a': [0.3, -0.2, 0.1],
        'm': [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]}}[{kind!r}]
one = np.array(one, dtype=float)
read_only = np.broadcast_to(one, (7,) + one.shape)
for x in (one, np.broadcast_to(one, (5,) + one.shape).copy(),
          np.broadcast_to(one, (5, 2) + one.shape).copy(), read_only,
          np.broadcast_to(one, (2000,) + one.shape).copy()):
    {call}
end = time.perf_counter()
print(imported - start, end - imported)
"""


def _summary(values, unit='', scale=1.0):
    values = [v * scale for v in values]
    if not values:
        return '-'
    return (f'{statistics.median(values):.2f}{unit} '
            f'[{min(values):.2f}-{max(values):.2f}]')


# ------------------------------------------------------------ the node

class _Traffic:
    """Imu messages published on /input every 20 ms; the first /euler message's arrival."""

    def __init__(self, domain):
        import rclpy
        from rclpy.node import Node
        from sensor_msgs.msg import Imu
        from geometry_msgs.msg import Vector3Stamped
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = Node('cold_start_bench', context=self.context)
        self.publisher = self.node.create_publisher(Imu, '/input', 10)
        self.first_output = None
        self.node.create_subscription(Vector3Stamped, '/euler', self._received, 10)
        self.message = Imu()
        self.message.orientation.w = 1.0
        from rclpy.executors import SingleThreadedExecutor
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.node.create_timer(0.02, lambda: self.publisher.publish(self.message))
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _received(self, _msg):
        if self.first_output is None:
            self.first_output = time.perf_counter()

    def _spin(self):
        while not self.stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def close(self):
        self.stop.set()
        self.thread.join()
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def node_start(tree, cache, domain):
    """Return (seconds to the first log line, seconds to the first converted message)."""
    env = tree_environment(tree, NUMBA_CACHE_DIR=cache, ROS_DOMAIN_ID=str(domain),
                           ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
    traffic = _Traffic(domain)
    lines = queue.SimpleQueue()
    start = time.perf_counter()
    process = subprocess.Popen(
        [os.path.join(VENV_BIN, 'rotation_node'), '--ros-args', '-p', 'input_type:=imu'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)

    def read():
        for line in process.stdout:
            lines.put((time.perf_counter(), line))

    threading.Thread(target=read, daemon=True).start()
    first_line = None
    output = []
    try:
        while time.perf_counter() - start < START_TIMEOUT_S:
            try:
                at, line = lines.get(timeout=0.05)
                output.append(line)
                first_line = at if first_line is None else first_line
            except queue.Empty:
                pass
            if first_line is not None and traffic.first_output is not None:
                break
            if process.poll() is not None and lines.empty():
                raise RuntimeError('the node stopped:\n' + ''.join(output))
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        traffic.close()
    if first_line is None or traffic.first_output is None:
        raise RuntimeError('no log line or no output within the timeout:\n' + ''.join(output))
    return first_line - start, traffic.first_output - start, output


# ------------------------------------------------------------ convert

def write_one_message_bag(path):
    """Write a rosbag2 MCAP bag of one sensor_msgs/Imu message on /imu."""
    from rclpy.serialization import serialize_message
    from rotation_node.bag.writing.writer import BagWriter
    from sensor_msgs.msg import Imu
    msg = Imu()
    msg.header.frame_id = 'imu_link'
    msg.header.stamp.sec = 1_700_000_000
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = (
        0.1, 0.2, 0.3, 0.9)
    with BagWriter(path, overwrite=True, compression='none') as writer:
        writer.write_serialized('/imu', 'sensor_msgs/msg/Imu', serialize_message(msg),
                                1_700_000_000_001_000_000)


def timed_process(command, env):
    """Return (wall s, CPU s, peak RSS MiB) of a process running ``command``."""
    start = time.perf_counter()
    result = subprocess.run(['/usr/bin/time', '-f', '%U %S %M', *command],
                            capture_output=True, text=True, env=env)
    wall = time.perf_counter() - start
    if result.returncode != 0:
        raise RuntimeError(result.stdout + result.stderr)
    user, system, kib = result.stderr.strip().splitlines()[-1].split()
    return wall, float(user) + float(system), int(kib) / 1024


def convert_one(tree, cache, source, output):
    """Return (wall s, CPU s, peak RSS MiB) of ``rotation_bag convert SOURCE OUTPUT``."""
    return timed_process([os.path.join(VENV_BIN, 'rotation_bag'), 'convert', source, output,
                          '--params', PARAMS_FILE, '--force'],
                         tree_environment(tree, NUMBA_CACHE_DIR=cache))


#: The floor under a tool's start: the interpreter, and the interpreter with numpy.
FLOORS = {'python_numpy': 'import numpy', 'python': 'pass'}


def floor_one(code):
    """Return (wall s, CPU s, peak RSS MiB) of ``python -c CODE``."""
    return timed_process([sys.executable, '-c', code], tree_environment())


# ------------------------------------------------------------ library vs scipy

def library_start(tree, cache, kind, import_line, call):
    code = _PROGRAM.format(import_line=import_line, kind=kind, call=call)
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True,
                         env=tree_environment(tree, NUMBA_CACHE_DIR=cache))
    import_time, calls_time = map(float, out.stdout.split())
    return import_time, calls_time


MEASUREMENTS = ('node', 'convert', 'library')


def compile_tree(tree):
    """Compile the package's Python files of ``tree`` (the installed one if None) to bytecode."""
    import compileall
    import importlib.util
    package = (os.path.join(tree, 'rotation_node') if tree is not None else
               os.path.dirname(importlib.util.find_spec('rotation_node').origin))
    compileall.compile_dir(package, quiet=1)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=3, help='rounds of each measurement')
    parser.add_argument('--tree', action='append',
                        help='a source tree to measure (repeatable; default: the installed one)')
    parser.add_argument('--skip-first-start', action='store_true',
                        help='no first start with an empty cache (minutes on a busy machine)')
    parser.add_argument('--only', action='append', choices=MEASUREMENTS,
                        help='only these measurements (repeatable; default: all)')
    parser.add_argument('--json', help='write the results to this file')
    args = parser.parse_args(argv)
    trees = args.tree or [None]
    measured = set(args.only or MEASUREMENTS)

    print_machine()
    import numba
    import scipy
    print(f'Python {platform.python_version()}, numba {numba.__version__}, '
          f'scipy {scipy.__version__}')
    work = tempfile.mkdtemp(prefix='cold_start_')
    results = {}
    try:
        warm_caches = {}
        for tree in trees:   # each tree's kernels compiled once, into a cache of its own
            compile_tree(tree)
            warm_caches[tree] = os.path.join(work, f'cache{len(warm_caches)}')
            if measured != {'convert'}:   # a 1-message convert loads no kernel
                subprocess.run([sys.executable, '-m', 'rotation_node.conversions.warm_up',
                                '--quiet'], check=True,
                               env=tree_environment(tree, NUMBA_CACHE_DIR=warm_caches[tree]))
        source = os.path.join(work, 'one.mcap')
        write_one_message_bag(source)
        rows = {tree: {'first_start_log': [], 'first_start_output': [], 'warm_start_log': [],
                       'warm_start_output': [], 'convert_wall': [], 'convert_cpu': [],
                       'convert_rss': []} for tree in trees}
        floors = {name: {'wall': [], 'cpu': [], 'rss': []} for name in FLOORS}
        domain = 100 + os.getpid() % 60
        for round_ in range(args.rounds):
            if 'convert' in measured:
                for name, code in FLOORS.items():
                    for key, value in zip(('wall', 'cpu', 'rss'), floor_one(code)):
                        floors[name][key].append(value)
            for tree in trees:
                row = rows[tree]
                if 'node' in measured and not args.skip_first_start:
                    empty = tempfile.mkdtemp(dir=work)
                    log, out, _ = node_start(tree, empty, domain + round_ % 40)
                    row['first_start_log'].append(log)
                    row['first_start_output'].append(out)
                    shutil.rmtree(empty, ignore_errors=True)
                if 'node' in measured:
                    log, out, _ = node_start(tree, warm_caches[tree], domain + round_ % 40)
                    row['warm_start_log'].append(log)
                    row['warm_start_output'].append(out)
                if 'convert' in measured:
                    wall, cpu, rss = convert_one(tree, warm_caches[tree], source,
                                                 os.path.join(work, 'out.mcap'))
                    row['convert_wall'].append(wall)
                    row['convert_cpu'].append(cpu)
                    row['convert_rss'].append(rss)
        print(f'\nseconds (median [min-max] of {args.rounds} rounds); node: launch to its first '
              'log line / to the first converted message')
        if 'convert' in measured:
            for name, code in FLOORS.items():
                floor = floors[name]
                print(f'  floor, python -c {code!r:14s} wall {_summary(floor["wall"], " s")}  CPU '
                      f'{_summary(floor["cpu"], " s")}  peak RSS '
                      f'{_summary(floor["rss"], " MiB")}')
            results['floors'] = floors
        numpy_floor = floors['python_numpy']
        for tree in trees:
            row = rows[tree]
            name = tree or 'installed'
            print(f'\n{name}:')
            if row['first_start_log']:
                print(f'  node first start, empty cache: log {_summary(row["first_start_log"])}'
                      f'  first output {_summary(row["first_start_output"])}')
            if row['warm_start_log']:
                print(f'  node warm start:               log {_summary(row["warm_start_log"])}'
                      f'  first output {_summary(row["warm_start_output"])}')
            if row['first_start_output']:
                ratio = [f / w for f, w in zip(row['first_start_output'],
                                               row['warm_start_output'])]
                print(f'  first / warm start (first output): {_summary(ratio, "x")}'
                      f'  (target <= {TARGET})')
            if row['convert_wall']:
                print(f'  convert, 1 message: wall {_summary(row["convert_wall"], " s")}  CPU '
                      f'{_summary(row["convert_cpu"], " s")}  peak RSS '
                      f'{_summary(row["convert_rss"], " MiB")}')
                # each round's convert over the same round's numpy floor
                for key in ('wall', 'cpu'):
                    ratio = [c / f for c, f in zip(row[f'convert_{key}'], numpy_floor[key])]
                    print(f'    / python -c "import numpy" ({key}): {_summary(ratio, "x")}')
            results[name] = row

        if 'library' in measured:
            library_rows(args, trees, warm_caches, results)
        print(load_line())
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if args.json:
        with open(args.json, 'w') as f:
            json.dump({'cpu': cpu_model(), 'load_average': os.getloadavg(),
                       'results': results}, f, indent=1)
    return 0


def library_rows(args, trees, warm_caches, results):
    """Print (and add to ``results``) the library's import + first calls against scipy's."""
    print('\nnew process: import (numpy included) + first calls with 5 shapes, seconds '
          f'(median of {args.rounds} rounds)')
    print(f'{"conversion":34s} {"tree":>12s} {"package":>17s} {"scipy":>17s} {"ratio":>6s}')
    for name, (ours, theirs) in CONVERSIONS.items():
        kind = _SAMPLE[name]
        for tree in trees:
            rounds = []
            for _ in range(args.rounds):
                rounds.append((
                    library_start(tree, warm_caches[tree], kind,
                                  'import rotation_node.conversions as rc', ours),
                    library_start(tree, warm_caches[tree], kind,
                                  'from scipy.spatial.transform import Rotation', theirs)))
            ours_import = statistics.median(r[0][0] for r in rounds)
            ours_calls = statistics.median(r[0][1] for r in rounds)
            scipy_import = statistics.median(r[1][0] for r in rounds)
            scipy_calls = statistics.median(r[1][1] for r in rounds)
            ratio = statistics.median(sum(r[0]) / sum(r[1]) for r in rounds)
            label = os.path.basename(os.path.abspath(tree)) if tree else 'installed'
            print(f'{name:34s} {label:>12s} {ours_import:8.3f} {ours_calls:8.3f} '
                  f'{scipy_import:8.3f} {scipy_calls:8.3f} {ratio:6.2f}')
            results.setdefault('library', {}).setdefault(name, {})[label] = {
                'package_import_s': ours_import, 'package_calls_s': ours_calls,
                'scipy_import_s': scipy_import, 'scipy_calls_s': scipy_calls,
                'ratio': ratio}


if __name__ == '__main__':
    sys.exit(main())
