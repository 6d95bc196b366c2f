"""
ROS bags: ``reading`` every input format, ``writing`` crash-safe, both in ``records``' terms.

The ``rotation_bag`` commands (``cli``): ``record``, ``play``, ``convert`` (``block_convert``,
``block_codec``; ``batch``: many bags), ``plot``, ``export``, ``compare``.
"""
