"""
The ROS 2 wire format, shared by the node, the bag tools and the registry.

``cdr`` encodes and decodes fixed-layout messages (Imu, the ``*Stamped``
types...) without rclpy's message objects, one message or a block of them as
arrays, both from one layout per type; ``message_types`` looks message
classes, definitions and type hashes up by name; ``qos`` holds QoS profiles
as rosbag2 stores them (the ``offered_qos_profiles`` YAML); ``stamps``
converts time stamps between ``builtin_interfaces/Time``, integer nanoseconds
and text. Nothing here knows about bags or nodes.
"""
