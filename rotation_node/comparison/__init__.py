"""
Two orientation streams compared: errors, time offset, mounting, world alignment.

Pure numpy, built on the exact kernels of :mod:`rotation_node.conversions` and on
:mod:`rotation_node.kinematics`; quaternions ``(x, y, z, w)``, ``R`` body to world, and
(``docs/compare.md``) ``R_ref(t) = W R_est(t + dt) M``: ``W`` takes the estimate's world frame
to the reference's, ``M`` the reference body frame to the estimate's, ``dt`` is how much later
the estimate stamps the same orientation. A matched pair's error is
``E = R_ref^T (W R_est M)``, as a rotation vector about the reference body axes.
Errors: :class:`~rotation_node.errors.ComparisonError` (bad arrays, no overlap) and its
:class:`~rotation_node.errors.DegenerateMotionError` (the motion does not determine what was
asked), both ``ValueError``.
"""
from ._alignment import (align_pairs, aligned_series, AlignedSeries, Alignment, chordal_mean,
                         estimate_alignment, IDENTITY, kabsch)
from ._series import (error_statistics, ErrorStatistics, interpolate_orientations,
                      orientation_errors)
from ._time_offset import estimate_time_offset, TimeOffset
from ..errors import ComparisonError, DegenerateMotionError
from ..kinematics import slerp  # the one slerp, shared with tf_buffer

__all__ = [
    'AlignedSeries', 'Alignment', 'ComparisonError', 'DegenerateMotionError', 'ErrorStatistics',
    'IDENTITY', 'TimeOffset', 'align_pairs', 'aligned_series', 'chordal_mean', 'error_statistics',
    'estimate_alignment', 'estimate_time_offset', 'interpolate_orientations', 'kabsch',
    'orientation_errors', 'slerp',
]
