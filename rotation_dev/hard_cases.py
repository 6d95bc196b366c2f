"""
The hard-case corpus of ``docs/numerics.md``, shared by the tests, benchmarks and the study.

Every generator takes a seeded ``numpy.random.Generator`` and returns float64
arrays; the same seed gives the same corpus. Quaternions are (x, y, z, w).

- rotation angles 0 and 10^U(-16, -1); pi minus the same; pi exactly;
- quaternions scaled by 1e-160, 1e+160 and 1 +- 1e-6; ``q`` and ``-q`` with w = 0;
- rotation matrices: the above, plus diag(1, -1, -1) and its permutations;
- Euler angles whose middle angle is its singular value +- 10^U(-16, -2), or exactly it;
- noisy matrices ``R + sigma N`` with sigma from 1e-16 to 1e-1.
"""
import numpy as np
from rotation_node.conversions import matrix_from_quaternion, parse_sequence


def unit_vectors(rng, n):
    """Uniformly distributed unit vectors, shape (n, 3)."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def hard_angles(rng, n):
    """
    Rotation angles near 0 and near pi, shape (n,).

    A quarter each: 10^U(-16, -1); pi - 10^U(-16, -1); and, in the last
    quarter, exactly 0 and exactly float(pi) alternately.
    """
    k = n // 4
    small = 10.0 ** rng.uniform(-16, -1, k)
    near_pi = np.pi - 10.0 ** rng.uniform(-16, -1, k)
    exact = np.where(np.arange(n - 3 * k) % 2 == 0, 0.0, np.pi)
    uniform = rng.uniform(0, np.pi, k)
    return np.concatenate([small, near_pi, uniform, exact])


def hard_rotation_vectors(rng, n):
    """Rotation vectors ``angle * axis`` with :func:`hard_angles`, shape (n, 3)."""
    return unit_vectors(rng, n) * hard_angles(rng, n)[:, None]


def hard_quaternions(rng, n):
    """
    Quaternions that are hard to convert, shape (n, 4); not all of unit norm.

    Rotations by hard angles, each scaled by one of 1, 1e-160, 1e+160,
    1 + 1e-6, 1 - 1e-6 and a random sign; plus rotations by pi (w = 0
    exactly) about random and coordinate axes, in both signs.
    """
    m = n - n // 8
    angle = hard_angles(rng, m)
    axis = unit_vectors(rng, m)
    q = np.concatenate([axis * np.sin(angle / 2)[:, None], np.cos(angle / 2)[:, None]], axis=1)
    scale = rng.choice([1.0, 1e-160, 1e160, 1 + 1e-6, 1 - 1e-6], m) * rng.choice([-1.0, 1.0], m)
    w0 = np.zeros((n - m, 4))
    w0[:, :3] = unit_vectors(rng, n - m)
    w0[::3, :3] = np.eye(3)[rng.integers(0, 3, len(w0[::3]))]
    w0 *= rng.choice([-1.0, 1.0], (n - m, 1))
    return np.concatenate([q * scale[:, None], w0])


def diagonal_rotations():
    """Return the rotations by pi about the coordinate axes, as matrices, shape (3, 3, 3)."""
    return np.array([np.diag(d) for d in ((1.0, -1, -1), (-1.0, 1, -1), (-1.0, -1, 1))])


def hard_matrices(rng, n):
    """
    Rotation matrices of :func:`hard_quaternions` plus the diagonal rotations by pi.

    Returns
    -------
    ndarray, shape (n + 3, 3, 3)
        Orthonormal to rounding (as computed in float64).

    """
    return np.concatenate([matrix_from_quaternion(hard_quaternions(rng, n)), diagonal_rotations()])


def noisy_matrices(rng, n, sigma):
    """
    Rotation matrices plus Gaussian noise ``R + sigma N``, shape (n, 3, 3).

    Returns the noisy matrices and the rotations they were made from.
    """
    q = rng.normal(size=(n, 4))
    rotations = matrix_from_quaternion(q)
    return rotations + sigma * rng.normal(size=(n, 3, 3)), rotations


def near_gimbal_lock_angles(rng, n, seq):
    """
    Euler angles of ``seq`` with the middle angle at or near its singular value.

    The middle angle is a singular value (+-pi/2 for Tait-Bryan; 0 or pi for
    proper Euler) plus a signed offset of 10^U(-16, -2), with exactly 0 offset
    for every eighth sample; the outer angles are uniform in (-pi, pi).

    Returns
    -------
    ndarray, shape (n, 3)
        Angles in radians, within each convention's range of the middle angle.

    """
    proper = parse_sequence(seq).proper
    offset = 10.0 ** rng.uniform(-16, -2, n)
    offset[::8] = 0.0
    if proper:
        at_zero = rng.random(n) < 0.5
        middle = np.where(at_zero, offset, np.pi - offset)
    else:
        sign = rng.choice([-1.0, 1.0], n)
        middle = sign * (np.pi / 2 - offset)
    outer = rng.uniform(-np.pi, np.pi, (n, 2))
    return np.stack([outer[:, 0], middle, outer[:, 1]], axis=1)
