"""
Angular velocity: derivatives, Euler rates, finite differences, slerp, attitude integration.

Pure numpy + numba, built on :mod:`rotation_node.conversions`; no rclpy import. Every function
takes array_like input with any leading dimensions (broadcast between arguments), never
modifies it, and raises ``ValueError`` naming the argument (and the sample) on bad input: a
wrong shape, NaN/Inf, a zero quaternion, ``det(R) <= 0``, a bad ``seq`` or ``method``, a
``frame`` other than ``'body'`` or ``'world'``, times not strictly increasing.

Conventions (``docs/numerics.md``): quaternions ``(x, y, z, w)``, scalar last, Hamilton
product; ``R`` maps body to world coordinates; angular velocity in rad/s, either body ``w_b``
or world ``w_w = R w_b``, with

    Rdot = R [w_b]x = [w_w]x R,        qdot = 1/2 q (x) (w_b, 0) = 1/2 (w_w, 0) (x) q.

The textbook ``dq_v/dt = 1/2 (q_s w - q_v x w)`` is the WORLD-frame formula although it is
labelled body, and its ``Omega = Rdot R^T`` is ``[w_w]x``.
"""
from ._derivatives import (
    angular_velocity_from_matrix_derivative, angular_velocity_from_quaternion_derivative,
    matrix_derivative, quaternion_derivative)
from ._euler_rates import (
    angular_velocity_from_euler_rates, DEFAULT_SINGULARITY_THRESHOLD,
    euler_rates_from_angular_velocity, EulerSingularityWarning)
from ._finite_difference import angular_velocity_from_quaternions, slerp
from ._integration import integrate_angular_velocity, INTEGRATION_METHODS

__all__ = [
    'DEFAULT_SINGULARITY_THRESHOLD', 'EulerSingularityWarning', 'INTEGRATION_METHODS',
    'angular_velocity_from_euler_rates', 'angular_velocity_from_matrix_derivative',
    'angular_velocity_from_quaternion_derivative', 'angular_velocity_from_quaternions',
    'euler_rates_from_angular_velocity', 'integrate_angular_velocity', 'matrix_derivative',
    'quaternion_derivative', 'slerp',
]
