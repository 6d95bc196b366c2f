"""
The compiled building blocks of :mod:`rotation_node.conversions`, for the package's other kernels.

An internal interface (not for users): :mod:`rotation_node.kinematics` builds
its kernels from these, and imports nothing else from the conversions' private
modules. Everything here follows the conventions of the library: quaternions
``(x, y, z, w)``, Hamilton product, ``R`` body to world.

Declaring and calling kernels (see :mod:`._runtime` for the canonical layout)
    :data:`jit` (the JIT policy of every compiled helper), :func:`kernel`
    (a kernel with its one signature) and its argument types
    (``FLAT_IN``, ``ROWS_IN``, ``FLAT_OUT``, ``ROWS_OUT``, ``INT``, ``FLOAT``,
    ``BOOL``, :func:`array_type`); :func:`samples` and :func:`matrix_samples`
    (views of the canonical layout: compiled, free; interpreted, ndarray views),
    :func:`item_samples` (interpreted, a memoryview of Python floats: for kernels
    that only index items),
    :func:`kernel_layout`;
    :func:`call_binary` (validation, broadcasting, output, threads, errors);
    :data:`BATCH_SAMPLES`, the size from which conversions with a batch schedule
    use it (its results may differ from the single-sample path in the last bit).

Validation and error reporting
    :func:`float_array`, :func:`kernel_ready`, :func:`raise_sample_error`, the statuses
    (:func:`status`, :func:`first_status`, :func:`quaternion_status`,
    :func:`vector_status`) and defect codes (``OK``, ``NON_FINITE``).

Kernels run interpreted until loaded (see :mod:`._runtime`): the same source,
the same results bit for bit.

Scalar formulas (compiled, inlined; tuples in, tuples out)
    :func:`product` (Hamilton), :func:`unit_quaternion`,
    :func:`canonical_unit_quaternion`, :func:`scaled_quaternion`,
    :func:`matrix_at`, :func:`matrix_defect`,
    :func:`quaternion_from_rotation_vector_scalar` (exponential map),
    :func:`rotation_vector_from_quaternion_scalar` (logarithm map).

Kernels
    :func:`canonical_kernel`: canonical unit quaternions of flat quaternions.
"""
from ._axis_angle import (
    quaternion_from_rotation_vector_scalar, rotation_vector_from_quaternion_scalar)
from ._matrix import matrix_at, matrix_defect
from ._quaternion import (
    canonical_kernel, canonical_unit_quaternion, product, quaternion_status, scaled_quaternion,
    unit_quaternion, vector_status)
# Interpreted, the kernels of kinematics index sub-views of their samples (``fm[s]``,
# ``.T``, ``.flat``): ndarray views (samples, matrix_samples). Kernels that only read and
# write items (the pipeline's chains) take item_samples: memoryviews of Python floats.
from ._runtime import (
    array_matrix_samples as matrix_samples, array_samples as samples, array_type, BATCH_SAMPLES,
    BOOL, call_binary, first_status, FLAT_IN, FLAT_OUT, FLOAT, INT, jit, kernel, kernel_layout,
    ROWS_IN, ROWS_OUT, samples as item_samples, status)
from ._validation import float_array, kernel_ready, NON_FINITE, OK, raise_sample_error

__all__ = [
    'BATCH_SAMPLES', 'BOOL', 'FLAT_IN', 'FLAT_OUT', 'FLOAT', 'INT', 'NON_FINITE', 'OK',
    'ROWS_IN', 'ROWS_OUT',
    'array_type', 'call_binary', 'canonical_kernel', 'canonical_unit_quaternion',
    'first_status', 'float_array', 'item_samples', 'jit', 'kernel', 'kernel_layout',
    'kernel_ready', 'matrix_at', 'matrix_defect', 'matrix_samples', 'product',
    'quaternion_from_rotation_vector_scalar',
    'quaternion_status', 'raise_sample_error', 'rotation_vector_from_quaternion_scalar',
    'samples', 'scaled_quaternion', 'status', 'unit_quaternion', 'vector_status',
]
