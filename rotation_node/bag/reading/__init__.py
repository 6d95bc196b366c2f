"""Every bag a ROS user has, read as one stream of ``BagMessage`` (``reader.open_bag``)."""
