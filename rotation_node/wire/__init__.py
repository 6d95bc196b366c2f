"""The ROS 2 wire format: CDR, message types, QoS as rosbag2 stores it, stamps."""
