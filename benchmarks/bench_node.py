#!/usr/bin/env python3
"""
CPU cost of the rotation_node per message, against a bare rclpy relay.

One publisher (this process, no executor) sends sensor_msgs/Imu at a fixed rate
on ``/input``, reliable, keep last the node's default ``qos.depth``. Two
subscriber processes take every message with the same QoS (what the node's
``qos.reliability: auto`` adapts to for that publisher) and the same executor
(``rclpy.spin``, single-threaded): the ``rotation_node`` on its default
parameters (``outputs: [euler]`` unless ``--outputs`` says otherwise) and a
bare relay node that republishes each message unchanged, as rclpy gives it (a
Python message object). Each process's CPU time (user + system, from
/proc/<pid>/stat) is read around every round; the script prints the CPU model,
the CPU time per message of both, their ratio per round and the median ratio
(target: <= 1.0), and checks that no message was lost (node: its /diagnostics
counters ``received`` and ``lost``; relay: its own count).

``--calibrate`` replaces the node with a second relay: the ratio of two identical
processes shows the noise of the measurement on this machine.

Usage::

    python benchmarks/bench_node.py [--count 4000] [--rounds 5] [--rate 1000]
                                    [--depth N] [--outputs euler ...] [--calibrate]

``--depth`` sets ``qos.depth`` of the node and the depth of the publisher and
relay (default: the node's default). To measure another version of the node
against the same relay, put its source first on ``PYTHONPATH``.
"""
import argparse
import os
import signal
import statistics
import subprocess
import sys
import time

from _machine import print_machine


def relay_main(name, depth):
    """Bare relay: the node's subscription QoS and executor, no conversion; prints its count."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from sensor_msgs.msg import Imu

    rclpy.init()
    node = Node(name)
    qos = qos_profile(depth)
    publisher = node.create_publisher(Imu, f'/{name}/output', qos)
    relayed = 0

    def relay(msg):
        nonlocal relayed
        publisher.publish(msg)
        relayed += 1
    node.create_subscription(Imu, '/input', relay, qos)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        print(relayed, flush=True)


def qos_profile(depth):
    """Return the node's QoS for ``qos.depth: depth`` and a reliable publisher (keep last)."""
    from rotation_node.wire.qos import qos_profile as node_qos_profile
    from rotation_node.parameters import NodeParameters
    return node_qos_profile(NodeParameters(qos_depth=depth, qos_reliability='reliable'))


def default_depth():
    """Return the node's default ``qos.depth``."""
    from rotation_node.parameters import NodeParameters
    return NodeParameters().qos_depth


def cpu_seconds(pid):
    """User + system CPU time of a process, from /proc/<pid>/stat."""
    with open(f'/proc/{pid}/stat') as stat:
        fields = stat.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def imu_messages(count, rate):
    """Imu messages of a body tumbling at a constant rate, stamped at ``rate`` Hz."""
    import numpy as np
    from scipy.spatial.transform import Rotation
    from sensor_msgs.msg import Imu

    omega = np.array([0.7, -0.4, 1.3])
    t = np.arange(count) / rate
    quaternions = (Rotation.from_euler('xyz', [0.2, -0.1, 0.5])
                   * Rotation.from_rotvec(np.outer(t, omega))).as_quat()
    messages = []
    for k, q in enumerate(quaternions):
        msg = Imu()
        msg.header.frame_id = 'imu_link'
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(
            1_700_000_000_000_000_000 + round(t[k] * 1e9), 1_000_000_000)
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = q.tolist()
        msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = omega.tolist()
        messages.append(msg)
    return messages


def publish_paced(publisher, messages, rate):
    """Publish at ``rate`` Hz on an absolute schedule (no drift), without spinning."""
    start = time.monotonic()
    for k, msg in enumerate(messages):
        delay = start + k / rate - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        publisher.publish(msg)


def spin_for(node, seconds):
    import rclpy
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)


def run(args):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node
    from sensor_msgs.msg import Imu

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    print_machine()
    depth_args = [] if args.depth is None else ['-p', f'qos.depth:={args.depth}']
    args.depth = default_depth() if args.depth is None else args.depth
    outputs = '[' + ','.join(args.outputs) + ']'
    subject = 'relay_b' if args.calibrate else 'rotation_node'
    relay_command = [sys.executable, os.path.abspath(__file__), '--relay']
    if args.calibrate:
        subject_command = relay_command + ['relay_b', str(args.depth)]
    else:
        subject_command = [
            os.path.join(os.path.dirname(sys.executable), 'rotation_node'), '--ros-args',
            '-p', 'input_type:=imu', '-p', f'outputs:={outputs}', *depth_args]
    processes = {
        subject: subprocess.Popen(subject_command, stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True),
        'relay': subprocess.Popen(relay_command + ['relay', str(args.depth)],
                                  stdout=subprocess.PIPE, text=True),
    }
    rclpy.init()
    bench = Node('bench_node_publisher')
    node_counts = {}

    def read_counts(array):
        for status in array.status:
            if status.name.startswith('/rotation_node:'):
                node_counts.update({kv.key: kv.value for kv in status.values})
    bench.create_subscription(DiagnosticArray, '/diagnostics', read_counts, 10)
    publisher = bench.create_publisher(Imu, '/input', qos_profile(args.depth))
    messages = imu_messages(args.count, args.rate)
    total = args.rounds * args.count
    rounds = []
    try:
        deadline = time.monotonic() + 60.0
        while publisher.get_subscription_count() < 2:
            rclpy.spin_once(bench, timeout_sec=0.05)
            assert time.monotonic() < deadline, 'node or relay did not start'
        spin_for(bench, 2.0)   # both readers have matched the publisher too by now
        for _ in range(args.rounds):
            cpu = {name: cpu_seconds(p.pid) for name, p in processes.items()}
            publish_paced(publisher, messages, args.rate)
            time.sleep(1.0)   # both subscribers idle again: the tail adds ~no CPU time
            rounds.append({name: (cpu_seconds(p.pid) - cpu[name]) / args.count * 1e6
                           for name, p in processes.items()})
        deadline = time.monotonic() + 5.0
        while (not args.calibrate and int(node_counts.get('received', 0)) < total
               and time.monotonic() < deadline):
            rclpy.spin_once(bench, timeout_sec=0.1)
    finally:
        bench.destroy_node()
        rclpy.try_shutdown()
        for process in processes.values():
            process.send_signal(signal.SIGINT)
        printed = {name: p.communicate(timeout=15)[0] for name, p in processes.items()}

    print(f'{args.rounds} x {args.count} Imu messages at {args.rate:g} Hz, reliable QoS '
          f'depth {args.depth}' + ('' if args.calibrate else f', outputs {outputs}, '
                                   f'node input QoS {node_counts.get("input_qos")!r}')
          + '; CPU time per message:')
    ratios = []
    for k, per_message in enumerate(rounds):
        ratios.append(per_message[subject] / per_message['relay'])
        print(f'  round {k + 1}: {subject} {per_message[subject]:6.1f} us, '
              f'relay {per_message["relay"]:6.1f} us, ratio {ratios[-1]:.3f}')
    handled = {'relay': int(printed['relay'].split()[-1])}
    if args.calibrate:
        handled[subject] = int(printed[subject].split()[-1])
    else:
        handled['rotation_node'] = int(node_counts.get('received', 0))
        handled['rotation_node outputs'] = int(node_counts.get('published', 0)) // len(
            args.outputs)
        print(f'  node /diagnostics: lost {node_counts.get("lost")}, '
              f'duplicates {node_counts.get("duplicates")}')
    lost = {name: total - n for name, n in handled.items() if n != total}
    print(f'  messages handled (of {total}): {handled}'
          + (f'  LOST: {lost}' if lost else '  none lost'))
    print(f'  median ratio {subject} / relay = {statistics.median(ratios):.3f} '
          f'(spread {min(ratios):.3f} to {max(ratios):.3f}; target <= 1.0)')
    return 1 if lost else 0


def main():
    if len(sys.argv) == 4 and sys.argv[1] == '--relay':
        return relay_main(sys.argv[2], int(sys.argv[3]))
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--count', type=int, default=4000, help='messages per round')
    parser.add_argument('--rounds', type=int, default=5, help='timed rounds (median ratio)')
    parser.add_argument('--rate', type=float, default=1000.0, help='publish rate (Hz)')
    parser.add_argument('--depth', type=int, default=None,
                        help="QoS history depth (default: the node's default qos.depth)")
    parser.add_argument('--outputs', nargs='+', default=['euler'], help='node outputs')
    parser.add_argument('--calibrate', action='store_true',
                        help='compare two identical relays (noise of the measurement)')
    return run(parser.parse_args())


if __name__ == '__main__':
    sys.exit(main())
