"""
Orientation conversions: quaternion, rotation matrix, axis-angle, rotation vector, Euler angles.

Pure numpy + numba; no rclpy import. Every function takes array_like input
with any leading dimensions and returns float64 arrays; inputs are never
modified; bad input raises ``ValueError`` naming the argument.

Conventions (stated once here, relied on everywhere):

- Quaternions are ``(x, y, z, w)``, scalar last (as ``geometry_msgs/Quaternion``),
  Hamilton product, active rotation. Output quaternions are unit and canonical
  (``w >= 0``). Input quaternions may have any non-zero norm.
- ``R`` maps body coordinates to world coordinates.
- Euler ``seq``: three of x, y, z, no two consecutive alike; upper case
  intrinsic (body axes), lower case extrinsic (fixed axes). ROS roll, pitch,
  yaw (REP 103) is ``'xyz'``, the same rotation as ``'ZYX'`` with (yaw, pitch, roll).
- Angles in radians unless ``degrees=True``.
- ``scalar_first=True`` on every function that takes or returns quaternions
  reads and writes them as ``(w, x, y, z)`` instead (PX4, MuJoCo, ahrs,
  spatialmath): the same numbers, reordered.

The formulas are the numerically robust ones of ``docs/numerics.md``: Markley's
pivot for matrices, ``atan2`` for angles, Bernardes-Viollet for Euler angles;
conversions are exact to a few ulps on the hard cases (angles near 0 and pi,
gimbal lock, quaternions scaled by 1e+-160).

Speed: every function runs one compiled (numba) loop over the samples, with
validation inside it, so a single sample costs little more than the call.
Large batches evaluate ``sin``, ``cos`` and ``atan2`` in vectorised loops of
branch-free polynomials (``_trigonometry``), and batches of 262144 samples or more are split
across threads (:func:`set_threads`, environment variable ``ROTATION_NODE_THREADS``).
"""
from . import _axis_angle, _euler, _matrix, _quaternion
from ._runtime import set_threads
from ._scalar_first import scalar_first_adapter
from ._validation import EulerSequence, parse_sequence, SEQUENCES

# Every public function that takes or returns quaternions, with the keyword scalar_first:
# adapt(function, its quaternion parameters, whether it returns quaternions).
adapt = scalar_first_adapter
axis_angle_from_quaternion = adapt(_axis_angle.axis_angle_from_quaternion, ('q',))
quaternion_from_axis_angle = adapt(_axis_angle.quaternion_from_axis_angle, (), True)
quaternion_from_rotation_vector = adapt(_axis_angle.quaternion_from_rotation_vector, (), True)
rotation_vector_from_quaternion = adapt(_axis_angle.rotation_vector_from_quaternion, ('q',))
euler_from_quaternion = adapt(_euler.euler_from_quaternion, ('q',))
euler_singularity_margin = adapt(_euler.euler_singularity_margin, ('q',))
quaternion_from_euler = adapt(_euler.quaternion_from_euler, (), True)
matrix_from_quaternion = adapt(_matrix.matrix_from_quaternion, ('q',))
quaternion_from_matrix = adapt(_matrix.quaternion_from_matrix, (), True)
canonical_quaternion = adapt(_quaternion.canonical_quaternion, ('q',), True)
quaternion_conjugate = adapt(_quaternion.quaternion_conjugate, ('q',), True)
quaternion_distance = adapt(_quaternion.quaternion_distance, ('p', 'q'))
quaternion_product = adapt(_quaternion.quaternion_product, ('p', 'q'), True)
rotate_vector = adapt(_quaternion.rotate_vector, ('q',))
del adapt
axis_angle_from_matrix = _axis_angle.axis_angle_from_matrix
matrix_from_axis_angle = _axis_angle.matrix_from_axis_angle
matrix_from_rotation_vector = _axis_angle.matrix_from_rotation_vector
rotation_vector_from_matrix = _axis_angle.rotation_vector_from_matrix
euler_from_matrix = _euler.euler_from_matrix
matrix_from_euler = _euler.matrix_from_euler

__all__ = [
    'EulerSequence', 'SEQUENCES',
    'axis_angle_from_matrix', 'axis_angle_from_quaternion', 'canonical_quaternion',
    'euler_from_matrix', 'euler_from_quaternion', 'euler_singularity_margin',
    'matrix_from_axis_angle', 'matrix_from_euler', 'matrix_from_quaternion',
    'matrix_from_rotation_vector', 'parse_sequence', 'quaternion_conjugate',
    'quaternion_distance', 'quaternion_from_axis_angle', 'quaternion_from_euler',
    'quaternion_from_matrix', 'quaternion_from_rotation_vector', 'quaternion_product',
    'rotate_vector', 'rotation_vector_from_matrix', 'rotation_vector_from_quaternion',
    'set_threads',
]
