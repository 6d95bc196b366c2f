"""
Ground-truth motions: orientation and body angular velocity at given times.

``q`` (n, 4) unit, body-to-world and continuous in sign (``q[k] . q[k-1] >= 0``: a sign flip
in a sensor stream comes only from the ``quaternion_sign_flips`` effect); ``w`` (n, 3) the
body angular velocity, rad/s (``q' = 1/2 q (x) (w, 0)``). ``constant_rate``, ``coning`` and
``euler_sweep`` are closed forms; ``torque_free`` integrates Euler's equations
(:mod:`._free_rigid_body`). :class:`MotionStream` computes the truth block by block, bit for
bit as :func:`motion_truth` over all samples at once.
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
    """Return ``q`` signed to continue ``previous`` (or None), and the state to continue with."""
    linked = q if previous is None else np.concatenate((previous[np.newaxis], q))
    steps = np.sign(np.einsum('ij,ij->i', linked[1:], linked[:-1]))
    steps[steps == 0] = 1.0
    signs = previous_sign * np.cumprod(steps)
    if previous is None:
        signs = np.concatenate(([1.0], signs))
    return q * signs[:, np.newaxis], q[-1].copy(), float(signs[-1])


def coning_truth(half_angle: float, frequency: float,
                 t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """
    Return ``(q (n, 4), w (n, 3))`` of classical coning at times ``t`` (s), phase 0 at t = 0.

    Half angle ``a`` (rad), cone rate ``W`` (rad/s), scalar last (docs/numerics.md):
    ``q = (sin(a/2) cos(W t), sin(a/2) sin(W t), 0, cos(a/2))``,
    ``w = (-W sin a sin(W t), W sin a cos(W t), -W (1 - cos a))``.
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

    Internal steps turn the fastest axis flow by at most ``MAX_STEP_ANGLE``: ``|I w|`` and
    ``R I w`` stay constant to round-off, the energy within ~1e-14 without drift. A spin near
    the intermediate axis amplifies round-off at every flip: the tumbling box's truth is
    reproducible to ~3e-9 rad only (docs/accuracy.md).
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


def motion_truth(motion: Motion, t: FloatArray,
                 duration: float) -> tuple[FloatArray, FloatArray]:
    """Return ``(q (n, 4), w (n, 3))`` of a scene's motion at ``t`` (s since the first sample)."""
    t = np.asarray(t, dtype=np.float64)
    return MotionStream(motion, duration, longest_interval(t)).truth(t)


class MotionStream:
    """
    The truth of a motion over consecutive blocks of samples.

    ``duration`` is the scene's (the end of an Euler sweep), ``longest`` the longest interval
    of the whole series (:func:`longest_interval`; it sets the torque-free step). Sign
    continuity and the integrator's state carry over from one ``truth(t)`` to the next.
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
        t = np.asarray(t, dtype=np.float64)
        if isinstance(motion, ConstantRate):   # q0 (x) exp(w t), exp canonical: unsigned
            w = np.broadcast_to(np.asarray(motion.angular_velocity, dtype=np.float64),
                                (t.size, 3))
            q = quaternion_product(motion.orientation,
                                   quaternion_from_rotation_vector(w * t[:, np.newaxis]))
            w = w.copy()
        else:   # constant Euler rates: their angular velocity is defined even at gimbal lock
            assert isinstance(motion, EulerSweep)   # (for mypy: __init__ admits only motions)
            start = np.asarray(motion.start, dtype=np.float64)
            rates = (np.asarray(motion.end, dtype=np.float64) - start) / self._duration
            angles = start + rates * t[:, np.newaxis]
            q = quaternion_from_euler(angles, motion.sequence)
            w = angular_velocity_from_euler_rates(angles, np.broadcast_to(rates, angles.shape),
                                                  motion.sequence, frame='body')
        q, self._previous, self._previous_sign = _continue_signs(
            q, self._previous, self._previous_sign)
        return q, w
