"""
Writing bags and result files that survive crashes and appear whole.

``writer`` writes a bag the way rosbag2 does (``BagWriter``: a rosbag2
directory or one ``.mcap`` file, compression, a full disk), ``mcap_writer``
the MCAP chunks it is made of; ``part_output`` keeps a bag under an exclusive
``<output>.part`` until it is complete (a crash leaves it for recovery), and
``atomic_file`` writes other result files (JSON, CSV, PNG) through a hidden
temporary file renamed into place.
"""
