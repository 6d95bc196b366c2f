"""
The compiled building blocks of :mod:`rotation_node.conversions`, for the package's other kernels.

An internal interface: :mod:`rotation_node.kinematics` (and the pipeline's chains) build
their kernels from these alone, in the library's conventions. The runtime's declarations,
argument types and views (:mod:`._runtime`; ``samples`` and ``matrix_samples`` are ndarray
views when interpreted, ``item_samples`` memoryviews of Python floats for kernels that
only index items), validation and statuses, the scalar formulas (tuples in, tuples out)
and ``canonical_kernel``. :data:`BATCH_SAMPLES`: from this size batch schedules may differ
from the single-sample path in the last bit.
"""
from ._axis_angle import (
    quaternion_from_rotation_vector_scalar, rotation_vector_from_quaternion_scalar)
from ._matrix import matrix_at, matrix_defect
from ._quaternion import (
    canonical_kernel, canonical_unit_quaternion, product, quaternion_status, scaled_quaternion,
    unit_quaternion, vector_status)
from ._runtime import (
    array_matrix_samples as matrix_samples, array_samples as samples, array_type, BATCH_SAMPLES,
    BOOL, call_binary, first_status, FLAT_IN, FLAT_OUT, FLOAT, INT, jit, kernel, ROWS_IN,
    ROWS_OUT, samples as item_samples, status)
from ._validation import float_array, kernel_ready, NON_FINITE, OK, raise_sample_error

__all__ = [
    'BATCH_SAMPLES', 'BOOL', 'FLAT_IN', 'FLAT_OUT', 'FLOAT', 'INT', 'NON_FINITE', 'OK',
    'ROWS_IN', 'ROWS_OUT', 'array_type', 'call_binary', 'canonical_kernel',
    'canonical_unit_quaternion', 'first_status', 'float_array', 'item_samples', 'jit', 'kernel',
    'kernel_ready', 'matrix_at', 'matrix_defect', 'matrix_samples', 'product',
    'quaternion_from_rotation_vector_scalar', 'quaternion_status', 'raise_sample_error',
    'rotation_vector_from_quaternion_scalar', 'samples', 'scaled_quaternion', 'status',
    'unit_quaternion', 'vector_status',
]
