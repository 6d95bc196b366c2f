"""
Two orientation streams compared: errors, time alignment, time offset, mounting, world alignment.

Pure numpy + numba, built on :mod:`rotation_node.conversions` (its exact
product, conjugate, exponential and logarithm maps) and
:mod:`rotation_node.kinematics`; no rclpy import. Conventions as there:
quaternions ``(x, y, z, w)``, ``R`` body to world; and (``docs/compare.md``)::

    R_ref(t) = W R_est(t + dt) M

``W`` (world alignment) takes the estimate's world frame to the reference's,
``M`` (mounting) the reference body frame to the estimate's, ``dt`` (time
offset) is how much later the estimate stamps the same orientation. The error
of a matched pair is ``E = R_ref^T (W R_est M)``, its rotation vector about the
reference body axes (:func:`orientation_errors`).

Functions
    :func:`slerp`, :func:`interpolate_orientations` (at other stamps, with a gap
    tolerance), :func:`orientation_errors`, :func:`error_statistics`,
    :func:`estimate_time_offset` (angular rate magnitudes),
    :func:`estimate_alignment` (``W``, ``M``, ``dt`` by least squares on SO(3),
    with standard deviations), :func:`align_pairs` (``W``, ``M`` of matched
    pairs), :func:`aligned_series` (the matched pairs after
    alignment, and their errors).

Errors: :class:`~rotation_node.errors.ComparisonError` (bad arrays, no overlap),
:class:`~rotation_node.errors.DegenerateMotionError` (the motion does not
determine what was asked), both ``ValueError``.
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
