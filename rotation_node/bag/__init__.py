"""
ROS 2 bags: reading every format, writing MCAP the way rosbag2 writes it.

``reader`` opens any input bag as one stream (``open_bag``: rosbag2
directories, MCAP and sqlite3 storage, split and compressed bags, ROS 1 bags
via ``ros1``, unfinished recordings), built on ``mcap_io`` (one MCAP file,
``BagReader``) and the ``rosbags`` package; ``writer`` writes bags
crash-safe (``BagWriter``: a rosbag2 directory or one ``.mcap`` file, via
``output``: exclusive ``.part``, atomic rename); ``topic_names``
maps topic names that are not valid in ROS 2; ``cdr`` encodes and decodes
fixed-layout messages (Imu, the ``*Stamped`` types...) without rclpy's message
objects; ``record``, ``play``, ``convert`` and ``plot`` are the subcommands of
the ``rotation_bag`` command line (``cli``); ``batch`` converts many bags in
parallel processes or on Dask.
"""
