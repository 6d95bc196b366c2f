"""
The competing methods of the accuracy study, each written the way its users write it.

Every method takes a batch (the leading axis is the sample) and returns a batch;
none validates its input beyond what its source does. Quaternions are
(x, y, z, w), scalar last, active, body-to-world (docs/numerics.md); formulas from
other conventions are transcribed into this one without changing their
numerics.

Families and sources:

- matrix -> quaternion: the textbook trace formula; Shepperd [1]_ and
  Markley [2]_, which share the pivot on the largest of trace, R00, R11, R22
  and differ only in how the chosen column of the symmetric 4x4 matrix is
  scaled (Shepperd: the pivot component from a square root; Markley: the
  column's norm); tf2's ``getRotation`` (Shepperd's formulas, pivot on the
  trace whenever it is positive); the orthogonal Procrustes (SVD) nearest rotation followed
  by Markley; scipy's ``Rotation.from_matrix``; this package.
- quaternion -> rotation vector: the textbook ``theta = 2 acos(q_s)``,
  ``n = q_v / sqrt(1 - q_s^2)``; ``2 atan2(|q_v|, q_s)`` in plain numpy;
  scipy's ``as_rotvec``; this package.
- quaternion -> Euler angles: tf2's ``Matrix3x3(q).getRPY`` and PlotJuggler's
  ``quaternion_to_RPY`` (both ``asin`` pitch, ROS roll-pitch-yaw only);
  transforms3d's matrix-based ``quat2euler`` (Shoemake); scipy's
  ``as_euler``; this package.

scipy and transforms3d are study-time peers: this module is the only place
that imports them, and only inside the study.

References
----------
.. [1] S. W. Shepperd, "Quaternion from Rotation Matrix", J. Guidance and
   Control 1(3), 1978.
.. [2] F. L. Markley, "Unit Quaternion from Rotation Matrix", J. Guidance,
   Control, and Dynamics 31(2), 2008.

"""
import dataclasses
from typing import Callable, Optional, Tuple

import numpy as np
from rotation_node import conversions as rc
from scipy.spatial.transform import Rotation
import transforms3d

#: Label of this package in every table.
PACKAGE = 'rotation_node'
#: The one Euler convention of the tf2 and PlotJuggler formulas: ROS roll, pitch, yaw.
ROS_RPY = 'xyz'


@dataclasses.dataclass(frozen=True)
class Method:
    """
    One competing implementation of a conversion.

    Attributes
    ----------
    name : str
        Row label in the tables and plot legend.
    function : callable
        The conversion on a batch. Euler methods take ``(q, seq)``.
    source : str
        Where it comes from (a library call, or the formula it transcribes).
    batch : bool
        Whether it has a batch form; without one (transforms3d) it is a
        Python loop over the samples, and is timed that way.
    sequences : tuple of str or None
        Euler conventions it supports; None means all 24.

    """

    name: str
    function: Callable
    source: str
    batch: bool = True
    sequences: Optional[Tuple[str, ...]] = None

    @property
    def is_package(self):
        """Whether this is rotation_node's own method."""
        return self.name.startswith(PACKAGE)


# ------------------------------------------------------------ matrix -> quaternion

def textbook_trace_formula(m):
    """Return the textbook ``q_s = 1/2 sqrt(tr R + 1)``, ``q_v = vec(R - R^T) / (4 q_s)``."""
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    w = 0.5 * np.sqrt(trace + 1.0)
    skew = np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0],
                     m[:, 1, 0] - m[:, 0, 1]], axis=1)
    return np.concatenate([skew / (4.0 * w[:, None]), w[:, None]], axis=1)


def _pivot_columns(m):
    """
    Return the four columns of Markley's symmetric matrix and the pivot candidates.

    Column ``p`` is ``4 q_p q`` (p = x, y, z, w), well conditioned when its
    diagonal entry ``1 + R00 - R11 - R22`` (..., ``1 + trace``) is large.

    Returns
    -------
    columns : ndarray, shape (n, 4, 4)
        ``columns[:, p]`` is column ``p``.
    candidates : ndarray, shape (n, 4)
        R00, R11, R22 and the trace: the largest selects the pivot.

    """
    m00, m01, m02 = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    m10, m11, m12 = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    m20, m21, m22 = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    trace = m00 + m11 + m22
    columns = np.stack([
        np.stack([1.0 + m00 - m11 - m22, m01 + m10, m02 + m20, m21 - m12], axis=1),
        np.stack([m01 + m10, 1.0 + m11 - m00 - m22, m12 + m21, m02 - m20], axis=1),
        np.stack([m02 + m20, m12 + m21, 1.0 + m22 - m00 - m11, m10 - m01], axis=1),
        np.stack([m21 - m12, m02 - m20, m10 - m01, 1.0 + trace], axis=1),
    ], axis=1)
    return columns, np.stack([m00, m11, m22, trace], axis=1)


def _column(columns, pivot):
    return np.take_along_axis(columns, pivot[:, None, None], axis=1)[:, 0]


def _pivot_component_scaled(column, pivot):
    """Divide ``4 q_p q`` by ``4 q_p``, with ``q_p = 1/2 sqrt(4 q_p^2)`` (Shepperd's scaling)."""
    return column / (2.0 * np.sqrt(np.take_along_axis(column, pivot[:, None], axis=1)))


def shepperd(m):
    """Return Shepperd's quaternion: pivot on the largest of R00, R11, R22, trace."""
    columns, candidates = _pivot_columns(m)
    pivot = np.argmax(candidates, axis=1)
    return _pivot_component_scaled(_column(columns, pivot), pivot)


def tf2_get_rotation(m):
    """
    Return tf2's ``Matrix3x3::getRotation``, vectorised: Shepperd's formulas, another pivot.

    The trace when it is positive, else the largest diagonal entry (ties to
    the lower index, as its nested comparisons do).
    """
    columns, candidates = _pivot_columns(m)
    pivot = np.where(candidates[:, 3] > 0.0, 3, np.argmax(candidates[:, :3], axis=1))
    return _pivot_component_scaled(_column(columns, pivot), pivot)


def markley(m):
    """Return Markley's quaternion: pivot on the largest of R00, R11, R22, trace; normalise."""
    columns, candidates = _pivot_columns(m)
    column = _column(columns, np.argmax(candidates, axis=1))
    return column / np.linalg.norm(column, axis=1, keepdims=True)


def svd_markley(m):
    """Return Markley's quaternion of the SVD nearest rotation ``U diag(1, 1, det(U V^T)) V^T``."""
    u, _, vt = np.linalg.svd(m)
    u[:, :, 2] *= np.sign(np.linalg.det(u @ vt))[:, None]
    return markley(u @ vt)


MATRIX_TO_QUATERNION = (
    Method('textbook trace formula', textbook_trace_formula, 'textbook formula, numpy'),
    Method('Shepperd 1978', shepperd, 'numpy, pivot on max(tr, R00, R11, R22)'),
    Method('tf2 getRotation', tf2_get_rotation,
           'tf2::Matrix3x3::getRotation, transcribed to numpy'),
    Method('Markley 2008', markley, 'numpy, pivot column normalised'),
    Method('SVD nearest + Markley', svd_markley, 'numpy.linalg.svd, then Markley'),
    Method('scipy from_matrix', lambda m: Rotation.from_matrix(m).as_quat(),
           'scipy Rotation.from_matrix(R).as_quat() (SVD orthogonalisation + Markley)'),
    Method(f'{PACKAGE} quaternion_from_matrix', rc.quaternion_from_matrix,
           'validated; Markley, nearest rotation first when not orthonormal to 1e-15'),
)


# ------------------------------------------------------------ quaternion -> rotation vector

def textbook_acos(q):
    """
    Return the textbook ``theta n``: ``theta = 2 acos(q_s)``, ``n = q_v / sqrt(1 - q_s^2)``.

    Assumes a unit ``q``, as the textbook formula does.
    """
    w = q[:, 3]
    angle = 2.0 * np.arccos(w)
    axis = q[:, :3] / np.sqrt(1.0 - w * w)[:, None]
    return angle[:, None] * axis


def numpy_atan2(q):
    """Return ``2 atan2(|q_v|, q_s) q_v / |q_v|`` (``q_s >= 0`` first, numpy's norm); 0 -> 0."""
    q = np.where(q[:, 3:] < 0.0, -q, q)
    norm = np.linalg.norm(q[:, :3], axis=1)
    angle = 2.0 * np.arctan2(norm, q[:, 3])
    scale = np.divide(angle, norm, out=np.zeros_like(norm), where=norm > 0.0)
    return q[:, :3] * scale[:, None]


QUATERNION_TO_ROTATION_VECTOR = (
    Method('textbook 2 acos(q_s)', textbook_acos, 'textbook formula, numpy'),
    Method('2 atan2(|q_v|, q_s)', numpy_atan2, 'numpy, np.linalg.norm'),
    Method('scipy as_rotvec', lambda q: Rotation.from_quat(q).as_rotvec(),
           'scipy Rotation.from_quat(q).as_rotvec()'),
    Method(f'{PACKAGE} rotation_vector_from_quaternion', rc.rotation_vector_from_quaternion,
           'validated; atan2 with exact power-of-two scaling'),
)


# ------------------------------------------------------------ quaternion -> Euler angles

def tf2_get_rpy(q, seq=ROS_RPY):
    """
    Return tf2's ``Matrix3x3(q).getRPY(roll, pitch, yaw)``, vectorised.

    ``setRotation(q)`` builds the matrix with ``s = 2 / |q|^2``;
    ``getEulerYPR`` (solution 1) takes ``pitch = -asin(R20)`` (clamped), and
    when ``|R20| >= 1`` yaw 0, pitch ``-+pi/2`` and roll ``atan2(R21, R22)``
    (both entries are ~0 there: ros/geometry2 issue 504); otherwise roll and
    yaw from ``atan2`` of the entries divided by ``cos(pitch)``. Returns
    (roll, pitch, yaw): extrinsic ``xyz`` only.
    """
    _require_ros_rpy(seq)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz = y * ys, y * zs
    r00, r10 = 1.0 - (yy + z * zs), xy + wz
    r20, r21, r22 = xz - wy, yz + wx, 1.0 - (xx + yy)
    pitch = -np.arcsin(np.clip(r20, -1.0, 1.0))
    cos_pitch = np.cos(pitch)
    roll = np.arctan2(r21 / cos_pitch, r22 / cos_pitch)
    yaw = np.arctan2(r10 / cos_pitch, r00 / cos_pitch)
    locked = np.abs(r20) >= 1.0
    roll = np.where(locked, np.arctan2(r21, r22), roll)
    pitch = np.where(locked, np.where(r20 < 0.0, np.pi / 2, -np.pi / 2), pitch)
    yaw = np.where(locked, 0.0, yaw)
    return np.stack([roll, pitch, yaw], axis=1)


def plotjuggler_rpy(q, seq=ROS_RPY):
    """
    Return PlotJuggler's ``QuaternionToRollPitchYaw::calculateNextPoint``, vectorised.

    Normalises when ``| |q|^2 - 1 | > eps`` (``|q|^2 < 1e-10`` gives zeros);
    ``pitch = asin(2 (w y - z x))``, ``+-pi/2`` when out of range; roll and yaw
    from ``atan2`` of the quaternion formulas; no unwrapping. Extrinsic ``xyz``
    only.
    """
    _require_ros_rpy(seq)
    norm2 = np.sum(q * q, axis=1, keepdims=True)
    q = np.where(np.abs(norm2 - 1.0) > np.finfo(float).eps, q / np.sqrt(norm2), q)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    sin_pitch = 2 * (w * y - z * x)
    pitch = np.where(np.abs(sin_pitch) >= 1, np.copysign(np.pi / 2, sin_pitch),
                     np.arcsin(np.clip(sin_pitch, -1.0, 1.0)))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    angles = np.stack([roll, pitch, yaw], axis=1)
    return np.where(norm2 < 1e-10, 0.0, angles)


def _require_ros_rpy(seq):
    if seq != ROS_RPY:
        raise ValueError(f'only ROS roll, pitch, yaw ({ROS_RPY!r}) is supported, got {seq!r}')


def transforms3d_axes(seq):
    """Return transforms3d's name of a convention: ``'s'`` static, ``'r'`` rotating, + axes."""
    return ('s' if seq.islower() else 'r') + seq.lower()


def transforms3d_euler(q, seq):
    """Return ``transforms3d.euler.quat2euler`` (via the matrix, Shoemake), one by one."""
    axes = transforms3d_axes(seq)
    quat2euler = transforms3d.euler.quat2euler
    return np.array([quat2euler((w, x, y, z), axes) for x, y, z, w in q.tolist()])


QUATERNION_TO_EULER = (
    Method('tf2 getRPY (asin pitch)', tf2_get_rpy,
           'tf2::Matrix3x3(q).getRPY, transcribed to numpy', sequences=(ROS_RPY,)),
    Method('PlotJuggler (asin pitch)', plotjuggler_rpy,
           'PlotJuggler quaternion_to_RPY, transcribed to numpy', sequences=(ROS_RPY,)),
    Method('transforms3d quat2euler', transforms3d_euler,
           f'transforms3d {transforms3d.__version__} quat2euler, one call per sample',
           batch=False),
    Method('scipy as_euler', lambda q, seq: Rotation.from_quat(q).as_euler(seq),
           'scipy Rotation.from_quat(q).as_euler(seq)'),
    Method(f'{PACKAGE} euler_from_quaternion', rc.euler_from_quaternion,
           'validated; Bernardes-Viollet, atan2/hypot only'),
)
