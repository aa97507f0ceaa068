"""The equations of the contact-aided right-invariant EKF, as pure functions.

Hartley, Ghaffari, Eustice, Grizzle, "Contact-aided invariant extended Kalman filtering for
robot state estimation", IJRR 39(4), 2020 (arXiv:1904.09251). The state is
``X = (R, v, p, d_1 … d_K)`` in SE_{2+K}(3) (``columns = [v, p, d_1, …]``) with IMU biases
``b = [b_g, b_a]``; the error is ``η = X̂ X⁻¹ = exp(ξ)`` and ``ζ = b̂ − b``, ordered
``[ξ_R, ξ_v, ξ_p, ζ_g, ζ_a, ξ_d1 … ξ_dK]``. :class:`~.base_estimator.BaseEstimator` keeps the
bookkeeping; the tests check these against finite differences on the group.
"""

from __future__ import annotations

import numpy as np

from controller_server.estimation.lie import sek3_adjoint, so3_gammas
from controller_server.math.spatial import skew

__all__ = [
    "error_dynamics_matrix",
    "error_transition_matrix",
    "ground_innovation",
    "kinematic_innovation",
    "propagate_mean",
]


def propagate_mean(
    rotation: np.ndarray,
    columns: np.ndarray,
    angular_velocity: np.ndarray,
    acceleration: np.ndarray,
    gravity: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """IMU dynamics integrated exactly for inputs constant over ``dt`` (Hartley 2020, propagation).

    ``R⁺ = R Γ₀(ω dt)``, ``v⁺ = v + (R Γ₁(ω dt) a + g) dt``,
    ``p⁺ = p + v dt + (R Γ₂(ω dt) a + g/2) dt²``; contact points stay.

    Args:
        rotation: ``R_WI``.
        columns: ``(2 + K, 3)``: ``v``, ``p`` of the IMU point in W, contact points.
        angular_velocity: Bias-corrected gyro ``ω`` in I (rad/s).
        acceleration: Bias-corrected specific force ``a`` in I (m/s²).
        gravity: ``g`` in W (m/s²).
        dt: Step (s).

    Returns:
        ``(R⁺, columns⁺)``.
    """
    gamma0, gamma1, gamma2 = so3_gammas(angular_velocity * dt)
    velocity, position = columns[0], columns[1]
    new_columns = columns.copy()
    new_columns[0] = velocity + (rotation @ (gamma1 @ acceleration) + gravity) * dt
    new_columns[1] = (
        position + velocity * dt + (rotation @ (gamma2 @ acceleration) + gravity / 2) * dt**2
    )
    return rotation @ gamma0, new_columns


def error_dynamics_matrix(
    rotation: np.ndarray, columns: np.ndarray, gravity: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``A`` and ``G`` of ``ξ̇ = A ξ + G w`` (Hartley 2020, with IMU biases).

    ``A``: ``∂ξ̇_v/∂ξ_R = [g]×``, ``∂ξ̇_p/∂ξ_v = I``; bias columns ``−Ad_X̂`` on ``ζ_g`` and
    ``−R̂`` in the ``ξ_v`` rows on ``ζ_a``. ``G = blkdiag(Ad_X̂, I₆)`` in the state order,
    for the noise ``w = [w_g, w_a, 0, w_bg, w_ba, w_d1 …]`` (the ``ξ_p`` slot noiseless).

    Returns:
        ``(A, G)``, both ``(15 + 3K, 15 + 3K)``.
    """
    dim = 9 + 3 * len(columns)
    adjoint = sek3_adjoint(rotation, columns)
    a_matrix = np.zeros((dim, dim))
    a_matrix[3:6, 0:3] = skew(gravity)
    a_matrix[6:9, 3:6] = np.eye(3)
    a_matrix[0:9, 9:12] = -adjoint[0:9, 0:3]
    a_matrix[15:, 9:12] = -adjoint[9:, 0:3]
    a_matrix[3:6, 12:15] = -rotation
    # G = blkdiag(Ad_X, I₆) with the group blocks around the bias slot (Ad_X[:9, 9:] = 0).
    g_matrix = np.zeros((dim, dim))
    g_matrix[0:9, 0:9] = adjoint[0:9, 0:9]
    g_matrix[15:, 0:9] = adjoint[9:, 0:9]
    g_matrix[15:, 15:] = adjoint[9:, 9:]
    g_matrix[9:15, 9:15] = np.eye(6)
    return a_matrix, g_matrix


def error_transition_matrix(a_matrix: np.ndarray, dt: float) -> np.ndarray:
    """``Φ = exp(A dt) = I + A dt + (A dt)²/2 + (A dt)³/6`` (``A`` is nilpotent: ``A⁴ = 0``).

    The chain ``ζ → ξ_R → ξ_v → ξ_p`` has three links and ``A`` no other path, so the series
    stops; without biases the right-invariant error dynamics are autonomous and this
    ``Φ`` is exact (Hartley 2020, the log-linear property).
    """
    a_dt = a_matrix * dt
    a_dt2 = a_dt @ a_dt
    return np.eye(len(a_matrix)) + a_dt + a_dt2 / 2.0 + a_dt2 @ a_dt / 6.0


def kinematic_innovation(
    rotation: np.ndarray, columns: np.ndarray, contact_slot: int, measurement: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Innovation and Jacobian of one stance contact (Hartley 2020, kinematic correction).

    The measurement ``y = Rᵀ (d − p)`` (contact point in I) is a right-invariant
    observation ``Y = X⁻¹ b``; its innovation ``z = R̂ y − (d̂ − p̂)`` obeys
    ``z = H (−ξ) + R̂ n`` to first order with ``H = [0, 0, −I, 0, 0, …, I, …]``, independent
    of the estimate.

    Args:
        rotation: ``R̂``.
        columns: ``(2 + K, 3)`` ``[v̂, p̂, d̂_1, …]``.
        contact_slot: ``i`` of ``d̂_i`` (0-based among the contacts).
        measurement: ``y`` (m), in I.

    Returns:
        ``(z, H)``: ``(3,)`` and ``(3, 15 + 3K)``.
    """
    dim = 9 + 3 * len(columns)
    h_matrix = np.zeros((3, dim))
    h_matrix[:, 6:9] = -np.eye(3)
    h_matrix[:, 15 + 3 * contact_slot : 18 + 3 * contact_slot] = np.eye(3)
    innovation = rotation @ measurement - (columns[2 + contact_slot] - columns[1])
    return innovation, h_matrix


def ground_innovation(columns: np.ndarray, contact_slot: int) -> tuple[float, np.ndarray]:
    """Innovation and Jacobian of "the stance point ``d_i`` is on the ground ``z = 0``".

    A pseudo-measurement (flat, level ground): ``z = 0 − d̂_z``. With
    ``d̂ ≈ d + ξ_R × d̂ + ξ_d`` and the true ``d_z = 0``, ``z = H (−ξ)`` to first order with
    ``H = [(d̂ × e_z)ᵀ, 0, 0, 0, 0, …, e_zᵀ, …]``: it depends on the estimate through the
    rotation column only (a point off the vertical axis tilts with the rotation error).

    Args:
        columns: ``(2 + K, 3)`` ``[v̂, p̂, d̂_1, …]``.
        contact_slot: ``i`` of ``d̂_i`` (0-based among the contacts).

    Returns:
        ``(z, H)``: a number and ``(15 + 3K,)``.
    """
    dim = 9 + 3 * len(columns)
    point = columns[2 + contact_slot]
    h_row = np.zeros(dim)
    h_row[0:3] = point[1], -point[0], 0.0  # d̂ × e_z
    h_row[17 + 3 * contact_slot] = 1.0
    return -float(point[2]), h_row
