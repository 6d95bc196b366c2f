"""
Ground-truth motions: orientation and body angular velocity at given times.

:func:`motion_truth` returns ``(q, w)`` of a scene's motion for times ``t``
(seconds since the first sample, shape ``(n,)``):

- ``q``, shape (n, 4): unit quaternions (x, y, z, w), active, body-to-world,
  continuous in sign (``q[k] . q[k-1] >= 0``), so that a sign flip in a sensor
  stream comes only from the ``quaternion_sign_flips`` effect;
- ``w``, shape (n, 3): body angular velocity, rad/s
  (``q' = 1/2 q (x) (w, 0)``).

``constant_rate``, ``coning`` and ``euler_sweep`` are exact (closed form);
``torque_free`` integrates Euler's equations with a structure-preserving
splitting (:mod:`rotation_node.scene._free_rigid_body`).

:class:`MotionStream` computes the same truth block by block of consecutive
samples, carrying the sign continuity and the integrator's state across
blocks, with results bit-identical to :func:`motion_truth` over all samples at
once: the simulator streams scenes of any length in bounded memory.
"""
from __future__ import annotations

import math
from typing import Optional, TYPE_CHECKING

import numpy as np
from rotation_node.conversions import (
    quaternion_from_euler, quaternion_from_rotation_vector, quaternion_product)
from rotation_node.kinematics import angular_velocity_from_euler_rates

from . import _free_rigid_body
from .spec import Coning, ConstantRate, EulerSweep, Motion, TorqueFree

if TYPE_CHECKING:
    from rotation_node.type_aliases import FloatArray


def _continue_signs(q, previous, previous_sign):
    """
    Return ``q`` with continuous signs after ``previous`` (the unsigned sample before, or None).

    Also returns the last unsigned quaternion and its sign, to continue with.
    """
    if previous is None:
        linked, first = q, 1.0
    else:
        linked, first = np.concatenate((previous[np.newaxis], q)), previous_sign
    steps = np.sign(np.einsum('ij,ij->i', linked[1:], linked[:-1]))
    steps[steps == 0] = 1.0
    if previous is None:
        signs = np.concatenate(([1.0], np.cumprod(steps)))
    else:
        signs = first * np.cumprod(steps)
    return q * signs[:, np.newaxis], q[-1].copy(), float(signs[-1])


def _constant_rate_unsigned(orientation, angular_velocity, t):
    """Return ``q0 (x) exp(w t)`` and ``w``; exp comes back canonical (scalar >= 0), unsigned."""
    t = np.asarray(t, dtype=np.float64)
    w = np.broadcast_to(np.asarray(angular_velocity, dtype=np.float64), (t.size, 3))
    q = quaternion_product(orientation, quaternion_from_rotation_vector(w * t[:, np.newaxis]))
    return q, w.copy()


def coning_truth(half_angle: float, frequency: float,
                 t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return classical coning motion, phase 0 at ``t = 0`` (docs/numerics.md).

    With half angle ``a`` and cone rate ``W``, scalar last:
    ``q = (sin(a/2) cos(W t), sin(a/2) sin(W t), 0, cos(a/2))`` and
    ``w = (-W sin a sin(W t), W sin a cos(W t), -W (1 - cos a))``.

    Parameters
    ----------
    half_angle : float
        ``a``, rad.
    frequency : float
        ``W``, rad/s.
    t : array_like, shape (n,)
        Times, s.

    Returns
    -------
    q : ndarray, shape (n, 4)
    w : ndarray, shape (n, 3)

    """
    phase = frequency * np.asarray(t, dtype=np.float64)
    cos_phase, sin_phase = np.cos(phase), np.sin(phase)
    s = np.sin(0.5 * half_angle)
    q = np.stack([s * cos_phase, s * sin_phase, np.zeros_like(phase),
                  np.full_like(phase, np.cos(0.5 * half_angle))], axis=-1)
    # 1 - cos a = 2 sin^2(a/2), without the cancellation at small a.
    w = np.stack([-frequency * np.sin(half_angle) * sin_phase,
                  frequency * np.sin(half_angle) * cos_phase,
                  np.full_like(phase, -2.0 * frequency * s * s)], axis=-1)
    return q, w


def longest_interval(t: FloatArray) -> float:
    """Return the longest interval between consecutive times ``t`` (0 for fewer than two)."""
    return float(np.max(np.diff(t), initial=0.0))


class _TorqueFree:
    """
    The torque-free integration, resumable: each ``truth(t)`` continues the previous one.

    A fourth-order Lie-Poisson splitting (:mod:`rotation_node.scene._free_rigid_body`)
    with internal steps of at most ``MAX_STEP_ANGLE`` rad: ``|I w|`` and the world
    angular momentum ``R I w`` stay constant to round-off, the kinetic energy within
    ~1e-14 (relative), with no secular drift. The trajectory itself is as accurate as
    the motion is well-conditioned: ~1e-12 of a tight DOP853 reference for a generic
    spin, but a spin started near the intermediate axis amplifies round-off at every
    flip, and the tumbling-box scene's truth is reproducible only to ~3e-9 rad (two
    different time grids differ by that; see docs/accuracy.md).
    """

    def __init__(self, inertia, orientation, angular_velocity, longest):
        self.inverse_inertia = 1.0 / np.asarray(inertia, dtype=np.float64)
        w0 = np.asarray(angular_velocity, dtype=np.float64)
        self.momentum = w0 / self.inverse_inertia
        self.momentum_norm = math.sqrt(
            self.momentum[0] ** 2 + self.momentum[1] ** 2 + self.momentum[2] ** 2)
        # |w|^2 <= w.I w / I_min = 2T / I_min along the whole motion: T is conserved.
        fastest = np.sqrt(w0 @ self.momentum * self.inverse_inertia.max())
        self.substeps = max(1, math.ceil(fastest * longest / _free_rigid_body.MAX_STEP_ANGLE))
        q0 = np.array(orientation, dtype=np.float64)
        self.q = q0 / np.linalg.norm(q0)
        self.time: Optional[float] = None

    def truth(self, t):
        t = np.ascontiguousarray(t, dtype=np.float64)
        first = self.time is None
        times = t if self.time is None else np.concatenate(([self.time], t))
        q, momentum = _free_rigid_body.integrate(
            self.q, self.momentum, self.momentum_norm, self.inverse_inertia, times,
            self.substeps, _free_rigid_body.AXES, _free_rigid_body.FRACTIONS)
        if not first:
            q, momentum = q[1:], momentum[1:]
        self.q, self.momentum, self.time = q[-1].copy(), momentum[-1].copy(), float(t[-1])
        return q, momentum * self.inverse_inertia


def _euler_sweep_unsigned(sequence, start, end, duration, t):
    """
    Return the Euler angles' rotation moving linearly from ``start`` (t = 0) to ``end``.

    The body angular velocity follows from the constant Euler rates; that map is
    defined everywhere, gimbal lock included (only its inverse is singular).
    """
    t = np.asarray(t, dtype=np.float64)
    start = np.asarray(start, dtype=np.float64)
    rates = (np.asarray(end, dtype=np.float64) - start) / duration
    angles = start + rates * t[:, np.newaxis]
    q = quaternion_from_euler(angles, sequence)
    w = angular_velocity_from_euler_rates(angles, np.broadcast_to(rates, angles.shape),
                                          sequence, frame='body')
    return q, w


def motion_truth(motion: Motion, t: FloatArray,
                 duration: float) -> tuple[FloatArray, FloatArray]:
    """
    Return the truth ``(q, w)`` of a scene's motion at times ``t``.

    Parameters
    ----------
    motion : ConstantRate or Coning or TorqueFree or EulerSweep
        The scene's validated ``motion``.
    t : ndarray, shape (n,)
        Times since the first sample, s.
    duration : float
        The scene's duration, s (the end of an Euler sweep).

    Returns
    -------
    q : ndarray, shape (n, 4)
    w : ndarray, shape (n, 3)

    """
    t = np.asarray(t, dtype=np.float64)
    return MotionStream(motion, duration, longest_interval(t)).truth(t)


class MotionStream:
    """
    The truth of a motion over consecutive blocks of samples.

    ``truth(t)`` called on consecutive pieces of a time series returns, piece
    by piece, exactly (bit for bit) what :func:`motion_truth` returns for the
    whole series: sign continuity and the torque-free integrator's state carry
    over from one block to the next.

    Parameters
    ----------
    motion : ConstantRate or Coning or TorqueFree or EulerSweep
        The scene's validated ``motion``.
    duration : float
        The scene's duration, s (the end of an Euler sweep).
    longest : float
        The longest interval between consecutive times of the whole series,
        s (:func:`longest_interval`); sets the torque-free integrator's step.

    Raises
    ------
    TypeError
        If ``motion`` is not a scene motion.

    """

    def __init__(self, motion: Motion, duration: float, longest: float) -> None:
        if not isinstance(motion, (ConstantRate, Coning, TorqueFree, EulerSweep)):
            raise TypeError(f'motion_truth: not a scene motion: {motion!r}')
        self._motion = motion
        self._duration = duration
        self._torque_free = (
            _TorqueFree(motion.inertia, motion.orientation, motion.angular_velocity, longest)
            if isinstance(motion, TorqueFree) else None)
        self._previous = None       # last unsigned quaternion, and its sign
        self._previous_sign = 1.0

    def truth(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(q, w)`` at the times ``t`` that follow the previous call's."""
        motion = self._motion
        if isinstance(motion, Coning):
            return coning_truth(motion.half_angle, motion.frequency, t)
        if self._torque_free is not None:
            return self._torque_free.truth(t)
        if isinstance(motion, ConstantRate):
            q, w = _constant_rate_unsigned(motion.orientation, motion.angular_velocity, t)
        else:
            assert isinstance(motion, EulerSweep)
            q, w = _euler_sweep_unsigned(motion.sequence, motion.start, motion.end,
                                         self._duration, t)
        q, self._previous, self._previous_sign = _continue_signs(
            q, self._previous, self._previous_sign)
        return q, w
