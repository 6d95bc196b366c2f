"""
:class:`SampleBlock`: the samples of one stream as arrays.

What :mod:`rotation_node.bag.block_codec` decodes and
:meth:`rotation_node.pipeline.ConversionPipeline.process_block` converts; numpy
only, so that both import it downward.
"""
from typing import NamedTuple, Optional

import numpy as np


class SampleBlock(NamedTuple):
    """Consecutive samples of one input stream, one row per message (``Sample`` as arrays)."""

    stamp_ns: np.ndarray            # int64 (n,): header stamps
    orientation: np.ndarray         # (n, 4) or (n, 3), the input type's form
    orientation_known: np.ndarray   # bool (n,): False where the message says unknown
    angular_velocity: Optional[np.ndarray] = None         # (n, 3); None: none or not read
    angular_velocity_known: Optional[np.ndarray] = None   # bool (n,)
