"""
ROS 2 bags as MCAP files, written the way rosbag2 writes them.

``mcap_io`` reads and writes them (``BagReader``, ``BagWriter``); ``cdr``
encodes and decodes fixed-layout messages (Imu, the ``*Stamped`` types...)
without rclpy's message objects; ``record``, ``play``, ``convert`` and
``plot`` are the subcommands of the ``rotation_bag`` command line (``cli``).
"""
