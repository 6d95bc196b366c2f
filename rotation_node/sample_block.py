"""
:class:`SampleBlock`: consecutive samples of one input stream as arrays.

The array form of :class:`rotation_node.registry.Sample`: what
:mod:`rotation_node.bag.block_codec` decodes a block of input messages into
and :meth:`rotation_node.pipeline.ConversionPipeline.process_block` converts.
numpy only, so that the codec and the pipeline both import it downward.
"""
from typing import NamedTuple, Optional

import numpy as np


class SampleBlock(NamedTuple):
    """
    Consecutive samples of one input stream, one row per message.

    Attributes
    ----------
    stamp_ns : ndarray of int64, shape (n,)
        Header stamps in integer nanoseconds.
    orientation : ndarray, shape (n, 4) or (n, 3)
        In the input type's form (rows where it is unknown are ignored).
    orientation_known : ndarray of bool, shape (n,)
        False where the message says the orientation is unknown.
    angular_velocity : ndarray, shape (n, 3), or None
        None when the input type carries none (or it is not read).
    angular_velocity_known : ndarray of bool, shape (n,), or None
        False where the message says its angular velocity is unknown.

    """

    stamp_ns: np.ndarray
    orientation: np.ndarray
    orientation_known: np.ndarray
    angular_velocity: Optional[np.ndarray] = None
    angular_velocity_known: Optional[np.ndarray] = None
