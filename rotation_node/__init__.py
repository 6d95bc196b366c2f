"""rotation_node: exact, fast rotation and angular-velocity conversions for ROS 2."""

__version__ = '0.1.0'
