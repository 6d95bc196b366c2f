"""
Launch ``rotation_node`` on ``/tf``: roll, pitch and yaw of one frame in another.

    ros2 launch rotation_node tf_euler.launch.py parent_frame:=map child_frame:=base_link

The node reads ``/tf`` and ``/tf_static`` (``input_type: tf``) and publishes the
orientation of ``child_frame`` in ``parent_frame`` as ROS roll, pitch, yaw on
``<namespace>/euler``, with the lookup semantics of tf2's
``lookupTransform(parent, child, Time(0))``.

Arguments (all optional):

- ``parent_frame``, ``child_frame``: the two frames (the ``tf.parent_frame`` and
  ``tf.child_frame`` parameters); empty (the default): as the parameters file says;
- ``params_file``: a parameters file, default the package's ``config/tf_euler.yaml``
  (``map`` and ``base_link``, Euler angles out);
- ``namespace``: namespace of the node and of its outputs, default none.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

PACKAGE = 'rotation_node'


def _node(context):
    """Return the node action, its parameters from the launch arguments."""
    arguments = context.launch_configurations
    overrides = {f'tf.{name}': arguments[name]
                 for name in ('parent_frame', 'child_frame') if arguments[name]}
    return [Node(package=PACKAGE, executable='rotation_node', name='rotation_node',
                 namespace=arguments['namespace'],
                 parameters=[arguments['params_file'], overrides],
                 output='screen')]


def generate_launch_description():
    """Return the launch description: the arguments above and the node."""
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        DeclareLaunchArgument('parent_frame', default_value='',
                              description='frame the orientation is expressed in '
                                          '(tf.parent_frame); empty: as in the parameters file'),
        DeclareLaunchArgument('child_frame', default_value='',
                              description='frame whose orientation is published '
                                          '(tf.child_frame); empty: as in the parameters file'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', 'tf_euler.yaml'),
                              description='parameters file of the node'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node and its outputs'),
        OpaqueFunction(function=_node),
    ])
