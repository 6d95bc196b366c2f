"""
Reading every bag a ROS user has, as one stream of :class:`~rotation_node.bag.records.BagMessage`.

``reader`` opens any input (``open_bag``: rosbag2 directories with MCAP or
sqlite3 storage, single ``.mcap`` files, split and compressed bags, ROS 1
bags, unfinished recordings); ``mcap_reader`` reads one MCAP file (every
layout; damage skipped and counted in a note, lengths checked before
reading); ``rosbag2_sqlite3`` the sqlite3 storage; ``ros1`` and
``ros1_chunks`` ROS 1 bags, one chunk group at a time; ``rosbags_input`` the
formats read through the ``rosbags`` package; ``compression`` rosbag2's
per-file and per-message compression; ``topic_names`` maps topic names that
are not valid in ROS 2.
"""
