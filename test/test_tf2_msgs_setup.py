"""
The set-up's tf2_msgs (``tools/build_tf2_msgs.sh``): importable, wire-compatible, usable over DDS.

tf2_msgs is not on PyPI; ``run.sh`` builds ``tf2_msgs/msg/TFMessage`` from its
message definition into the venv. These tests use it the way the node and the
bag tools do - in a new process with no ROS environment variables set - and
check its serialization against rosbags' independent CDR implementation of
ROS 2 Jazzy's ``tf2_msgs/msg/TFMessage``.
"""
import os
import subprocess
import sys

import pytest
from ros_harness import RosProcess, TestNode
from rosbags.typesys import get_typestore, Stores

# Starts processes or builds packages: not in the edit-test loop (-m "not slow").
pytestmark = pytest.mark.slow

#: Environment of a process started from a shell that knows nothing of ROS: the ROS
#: wheels' start-up hook (``ros_wheels_bootstrapper``) sets the library path afresh.
BARE_ENV = {name: value for name, value in os.environ.items()
            if name not in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH', 'LD_LIBRARY_PATH',
                            'PYTHONPATH', 'COLCON_PREFIX_PATH',
                            '_ROS_WHEELS_BOOTSTRAP_COMPLETE')}

#: (parent, child, sec, nanosec, translation, rotation (x, y, z, w)) of the test message.
TRANSFORMS = (
    ('map', 'odom', 12, 345, (1.0, -2.0, 0.5), (0.0, 0.0, 0.6, 0.8)),
    ('odom', 'base_link', 4294967, 999999999, (0.0, 1e-300, -7.25),
     (-0.5, 0.5, -0.5, 0.5)),
)

BUILD_MESSAGE = f"""
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage


def build():
    transforms = []
    for parent, child, sec, nanosec, translation, rotation in {TRANSFORMS!r}:
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = parent, child
        t.header.stamp.sec, t.header.stamp.nanosec = sec, nanosec
        v, q = t.transform.translation, t.transform.rotation
        v.x, v.y, v.z = translation
        q.x, q.y, q.z, q.w = rotation
        transforms.append(t)
    return TFMessage(transforms=transforms)
"""


def _fields(transforms):
    """Return the test tuple of each transform of a TFMessage (rclpy's or rosbags')."""
    return tuple(
        (t.header.frame_id, t.child_frame_id, t.header.stamp.sec, t.header.stamp.nanosec,
         (t.transform.translation.x, t.transform.translation.y, t.transform.translation.z),
         (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
          t.transform.rotation.w))
        for t in transforms)


def test_tf_message_of_a_new_process_and_rosbags_cdr_read_each_other():
    code = BUILD_MESSAGE + (
        'from rclpy.serialization import serialize_message\n'
        'print(serialize_message(build()).hex())\n')
    result = subprocess.run([sys.executable, '-c', code], env=BARE_ENV, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    data = bytes.fromhex(result.stdout.strip())

    typestore = get_typestore(Stores.ROS2_JAZZY)
    decoded = typestore.deserialize_cdr(data, 'tf2_msgs/msg/TFMessage')
    assert _fields(decoded.transforms) == TRANSFORMS

    from rclpy.serialization import deserialize_message
    from tf2_msgs.msg import TFMessage
    assert _fields(deserialize_message(data, TFMessage).transforms) == TRANSFORMS
    encoded = bytes(typestore.serialize_cdr(decoded, 'tf2_msgs/msg/TFMessage'))
    assert _fields(deserialize_message(encoded, TFMessage).transforms) == TRANSFORMS


def test_tf_message_published_by_another_process_arrives():
    code = BUILD_MESSAGE + (
        'import rclpy\n'
        'from rclpy.executors import ExternalShutdownException\n'
        'rclpy.init()\n'
        "node = rclpy.create_node('tf2_msgs_setup_publisher')\n"
        "publisher = node.create_publisher(TFMessage, 'tf2_msgs_setup_check', 10)\n"
        'node.create_timer(0.1, lambda: publisher.publish(build()))\n'
        'try:\n'
        '    rclpy.spin(node)\n'
        'except (KeyboardInterrupt, ExternalShutdownException):\n'
        '    pass\n'
        'rclpy.try_shutdown()\n')
    from tf2_msgs.msg import TFMessage
    with TestNode() as client, RosProcess([sys.executable, '-c', code]) as process:
        received = client.collect(TFMessage, 'tf2_msgs_setup_check')
        arrived = client.spin_until(lambda: received, timeout=60)
        code = process.stop()
        assert arrived, process.output
        assert code == 0, process.output
    assert _fields(received[0].transforms) == TRANSFORMS
