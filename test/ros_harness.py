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

BIN = os.path.dirname(sys.executable)


def script(name):
    """Path of a console script installed in the test interpreter's environment."""
    return os.path.join(BIN, name)


class RosProcess:
    """A subprocess started with the ROS test environment; a context manager."""

    def __init__(self, args, env=None, cwd=None):
        self.args = [str(a) for a in args]
        environment = dict(os.environ)
        environment['PYTHONUNBUFFERED'] = '1'
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
