"""
Helpers for tests that talk to real processes over DDS.

``RosProcess`` starts one of the package's console scripts (or any command) in
a subprocess with the test session's ROS isolation environment, and stops it
with SIGINT as a user's Ctrl-C would. ``TestNode`` is an rclpy node in its own
context with helpers to wait for messages; it always shuts its context down.
"""
import os
import signal
import subprocess
import sys
import time

from rotation_node import registry

BIN = os.path.dirname(sys.executable)

PLAIN_INPUT_TYPES = tuple(name for name, entry in registry.INPUTS.items() if entry.stream is None)
"""Input types read one sample from each message on ``input`` (:func:`make_input_message`)."""


def script(name):
    """Path of a console script installed in the test interpreter's environment."""
    return os.path.join(BIN, name)


class RosProcess:
    """A subprocess started with the ROS test environment; a context manager."""

    def __init__(self, args, env=None, cwd=None):
        self.args = [str(a) for a in args]
        environment = dict(os.environ)
        environment['PYTHONUNBUFFERED'] = '1'
        environment['PYTHONFAULTHANDLER'] = '1'   # a crash prints where each thread was
        if env:
            environment.update(env)
        self.proc = subprocess.Popen(
            self.args, env=environment, cwd=cwd,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.output = None

    def alive(self):
        return self.proc.poll() is None

    def stop(self, timeout=15.0):
        """Send SIGINT (Ctrl-C), wait, return the exit code; output in ``self.output``."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            self.output, _ = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.output, _ = self.proc.communicate()
        return self.proc.returncode

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.output is None:
            self.stop()


class TestNode:
    """An rclpy node in a private context; ``with TestNode() as t: ...``."""

    __test__ = False  # not a pytest test class

    def __init__(self, name='test_client'):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def collect(self, msg_type, topic, qos=10):
        """Subscribe and return the list that received messages are appended to."""
        received = []
        self.node.create_subscription(msg_type, topic, received.append, qos)
        return received

    def spin_until(self, condition, timeout=20.0):
        """Spin until ``condition()`` is true; return whether it became true in time."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if condition():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return condition()

    def spin_for(self, seconds):
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    def wait_for_subscriber(self, publisher, timeout=20.0):
        return self.spin_until(lambda: publisher.get_subscription_count() > 0, timeout)

    def close(self):
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# Orientation covariance written into the inputs that carry one (rad^2, row-major):
# standard deviations about 1e-3 rad, correlated.
INPUT_COVARIANCE = (1.0e-6, 0.3e-6, -0.2e-6,
                    0.3e-6, 2.0e-6, 0.1e-6,
                    -0.2e-6, 0.1e-6, 1.5e-6)


def make_input_message(input_type, rotation, *, omega=(0.0, 0.0, 0.0), stamp_ns=0,
                       frame_id='', sequence='xyz', degrees=False, covariance=INPUT_COVARIANCE):
    """
    Return an input message of the node's ``input_type`` holding ``rotation``.

    ``rotation`` is a scipy ``Rotation`` (the tests' oracle); ``omega`` goes into
    the angular-velocity field of the types that carry one; ``sequence`` and
    ``degrees`` give the Euler convention of an Euler-angle input; ``covariance``
    (9 numbers, row-major) goes into the orientation covariance block of the
    types that carry one. The fields written are those the input type's entry
    in rotation_node.registry names.
    """
    import operator
    from rotation_node import registry
    from rotation_node.wire.stamps import split_ns
    entry = registry.INPUTS[input_type]
    msg = entry.message_class()
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(stamp_ns)
    msg.header.frame_id = frame_id
    target = operator.attrgetter(entry.orientation_field)(msg)
    if entry.orientation_form == registry.QUATERNION:
        target.x, target.y, target.z, target.w = (float(v) for v in rotation.as_quat())
    else:
        values = (rotation.as_euler(sequence, degrees=degrees)
                  if entry.orientation_form == registry.EULER else rotation.as_rotvec())
        target.x, target.y, target.z = (float(v) for v in values)
    if entry.angular_velocity_field is not None:
        w = operator.attrgetter(entry.angular_velocity_field)(msg)
        w.x, w.y, w.z = (float(v) for v in omega)
    if entry.covariance_field is not None:
        block = operator.attrgetter(entry.covariance_field)(msg)
        for index, value in zip(entry.covariance_indices, covariance):
            block[index] = float(value)
    return msg


def oracle_output(name, rotation, omega_body=(0.0, 0.0, 0.0), *, sequence='xyz',
                  degrees=False, frame='body', covariance=INPUT_COVARIANCE,
                  covariance_frame='fixed'):
    """
    Return the expected values of the node output ``name``, computed independently with scipy.

    ``rotation`` (scipy ``Rotation``) turns at the constant body rate
    ``omega_body``; rates are central differences of scipy's conversions. The
    Euler covariance is ``J Sigma J^T`` with ``J`` the central differences of
    scipy's Euler angles w.r.t. a rotation vector about the fixed or body axes.
    Returns a flat array laid out as :func:`output_values` reads the message.
    """
    import numpy as np
    from scipy.spatial.transform import Rotation
    omega_body = np.asarray(omega_body, dtype=float)
    q = rotation.as_quat(canonical=True)
    h = 1e-6

    def moved(t):
        return rotation * Rotation.from_rotvec(omega_body * t)

    if name == 'quaternion':
        return q
    if name == 'euler':
        return rotation.as_euler(sequence, degrees=degrees)
    if name == 'rotation_vector':
        return rotation.as_rotvec()
    if name == 'axis_angle':
        v = rotation.as_rotvec()
        angle = np.linalg.norm(v)
        return np.array([1.0, 0.0, 0.0, 0.0]) if angle == 0 else np.append(v / angle, angle)
    if name == 'matrix':
        return rotation.as_matrix().ravel()
    if name == 'angular_velocity':
        return omega_body if frame == 'body' else rotation.apply(omega_body)
    if name == 'euler_rates':
        step = moved(h).as_euler(sequence) - moved(-h).as_euler(sequence)
        rates = (np.remainder(step + np.pi, 2 * np.pi) - np.pi) / (2 * h)
        return np.degrees(rates) if degrees else rates
    if name in ('euler_stddev', 'euler_covariance'):
        steps = Rotation.from_rotvec(h * np.vstack([np.eye(3), -np.eye(3)]))
        moved = steps * rotation if covariance_frame == 'fixed' else rotation * steps
        angles = moved.as_euler(sequence)
        jacobian = (np.remainder(angles[:3] - angles[3:] + np.pi, 2 * np.pi) - np.pi).T / (2 * h)
        euler_cov = jacobian @ np.reshape(covariance, (3, 3)) @ jacobian.T
        if degrees:
            euler_cov = euler_cov * (180 / np.pi) ** 2
        if name == 'euler_stddev':
            return np.sqrt(np.diagonal(euler_cov))
        return np.concatenate([rotation.as_euler(sequence, degrees=degrees), euler_cov.ravel()])
    if name == 'quaternion_rate':
        ahead, behind = moved(h).as_quat(), moved(-h).as_quat()
        ahead, behind = (p if np.dot(p, q) > 0 else -p for p in (ahead, behind))
        return (ahead - behind) / (2 * h)
    raise ValueError(f'unknown output {name!r}')


def output_values(msg):
    """Return the numbers of an output message as a flat array (as its output builds it)."""
    import numpy as np
    from rotation_node import registry
    from rotation_node.wire.message_types import type_name_of
    numbers = {o.type_name: o.message.numbers for o in registry.OUTPUTS.values()}
    return np.array(numbers[type_name_of(type(msg))](msg), dtype=float)
