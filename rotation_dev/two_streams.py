"""
Two orientation streams of one synthetic motion with a known alignment and time offset.

Shared by the comparison tests, the ``rotation_bag compare`` tests and the
accuracy study. The truth is built with scipy (an oracle independent of the
package): a smooth random motion ``B(t) = exp(sum_k a_k sin(2 pi f_k t + p_k))``
(a rotation vector per axis, several frequencies), and

    R_ref(t) = W B(t) M (x) noise,        R_est(t) = B(t - dt) (x) noise,

so that ``R_ref(t) = W R_est(t + dt) M`` without noise. Noise is a rotation
``exp(n)`` on the body side, ``n`` Gaussian with ``noise_deg / sqrt(3)`` per
axis (``noise_deg`` is the root mean square noise angle).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass
class TwoStreams:
    """The streams and their truth (quaternions (x, y, z, w), times in seconds)."""

    t_ref: np.ndarray
    q_ref: np.ndarray
    t_est: np.ndarray
    q_est: np.ndarray
    rates_est: np.ndarray        # body angular rates of the estimate at t_est, noise-free
    world: np.ndarray            # W
    mounting: np.ndarray         # M
    time_offset: float           # dt
    noise_ref: np.ndarray        # the rotation vectors of the reference noise, per sample
    noise_est: np.ndarray


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Return a uniformly random rotation as a quaternion (x, y, z, w)."""
    return Rotation.random(random_state=rng).as_quat()


def _motion(rng, amplitude, axes):
    terms = 4
    amp = rng.uniform(0.3, 1.0, (terms, 3)) * amplitude * np.asarray(axes, dtype=float)
    freq = rng.uniform(0.05, 0.7, (terms, 3))
    phase = rng.uniform(0.0, 2.0 * np.pi, (terms, 3))

    def vector(t):
        return np.sum(amp * np.sin(2.0 * np.pi * freq * t[:, None, None] + phase), axis=1)

    def vector_rate(t):
        return np.sum(amp * 2.0 * np.pi * freq * np.cos(2.0 * np.pi * freq * t[:, None, None]
                                                        + phase), axis=1)
    return vector, vector_rate


def _body_rates(vector, vector_rate, t):
    """Body angular rate of ``exp(v(t))`` by a central difference of 1e-6 s (scipy)."""
    h = 1e-6
    before, after = Rotation.from_rotvec(vector(t - h)), Rotation.from_rotvec(vector(t + h))
    return (before.inv() * after).as_rotvec() / (2.0 * h)


def two_streams(seed: int = 0, *, duration: float = 60.0, rate_ref: float = 100.0,
                rate_est: float = 200.0, noise_ref_deg: float = 0.3,
                noise_est_deg: float = 0.3, time_offset: float = 0.0373,
                world: Optional[np.ndarray] = None, mounting: Optional[np.ndarray] = None,
                amplitude: float = 0.6, axes=(1.0, 1.0, 1.0), start: float = 0.0,
                margin: float = 1.0) -> TwoStreams:
    """
    Return two streams of one random smooth motion (see the module docstring).

    The estimate covers ``margin`` seconds more than the reference on each side.
    ``axes`` scales the motion per axis (``(0, 0, 1)``: about z only);
    ``world``, ``mounting`` default to random rotations.
    """
    rng = np.random.default_rng(seed)
    vector, vector_rate = _motion(rng, amplitude, axes)
    world = random_rotation(rng) if world is None else np.asarray(world, dtype=float)
    mounting = random_rotation(rng) if mounting is None else np.asarray(mounting, dtype=float)
    t_ref = start + np.arange(int(round(duration * rate_ref))) / rate_ref
    t_est = start - margin + np.arange(int(round((duration + 2 * margin) * rate_est))) / rate_est
    sigma_ref = np.radians(noise_ref_deg) / np.sqrt(3.0)
    sigma_est = np.radians(noise_est_deg) / np.sqrt(3.0)
    noise_ref = rng.normal(0.0, sigma_ref, (t_ref.size, 3))
    noise_est = rng.normal(0.0, sigma_est, (t_est.size, 3))
    w, m = Rotation.from_quat(world), Rotation.from_quat(mounting)
    ref = w * Rotation.from_rotvec(vector(t_ref - start)) * m * Rotation.from_rotvec(noise_ref)
    est = Rotation.from_rotvec(vector(t_est - start - time_offset)) * Rotation.from_rotvec(
        noise_est)
    return TwoStreams(t_ref, ref.as_quat(), t_est, est.as_quat(),
                      _body_rates(vector, vector_rate, t_est - start - time_offset),
                      world, mounting, time_offset, noise_ref, noise_est)
