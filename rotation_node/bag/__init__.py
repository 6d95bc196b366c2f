"""
ROS bags: the ``rotation_bag`` commands, on top of reading and writing.

``reading`` opens every input format as one stream and ``writing`` writes
bags crash-safe, both in terms of ``records`` (``TopicMetadata``,
``BagMessage``) and, for MCAP, ``mcap_layout``. The commands of
``rotation_bag`` (``cli``) are ``record``, ``play``, ``convert`` (with
``block_convert`` and ``block_codec`` converting in blocks, and ``batch`` for
many bags), ``plot``, ``export`` and
``compare``.
"""
