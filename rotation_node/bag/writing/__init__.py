"""
Bags and result files written crash-safe and appearing whole.

``writer`` (``BagWriter``) on ``mcap_writer``'s chunks and ``part_output``'s ``.part``;
``atomic_file`` for JSON, CSV and PNG outputs.
"""
