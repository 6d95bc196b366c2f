"""
The main job: a simulated IMU replayed through a live ``rotation_node``, checked against truth.

1. Simulate a scene (default: the tumbling box, which flips about its
   intermediate axis) into an MCAP bag with ``rotation_scene``'s simulator.
2. Start ``rotation_node`` (Imu in, quaternion + Euler angles + angular
   velocity out) and ``rotation_bag record`` on its outputs, as processes.
3. ``rotation_bag play`` the sensor stream into the node; stop the recorder
   and the node with Ctrl-C (SIGINT), as a user would.
4. Convert the same bag offline with ``rotation_bag convert`` and the same
   parameters, and compare with what the live node published.
5. Print a summary (messages, orientation and rate error against the truth,
   near-singular samples) and write plots with ``rotation_bag plot``.

Usage: ``python -m rotation_dev.demo [--scene FILE] [--out DIR] [--seed N]`` from the
repository root (``./run.sh main`` runs it with the defaults).
"""
import argparse
import os
import signal
import subprocess
import sys
import time

import numpy as np
from rotation_dev.paths import config_path
from rotation_node import conversions as rc

OUTPUTS = ('quaternion', 'euler', 'angular_velocity')
SEQUENCE = 'xyz'
SINGULARITY_THRESHOLD = 0.01
DISCOVERY_SETTLE_S = 1.0


def _script(name):
    return os.path.join(os.path.dirname(sys.executable), name)


def _write_parameters(path):
    with open(path, 'w') as f:
        f.write('/**:\n  ros__parameters:\n    input_type: imu\n'
                f'    outputs: [{", ".join(OUTPUTS)}]\n'
                f'    euler:\n      sequence: {SEQUENCE}\n      unwrap: false\n'
                f'      singularity_threshold: {SINGULARITY_THRESHOLD}\n'
                '    qos:\n      reliability: reliable\n      depth: 1000\n')


def _stop(process, timeout=20):
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        return process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        return process.wait()


def _run_live(scene_bag, live_bag, params, topic, expected, log):
    """
    Node + recorder + player as processes; returns once the recorder has closed its bag.

    A watcher node in this process subscribes to the node's outputs too, so the
    recorder is stopped only once every expected message has gone through the
    node (or after a timeout), not after a guessed delay.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rotation_node import registry
    from rotation_node.wire.qos import recording_qos
    context = Context()
    rclpy.init(context=context)
    watcher = rclpy.create_node('rotation_demo_watcher', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(watcher)
    out_topics = [f'{topic}/{name}' for name in OUTPUTS]
    received = {t: 0 for t in out_topics}
    processes = []

    def start(args):
        processes.append(subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT))
        return processes[-1]

    def spin_until(condition, timeout, what):
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise RuntimeError(f'timed out after {timeout:.0f} s waiting for {what}')
            executor.spin_once(timeout_sec=0.05)

    def count(t):
        def callback(_):
            received[t] += 1
        return callback

    try:
        node = start([_script('rotation_node'), '--ros-args', '-r', f'__ns:={topic}',
                      '-r', f'input:={topic}', '--params-file', params])
        spin_until(lambda: all(watcher.count_publishers(t) for t in out_topics),
                   120, 'rotation_node to advertise its outputs')
        for t, name in zip(out_topics, OUTPUTS):
            offered = [i.qos_profile for i in watcher.get_publishers_info_by_topic(t)]
            watcher.create_subscription(registry.OUTPUTS[name].message_class, t, count(t),
                                        recording_qos(offered))
        recorder = start([_script('rotation_bag'), 'record', live_bag, '--force',
                          '--topics', *out_topics])
        spin_until(lambda: all(watcher.count_subscribers(t) >= 2 for t in out_topics),
                   60, 'the recorder to subscribe')
        player = start([_script('rotation_bag'), 'play', scene_bag, '--topics', topic,
                        '--wait-for-subscribers', '--delay', str(DISCOVERY_SETTLE_S)])
        spin_until(lambda: player.poll() is not None, 600, 'rotation_bag play')
        if player.returncode != 0:
            raise RuntimeError('rotation_bag play failed (see the log)')
        try:
            spin_until(lambda: min(received.values()) >= expected, 30, "the node's outputs")
        except RuntimeError:
            pass  # the summary reports what is missing
        executor.spin_once(timeout_sec=DISCOVERY_SETTLE_S)  # the recorder is as fast as we are
        log.write(f'demo watcher received {received} of {expected} each\n')
        log.flush()
        for process, name in ((recorder, 'rotation_bag record'), (node, 'rotation_node')):
            code = _stop(process)
            if code != 0:
                raise RuntimeError(f'{name} exited with code {code} on Ctrl-C (see the log)')
    finally:
        for process in processes:
            _stop(process)
        executor.shutdown()
        watcher.destroy_node()
        rclpy.try_shutdown(context=context)


def _read(bag, topics):
    """{topic: (stamps_ns, values)} of the converted outputs in a bag."""
    from rotation_node.bag.reading.mcap_reader import BagReader
    from rotation_node.wire.stamps import header_stamp_ns
    columns = {t: ([], []) for t in topics}
    for record in BagReader(bag).messages(topics=list(topics)):
        msg = record.message()
        stamps, values = columns[record.topic]
        stamps.append(header_stamp_ns(msg.header))
        if hasattr(msg, 'quaternion'):
            q = msg.quaternion
            values.append((q.x, q.y, q.z, q.w))
        else:
            values.append((msg.vector.x, msg.vector.y, msg.vector.z))
    return {t: (np.array(s, dtype=np.int64), np.array(v)) for t, (s, v) in columns.items()}


def _summary(sim, live, offline, topic):
    """Lines of the summary: counts, error against truth, live vs offline."""
    stamps = sim.stamp_ns
    published = int(sim.sensor.published.sum())
    index = {int(s): k for k, s in enumerate(stamps)}
    lines = [f'samples simulated: {len(stamps)}, Imu messages in the scene bag: {published}']
    for name in OUTPUTS:
        got = live[f'{topic}/{name}'][0]
        missing = sorted(set(range(len(stamps))) - {index[int(s)] for s in got})
        lines.append(f'{topic}/{name}: {len(got)} messages recorded live ('
                     + (f'{len(missing)} missing, samples {missing[0]}..{missing[-1]}'
                        if missing else 'none lost') + ')')
    q_stamps, q = live[f'{topic}/quaternion']
    rows = [index[int(s)] for s in q_stamps]
    error = rc.quaternion_distance(q, sim.truth_orientation[rows])
    lines.append(f'orientation error vs truth: max {error.max():.2e} rad, '
                 f'median {np.median(error):.2e} rad')
    w_stamps, w = live[f'{topic}/angular_velocity']
    w_error = np.linalg.norm(w - sim.truth_angular_velocity[[index[int(s)] for s in w_stamps]],
                             axis=-1)
    lines.append(f'angular velocity error vs truth: max {w_error.max():.2e} rad/s')
    margin = rc.euler_singularity_margin(sim.truth_orientation, SEQUENCE)
    lines.append(f'near gimbal lock ({SEQUENCE}, margin < {SINGULARITY_THRESHOLD} rad): '
                 f'{int((margin < SINGULARITY_THRESHOLD).sum())} samples, '
                 f'closest {margin.min():.2e} rad')
    for name in OUTPUTS:
        t = f'{topic}/{name}'
        common, live_rows, offline_rows = np.intersect1d(live[t][0], offline[t][0],
                                                         return_indices=True)
        difference = np.abs(live[t][1][live_rows] - offline[t][1][offline_rows]).max(initial=0.0)
        lines.append(f'{t}: live node vs offline convert on {len(common)} common stamps: '
                     + ('identical' if difference == 0 else f'max difference {difference:.2e}'))
    return lines


def main(argv=None):
    """Run the demonstration; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m rotation_dev.demo',
                                     description=__doc__.split('\n')[1])
    parser.add_argument('--scene', default=config_path('scenes', 'tumbling_box.yaml'),
                        help='scene file to simulate (default config/scenes/tumbling_box.yaml)')
    parser.add_argument('--out', default='out/demo', help='output directory (default out/demo)')
    parser.add_argument('--seed', type=int, default=0,
                        help="seed of the scene's random effects (default 0)")
    args = parser.parse_args(argv)

    from rotation_node.scene import load_scene, simulate, write_bag
    os.makedirs(args.out, exist_ok=True)
    paths = {name: os.path.join(args.out, name) for name in (
        'scene.mcap', 'live.mcap', 'converted.mcap', 'params.yaml', 'processes.log')}
    scene = load_scene(args.scene)
    print(f'1/5 simulating {args.scene} ({scene.duration:g} s at {scene.rate:g} Hz)')
    sim = simulate(scene, seed=args.seed)
    write_bag(sim, paths['scene.mcap'], overwrite=True)
    _write_parameters(paths['params.yaml'])

    print('2/5 replaying it through a live rotation_node, recording the outputs')
    with open(paths['processes.log'], 'w') as log:
        _run_live(paths['scene.mcap'], paths['live.mcap'], paths['params.yaml'], scene.topic,
                  int(sim.sensor.published.sum()), log)

    print('3/5 converting the same bag offline (rotation_bag convert)')
    subprocess.run([_script('rotation_bag'), 'convert', paths['scene.mcap'],
                    paths['converted.mcap'], '--params', paths['params.yaml'], '--force'],
                   check=True, stdout=subprocess.DEVNULL)

    print('4/5 plotting')
    plots = []
    for name in ('euler', 'angular_velocity'):
        png = os.path.join(args.out, f'{name}.png')
        subprocess.run([_script('rotation_bag'), 'plot', paths['live.mcap'],
                        '--topic', f'{scene.topic}/{name}', '-o', png, '--force',
                        '--params', paths['params.yaml']], check=True, stdout=subprocess.DEVNULL)
        plots.append(png)

    print('5/5 summary')
    topics = [f'{scene.topic}/{name}' for name in OUTPUTS]
    for line in _summary(sim, _read(paths['live.mcap'], topics),
                         _read(paths['converted.mcap'], topics), scene.topic):
        print('   ' + line)
    print(f'   plots: {", ".join(plots)}; bags and logs in {args.out}/')
    return 0


if __name__ == '__main__':
    sys.exit(main())
