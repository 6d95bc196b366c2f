"""
World ENU <-> NED <-> NWU and body FLU <-> FRD conventions, exactly (docs/frames.md).

Each change is a signed permutation of the axes and a rotation: ``P`` for the world (NED from
ENU, NWU from ENU, NWU from NED...), ``B = diag(1, -1, -1)`` for FRD <-> FLU. With ``R`` body
to world, ``R' = P R B``, ``q' = q_P (x) q (x) q_B``, world vectors ``P v``, body vectors
``B v``, world and body rotation-vector covariances ``P Sigma P^T`` and ``B Sigma B^T``.
Matrices, vectors and covariances are exact (elements only move and change sign);
quaternions are exact for a body change and NED <-> NWU, within 2 eps for the other world
changes, keep their norm and have ``w >= 0``.
"""
from __future__ import annotations

from dataclasses import dataclass
import functools
from typing import TYPE_CHECKING

import numpy as np

from ._arrays import finite_array

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ['BODY_FRAMES', 'ENU_FLU_FROM_NED_FRD', 'FrameConversion', 'NED_FRD_FROM_ENU_FLU',
           'WORLD_FRAMES']

#: World frame conventions: x east, y north, z up (REP 103); x north, y east, z down;
#: x north, y west, z up.
WORLD_FRAMES = ('enu', 'ned', 'nwu')
#: Body frame conventions: x forward, y left, z up (REP 103), or forward, right, down.
BODY_FRAMES = ('flu', 'frd')

_HALF_SQRT2 = float(np.sqrt(0.5))
# Signed permutations as (index, sign): row i of the matrix has sign[i] in column index[i].
_IDENTITY = (np.array([0, 1, 2]), np.array([1.0, 1.0, 1.0]))
_BODY_FLIP = (np.array([0, 1, 2]), np.array([1.0, -1.0, -1.0]))  # B

# Each world convention's coordinates from ENU's: a signed permutation (index, sign).
_FROM_ENU = {'enu': _IDENTITY,
             'ned': (np.array([1, 0, 2]), np.array([1.0, 1.0, -1.0])),    # P
             'nwu': (np.array([1, 0, 2]), np.array([1.0, -1.0, 1.0]))}    # N
# The world change's quaternion, q_W = scale * (x, y, z, w) with x, y, z, w in {-1, 0, 1}.
_WORLD_QUATERNIONS = {
    ('enu', 'ned'): (_HALF_SQRT2, (1, 1, 0, 0)), ('ned', 'enu'): (_HALF_SQRT2, (1, 1, 0, 0)),
    ('enu', 'nwu'): (_HALF_SQRT2, (0, 0, -1, 1)), ('nwu', 'enu'): (_HALF_SQRT2, (0, 0, 1, 1)),
    ('ned', 'nwu'): (1.0, (1, 0, 0, 0)), ('nwu', 'ned'): (1.0, (1, 0, 0, 0))}


@functools.lru_cache(maxsize=None)
def _world_change(source: str, target: str):
    """Return the signed permutation of world coordinates from ``source`` to ``target``."""
    matrix = (_signed_permutation_matrix(_FROM_ENU[target])
              @ _signed_permutation_matrix(_FROM_ENU[source]).T)
    index = np.argmax(np.abs(matrix), axis=1)
    return index, matrix[np.arange(3), index]


@functools.lru_cache(maxsize=None)
def _left_product_terms(p):
    """
    Return the terms of ``p (x) q`` for p of entries in {-1, 0, 1}: per component (sign, index).

    Zero terms are left out, so that the sum rounds as the written-out formula does.
    """
    px, py, pz, pw = p
    rows = [[(pw, 0), (px, 3), (py, 2), (-pz, 1)],     # x: pw x + px w + py z - pz y
            [(pw, 1), (-px, 2), (py, 3), (pz, 0)],     # y: pw y - px z + py w + pz x
            [(pw, 2), (px, 1), (-py, 0), (pz, 3)],     # z: pw z + px y - py x + pz w
            [(pw, 3), (-px, 0), (-py, 1), (-pz, 2)]]   # w: pw w - px x - py y - pz z
    return [[(sign, index) for sign, index in row if sign != 0] for row in rows]


def _left_product(scale, terms, components):
    """Return the components of ``q_W (x) q`` from ``q``'s, by :func:`_left_product_terms`."""
    out = []
    for row in terms:
        total = None
        for sign, index in row:
            term = components[index] if sign > 0 else -components[index]
            total = term if total is None else total + term
        out.append(total if scale == 1.0 else scale * total)
    return out


def _signed_permutation_matrix(perm) -> np.ndarray:
    index, sign = perm
    out = np.zeros((3, 3))
    out[np.arange(3), index] = sign
    return out


def _permute_vector(v: np.ndarray, perm) -> np.ndarray:
    index, sign = perm
    return v[..., index] * sign


def _permute_covariance(c: np.ndarray, perm) -> np.ndarray:
    index, sign = perm
    return c[..., index[:, None], index] * (sign[:, None] * sign)


def _check(frame: str, allowed: tuple, name: str) -> None:
    if frame not in allowed:
        raise ValueError(f'Expected `{name}` to be one of {", ".join(map(repr, allowed))}, '
                         f'got {frame!r}.')


@dataclass(frozen=True)
class FrameConversion:
    """
    A change of world and body frame conventions, from ``source_*`` to ``target_*``.

    Its methods raise ValueError naming the argument for a wrong shape or NaN/Inf.

    Parameters
    ----------
    source_world, target_world : {'enu', 'ned', 'nwu'}
        World frame of the input and of the output.
    source_body, target_body : {'flu', 'frd'}
        Body frame of the input and of the output.

    Examples
    --------
    >>> to_px4 = FrameConversion('enu', 'flu', 'ned', 'frd')
    >>> to_px4.quaternion([0.0, 0.0, 0.0, 1.0])    # level, facing east: yaw +90 deg in NED
    array([0.        , 0.        , 0.70710678, 0.70710678])
    >>> to_px4.inverse == FrameConversion('ned', 'frd', 'enu', 'flu')
    True

    """

    source_world: str = 'enu'
    source_body: str = 'flu'
    target_world: str = 'enu'
    target_body: str = 'flu'

    def __post_init__(self) -> None:
        """Validate the frame names."""
        _check(self.source_world, WORLD_FRAMES, 'source_world')
        _check(self.target_world, WORLD_FRAMES, 'target_world')
        _check(self.source_body, BODY_FRAMES, 'source_body')
        _check(self.target_body, BODY_FRAMES, 'target_body')

    @property
    def changes_world(self) -> bool:
        """Tell whether the world frame changes (ENU, NED, NWU)."""
        return self.source_world != self.target_world

    @property
    def changes_body(self) -> bool:
        """Tell whether the body frame changes (FLU <-> FRD)."""
        return self.source_body != self.target_body

    @property
    def is_identity(self) -> bool:
        """Tell whether nothing changes."""
        return not (self.changes_world or self.changes_body)

    @property
    def inverse(self) -> 'FrameConversion':
        """Return the conversion back, from the target frames to the source frames."""
        return FrameConversion(self.target_world, self.target_body,
                               self.source_world, self.source_body)

    @property
    def _world(self):
        if not self.changes_world:
            return _IDENTITY
        return _world_change(self.source_world, self.target_world)

    @property
    def _body(self):
        return _BODY_FLIP if self.changes_body else _IDENTITY

    def world_matrix(self) -> np.ndarray:
        """Return the 3x3 signed permutation that maps world coordinates (``P``, ``N``, ``I``)."""
        return _signed_permutation_matrix(self._world)

    def body_matrix(self) -> np.ndarray:
        """Return the 3x3 signed permutation that maps body coordinates (``B`` or ``I``)."""
        return _signed_permutation_matrix(self._body)

    def quaternion(self, quaternion: ArrayLike) -> np.ndarray:
        """
        Return the orientation ``q_P (x) q (x) q_B`` (x, y, z, w) in the target frames.

        ``quaternion`` (..., 4) is the body-to-world orientation in the source frames, any
        norm; the result has the same norm and ``w >= 0``.
        """
        q = finite_array(quaternion, 'quaternion', (4,))
        single = q.ndim == 1   # Python floats: a tenth of the time of numpy's small arrays
        x, y, z, w = q.tolist() if single else np.moveaxis(q, -1, 0)
        if self.changes_body:
            x, y, z, w = w, z, -y, -x
        if self.changes_world:
            scale, p = _WORLD_QUATERNIONS[self.source_world, self.target_world]
            x, y, z, w = _left_product(scale, _left_product_terms(p), (x, y, z, w))
        if single:
            sign = -1.0 if w < 0.0 else 1.0
            return np.array([sign * x + 0.0, sign * y + 0.0, sign * z + 0.0, sign * w + 0.0])
        out = np.stack(np.broadcast_arrays(x, y, z, w), axis=-1)
        return np.where(out[..., 3:] < 0.0, -out, out) + 0.0

    def matrix(self, matrix: ArrayLike) -> np.ndarray:
        """Return the body-to-world matrices (..., 3, 3) in the target frames: ``P R B``, exact."""
        m = finite_array(matrix, 'matrix', (3, 3))
        (wi, ws), (bi, bs) = self._world, self._body
        return m[..., wi[:, None], bi] * (ws[:, None] * bs)

    def world_vector(self, vector: ArrayLike) -> np.ndarray:
        """Return ``P v`` (exact) for world-frame vectors (..., 3) (world angular velocity)."""
        return _permute_vector(finite_array(vector, 'vector', (3,)), self._world)

    def body_vector(self, vector: ArrayLike) -> np.ndarray:
        """Return ``B v`` (exact) for body-frame vectors (..., 3) (body angular velocity)."""
        return _permute_vector(finite_array(vector, 'vector', (3,)), self._body)

    def world_covariance(self, covariance: ArrayLike) -> np.ndarray:
        """Return ``P Sigma P^T`` (exact) of fixed-axes rotation-vector covariances (..., 3, 3)."""
        return _permute_covariance(finite_array(covariance, 'covariance', (3, 3)), self._world)

    def body_covariance(self, covariance: ArrayLike) -> np.ndarray:
        """Return ``B Sigma B^T`` (exact) of body-axes rotation-vector covariances (..., 3, 3)."""
        return _permute_covariance(finite_array(covariance, 'covariance', (3, 3)), self._body)


#: REP 103 (ENU world, FLU body) to PX4 / aerospace (NED world, FRD body).
NED_FRD_FROM_ENU_FLU = FrameConversion('enu', 'flu', 'ned', 'frd')
#: PX4 / aerospace (NED world, FRD body) to REP 103 (ENU world, FLU body).
ENU_FLU_FROM_NED_FRD = FrameConversion('ned', 'frd', 'enu', 'flu')
