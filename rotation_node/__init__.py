"""
rotation_node: exact, fast rotation and angular-velocity conversions for ROS 2.

The numerical core lives in :mod:`rotation_node.conversions` (orientations) and
:mod:`rotation_node.kinematics` (angular velocity); neither imports rclpy.
"""

__version__ = '0.1.0'
