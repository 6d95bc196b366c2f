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

The formulas are the numerically robust ones of ``docs/numerics.md``: Markley's
pivot for matrices, ``atan2`` for angles, Bernardes-Viollet for Euler angles;
conversions are exact to a few ulps on the hard cases (angles near 0 and pi,
gimbal lock, quaternions scaled by 1e+-160).

Speed: every function runs one compiled (numba) loop over the samples, with
validation inside it, so a single sample costs little more than the call.
Large batches evaluate ``sin``, ``cos`` and ``atan2`` in vectorised loops of
branch-free polynomials (``_trigonometry``), and batches of 65536 samples or more are split
across threads (:func:`set_threads`, environment variable ``ROTATION_NODE_THREADS``).
"""
from ._axis_angle import (axis_angle_from_matrix, axis_angle_from_quaternion,
                          matrix_from_axis_angle, matrix_from_rotation_vector,
                          quaternion_from_axis_angle, quaternion_from_rotation_vector,
                          rotation_vector_from_matrix, rotation_vector_from_quaternion)
from ._euler import (euler_from_matrix, euler_from_quaternion, euler_singularity_margin,
                     matrix_from_euler, quaternion_from_euler)
from ._matrix import matrix_from_quaternion, quaternion_from_matrix
from ._quaternion import (canonical_quaternion, quaternion_conjugate, quaternion_distance,
                          quaternion_product, rotate_vector)
from ._runtime import set_threads
from ._validation import EulerSequence, parse_sequence

_LOWER = ('xyz', 'xzy', 'yxz', 'yzx', 'zxy', 'zyx', 'xyx', 'xzx', 'yxy', 'yzy', 'zxz', 'zyz')
#: The 24 conventions: 12 extrinsic (lower case) and 12 intrinsic (upper case).
SEQUENCES = _LOWER + tuple(s.upper() for s in _LOWER)

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
