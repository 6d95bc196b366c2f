"""
Launch ``rotation_node`` on one input topic.

    ros2 launch rotation_node rotation_node.launch.py input_topic:=/imu/data \
        input_type:=imu params_file:=my_params.yaml namespace:=imu

Arguments (all optional):

- ``input_topic``: the topic the node reads (its ``input`` remapped), default ``/imu``;
- ``input_type``: the message type on it (the node's ``input_type`` parameter); empty
  (the default): as the parameters file says;
- ``params_file``: a parameters file, default the package's ``config/params.yaml``
  (every parameter at its default);
- ``namespace``: namespace of the node and of its outputs (``<namespace>/euler``, ...),
  default none.

A parameters file for a node in a namespace must name the node for any namespace,
``/**/rotation_node:`` (or ``/**:``): ``rotation_node:`` only matches ``/rotation_node``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

PACKAGE = 'rotation_node'


def _node(context):
    """Return the node action, its parameters and remappings from the launch arguments."""
    arguments = context.launch_configurations
    overrides = {'input_type': arguments['input_type']} if arguments['input_type'] else {}
    return [Node(package=PACKAGE, executable='rotation_node', name='rotation_node',
                 namespace=arguments['namespace'],
                 parameters=[arguments['params_file'], overrides],
                 remappings=[('input', arguments['input_topic'])],
                 output='screen')]


def generate_launch_description():
    """Return the launch description: the arguments above and the node."""
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        DeclareLaunchArgument('input_topic', default_value='/imu',
                              description='topic the node reads (its input remapped)'),
        DeclareLaunchArgument('input_type', default_value='',
                              description='message type on the input topic (input_type '
                                          'parameter); empty: as in the parameters file'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', 'params.yaml'),
                              description='parameters file of the node'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node and its outputs'),
        OpaqueFunction(function=_node),
    ])
