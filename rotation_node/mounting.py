"""
A fixed mounting rotation and world alignment: ``R' = W R M`` (docs/frames.md).

``R`` maps the sensor's body coordinates to its world's. ``M`` is the new body frame's
orientation in the sensor's (``base_link`` in ``imu_link``), ``W`` the sensor's world frame's
orientation in the new world; then ``q' = q_W (x) q (x) q_M``, body vectors ``M^T v``, world
vectors ``W v``, body-axes covariances ``M^T Sigma M``, fixed-axes ones ``W Sigma W^T``.
A yaw offset and a magnetic declination rotate the world about z,
``W = Rz(yaw_offset + magnetic_declination) W0``: robot_localization's sign convention.
Elementwise numpy, so that one sample and a block give the same numbers bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence, TYPE_CHECKING

import numpy as np

from ._arrays import finite_array
from .conversions import matrix_from_quaternion, quaternion_from_euler

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ['IDENTITY', 'Mounting', 'normalised_unit_quaternion', 'quaternion_from_rotation_values',
           'UNIT_NORM_TOLERANCE']

IDENTITY = (0.0, 0.0, 0.0, 1.0)
#: A quaternion given as a parameter or in a scene must have unit norm within this (it is
#: then normalised).
UNIT_NORM_TOLERANCE = 1e-6


def normalised_unit_quaternion(values: Sequence[float]) -> tuple[float, ...]:
    """Return ``[x, y, z, w]`` over its norm; a ValueError unless that is 1 within tolerance."""
    norm = math.hypot(*values)
    if abs(norm - 1.0) > UNIT_NORM_TOLERANCE:
        raise ValueError(f'expected a unit quaternion [x, y, z, w], got norm {norm!r} '
                         f'(tolerance {UNIT_NORM_TOLERANCE:g})')
    return tuple(c / norm for c in values)


def quaternion_from_rotation_values(values: Sequence[float]) -> tuple[float, ...]:
    """
    Return the unit quaternion (x, y, z, w) of ``[x, y, z, w]`` or ``[roll, pitch, yaw]``.

    A quaternion must have unit norm within :data:`UNIT_NORM_TOLERANCE` (it is normalised);
    roll, pitch, yaw are degrees, ROS's ``'xyz'`` (``R = Rz(yaw) Ry(pitch) Rx(roll)``).
    ValueError for another length, a non-finite number or a quaternion not of unit norm.
    """
    v = [float(x) for x in values]
    if not all(map(math.isfinite, v)):
        raise ValueError(f'expected finite numbers, got {v}')
    if len(v) == 3:
        q = quaternion_from_euler(v, 'xyz', degrees=True)
        return tuple(float(c) for c in q)
    if len(v) == 4:
        return normalised_unit_quaternion(v)
    raise ValueError(f'expected [x, y, z, w] (a quaternion) or [roll, pitch, yaw] (degrees), '
                     f'got {len(v)} numbers')


def _product(p, q):
    """Return the Hamilton product ``p (x) q`` of (..., 4) arrays, component by component."""
    px, py, pz, pw = np.moveaxis(np.asarray(p, dtype=np.float64), -1, 0)
    qx, qy, qz, qw = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack(np.broadcast_arrays(
        pw * qx + px * qw + (py * qz - pz * qy),
        pw * qy + py * qw + (pz * qx - px * qz),
        pw * qz + pz * qw + (px * qy - py * qx),
        pw * qw - (px * qx + py * qy + pz * qz)), axis=-1)


def _apply(matrix, v):
    """Return ``matrix @ v`` for (..., 3) vectors, component by component (no BLAS)."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([matrix[i, 0] * x + matrix[i, 1] * y + matrix[i, 2] * z for i in range(3)],
                    axis=-1)


@dataclass(frozen=True)
class Mounting:
    """
    A body-side rotation ``M`` and a world-side rotation ``W``: ``R' = W R M``.

    Its methods raise ValueError naming the argument for a wrong shape or NaN/Inf.

    Parameters
    ----------
    body : tuple of float, shape (4,)
        ``M`` (x, y, z, w), unit: the new body's orientation in the sensor's body frame.
    world : tuple of float, shape (4,)
        ``W`` (x, y, z, w), unit: the sensor's world frame's orientation in the new world.

    Examples
    --------
    >>> yaw_90 = Mounting.from_parts(world=[0.0, 0.0, 90.0])
    >>> yaw_90.quaternion([0.0, 0.0, 0.0, 1.0]).round(6)    # facing east -> facing north
    array([0.      , 0.      , 0.707107, 0.707107])

    """

    body: tuple = IDENTITY
    world: tuple = IDENTITY

    @classmethod
    def from_parts(cls, body: Sequence[float] = IDENTITY, world: Sequence[float] = IDENTITY,
                   yaw_offset: float = 0.0, magnetic_declination: float = 0.0) -> 'Mounting':
        """
        Return the mounting of the node's parameters.

        Parameters
        ----------
        body, world : sequence of float
            ``M`` and ``W0`` as :func:`quaternion_from_rotation_values` takes them.
        yaw_offset, magnetic_declination : float
            Radians; ``W = Rz(yaw_offset + magnetic_declination) W0``.

        """
        m = quaternion_from_rotation_values(body)
        w = quaternion_from_rotation_values(world)
        angle = float(yaw_offset) + float(magnetic_declination)
        if angle != 0.0:
            w = tuple(float(c) for c in _product(
                [0.0, 0.0, math.sin(0.5 * angle), math.cos(0.5 * angle)], w))
        return cls(m, w)

    @property
    def changes_body(self) -> bool:
        """Tell whether ``M`` is not the identity."""
        return self.body[:3] != (0.0, 0.0, 0.0)

    @property
    def changes_world(self) -> bool:
        """Tell whether ``W`` is not the identity."""
        return self.world[:3] != (0.0, 0.0, 0.0)

    @property
    def is_identity(self) -> bool:
        """Tell whether nothing changes."""
        return not (self.changes_body or self.changes_world)

    @property
    def inverse(self) -> 'Mounting':
        """Return the mounting back: ``R = W^T R' M^T``."""
        bx, by, bz, bw = self.body
        wx, wy, wz, ww = self.world
        return Mounting((-bx, -by, -bz, bw), (-wx, -wy, -wz, ww))

    def body_matrix(self) -> np.ndarray:
        """Return ``M``, 3x3."""
        return matrix_from_quaternion(self.body)

    def world_matrix(self) -> np.ndarray:
        """Return ``W``, 3x3."""
        return matrix_from_quaternion(self.world)

    def quaternion(self, quaternion: ArrayLike) -> np.ndarray:
        """Return ``q_W (x) q (x) q_M`` of orientations (..., 4), any norm (kept), ``w >= 0``."""
        q = finite_array(quaternion, 'quaternion', (4,))
        if self.changes_body:
            q = _product(q, self.body)
        if self.changes_world:
            q = _product(self.world, q)
        return np.where(q[..., 3:] < 0.0, -q, q) + 0.0

    def body_vector(self, vector: ArrayLike) -> np.ndarray:
        """Return ``M^T v`` for body-frame vectors (body angular velocity), (..., 3)."""
        v = finite_array(vector, 'vector', (3,))
        return _apply(self.body_matrix().T, v) if self.changes_body else v.copy()

    def world_vector(self, vector: ArrayLike) -> np.ndarray:
        """Return ``W v`` for world-frame vectors (world angular velocity), (..., 3)."""
        v = finite_array(vector, 'vector', (3,))
        return _apply(self.world_matrix(), v) if self.changes_world else v.copy()

    def vector(self, vector: ArrayLike, frame: str) -> np.ndarray:
        """Return ``vector`` of ``frame`` (``'world'`` or ``'body'``) rotated as that frame is."""
        return self.world_vector(vector) if frame == 'world' else self.body_vector(vector)

    def body_covariance(self, covariance: ArrayLike) -> np.ndarray:
        """Return ``M^T Sigma M`` for a body-axes rotation-vector covariance, (..., 3, 3)."""
        c = finite_array(covariance, 'covariance', (3, 3))
        m = self.body_matrix()
        return np.einsum('ji,...jk,kl->...il', m, c, m) if self.changes_body else c.copy()

    def world_covariance(self, covariance: ArrayLike) -> np.ndarray:
        """Return ``W Sigma W^T`` for a fixed-axes rotation-vector covariance, (..., 3, 3)."""
        c = finite_array(covariance, 'covariance', (3, 3))
        w = self.world_matrix()
        return np.einsum('ij,...jk,lk->...il', w, c, w) if self.changes_world else c.copy()
