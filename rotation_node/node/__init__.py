"""
The ``rotation_node`` ROS 2 node (docs/ARCHITECTURE.md lists its modules).

Importing the package imports nothing: the program loads the node only once
it has said that it is starting.
"""
