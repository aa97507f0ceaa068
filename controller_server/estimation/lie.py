"""SO(3) and SE_{2+K}(3) helpers for the contact-aided invariant EKF.

An element of SE_{2+K}(3) (Hartley et al. 2020, "Contact-aided invariant extended Kalman
filtering for robot state estimation", IJRR 2020, the state as a matrix Lie group;
arXiv:1904.09251) is a rotation ``R`` with ``2 + K`` vectors ``x_i`` (velocity, position,
K contact positions), the matrix ``[[R, x_1 … x_{2+K}], [0, I]]``. Its tangent vector is
``ξ = [ξ_R, ξ_1, …, ξ_{2+K}]`` (3 + 3(2 + K) numbers) and

* ``exp(ξ) = (Γ₀(ξ_R), Γ₁(ξ_R) ξ_1, …, Γ₁(ξ_R) ξ_{2+K})``,
* ``Ad_X = [[R, 0 …], [[x_i]× R, … R …]]`` (block lower triangular),

with ``Γ_m(φ) = Σ_n (φ×)ⁿ / (n + m)!`` the series of Hartley et al. 2020
(their Γ functions): ``Γ₀`` is the SO(3) exponential, ``Γ₁`` its left Jacobian.
"""

from __future__ import annotations

import math

import numpy as np

from controller_server.math.spatial import skew

__all__ = [
    "sek3_adjoint",
    "sek3_exp",
    "sek3_log",
    "so3_exp",
    "so3_gamma",
    "so3_gammas",
    "so3_log",
]

_SMALL_ANGLE = 0.1
"""Below this angle (rad) the Γ coefficients use their Taylor series (5 terms: error < 1e-17)."""


_SERIES = [[(-1) ** n / math.factorial(2 * n + k) for n in range(5)] for k in range(5)]
"""Coefficients of ``c_k(θ) = Σ_n (−θ²)ⁿ / (2n + k)!``, five terms."""
_IDENTITY = np.eye(3)
_IDENTITY.setflags(write=False)


def _even_series(theta_squared: float, first: int) -> float:
    """``c_first(θ) = Σ_{n=0}^{4} (−θ²)ⁿ / (2n + first)!`` (Horner)."""
    a0, a1, a2, a3, a4 = _SERIES[first]
    t2 = theta_squared
    return a0 + t2 * (a1 + t2 * (a2 + t2 * (a3 + t2 * a4)))


def _gamma_coefficients(phi: np.ndarray) -> tuple[float, float, float, float]:
    """``c_1 … c_4`` of the Γ series: ``Γ_m = I/m! + c_{m+1} φ× + c_{m+2} φ×²``."""
    x, y, z = phi
    t2 = float(x * x + y * y + z * z)
    if t2 < _SMALL_ANGLE * _SMALL_ANGLE:
        # The closed forms cancel catastrophically at small angles.
        return (_even_series(t2, 1), _even_series(t2, 2), _even_series(t2, 3), _even_series(t2, 4))
    theta = math.sqrt(t2)
    sin, cos = math.sin(theta), math.cos(theta)
    return (
        sin / theta,
        (1.0 - cos) / t2,
        (theta - sin) / (t2 * theta),
        (t2 + 2.0 * cos - 2.0) / (2.0 * t2 * t2),
    )


def so3_gamma(phi: np.ndarray, order: int) -> np.ndarray:
    """``Γ_m(φ) = Σ_{n≥0} (φ×)ⁿ / (n + m)!`` for ``m`` in 0, 1, 2 (Hartley et al. 2020).

    Closed forms with ``θ = |φ|``:
    ``Γ₀ = I + sin θ/θ φ× + (1 − cos θ)/θ² φ×²``,
    ``Γ₁ = I + (1 − cos θ)/θ² φ× + (θ − sin θ)/θ³ φ×²``,
    ``Γ₂ = ½ I + (θ − sin θ)/θ³ φ× + (θ² + 2 cos θ − 2)/(2 θ⁴) φ×²``.

    Args:
        phi: Rotation vector (rad), ``(3,)``.
        order: ``m``, 0, 1 or 2.

    Returns:
        The ``(3, 3)`` matrix.
    """
    c1, c2, c3, c4 = _gamma_coefficients(phi)
    phi_x = skew(phi)
    phi_x2 = phi_x @ phi_x
    if order == 0:
        return _IDENTITY + c1 * phi_x + c2 * phi_x2
    if order == 1:
        return _IDENTITY + c2 * phi_x + c3 * phi_x2
    if order == 2:
        return 0.5 * _IDENTITY + c3 * phi_x + c4 * phi_x2
    raise ValueError(f"Γ is implemented for orders 0, 1, 2, got {order=}")


def so3_gammas(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Γ₀(φ), Γ₁(φ), Γ₂(φ))`` at once (see :func:`so3_gamma`)."""
    c1, c2, c3, c4 = _gamma_coefficients(phi)
    phi_x = skew(phi)
    phi_x2 = phi_x @ phi_x
    return (
        _IDENTITY + c1 * phi_x + c2 * phi_x2,
        _IDENTITY + c2 * phi_x + c3 * phi_x2,
        0.5 * _IDENTITY + c3 * phi_x + c4 * phi_x2,
    )


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """The rotation ``exp([φ]×)`` (Rodrigues), ``Γ₀(φ)``."""
    return so3_gamma(phi, 0)


def so3_log(rotation: np.ndarray) -> np.ndarray:
    """The rotation vector ``φ`` (rad, ``|φ| ≤ π``) with ``exp([φ]×) = rotation``."""
    cos_theta = np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)
    theta = float(np.arccos(cos_theta))
    axis_sin = 0.5 * np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    )
    if theta < 1e-4:
        return axis_sin * (1.0 + theta * theta / 6.0)
    if np.pi - theta < 1e-6:
        # sin θ ≈ 0: the axis is the dominant column of (R + I) / 2 = a aᵀ.
        outer = (rotation + np.eye(3)) / 2.0
        axis = outer[:, int(np.argmax(np.diag(outer)))]
        return theta * axis / np.linalg.norm(axis)
    return theta / np.sin(theta) * axis_sin


def sek3_exp(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exponential of SE_{2+K}(3) (Hartley et al. 2020).

    Args:
        xi: Tangent vector ``[ξ_R, ξ_1, …, ξ_N]``, ``(3 + 3N,)``.

    Returns:
        ``(R, columns)``: ``Γ₀(ξ_R)`` and the ``(N, 3)`` vectors ``Γ₁(ξ_R) ξ_i``.
    """
    xi_rotation = xi[:3]
    left_jacobian = so3_gamma(xi_rotation, 1)
    columns = xi[3:].reshape(-1, 3) @ left_jacobian.T
    return so3_gamma(xi_rotation, 0), columns


def sek3_adjoint(rotation: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Adjoint matrix of ``X = (R, x_1 … x_N)`` (Hartley et al. 2020).

    ``Ad_X = [[R, 0, …, 0], [[x_1]× R, R, …], …, [[x_N]× R, 0, …, R]]``, so that
    ``X exp(ξ) X⁻¹ = exp(Ad_X ξ)``.

    Args:
        rotation: ``R``, ``(3, 3)``.
        columns: ``(N, 3)`` vectors ``x_i``.

    Returns:
        The ``(3 + 3N, 3 + 3N)`` matrix.
    """
    dim = 3 + 3 * len(columns)
    adjoint = np.zeros((dim, dim))
    adjoint[:3, :3] = rotation
    for i, column in enumerate(columns):
        rows = slice(3 + 3 * i, 6 + 3 * i)
        adjoint[rows, :3] = skew(column) @ rotation
        adjoint[rows, rows] = rotation
    return adjoint


def sek3_log(rotation: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Inverse of :func:`sek3_exp`: ``[φ, Γ₁(φ)⁻¹ x_1, …]`` with ``φ = log R``."""
    phi = so3_log(rotation)
    left_jacobian = so3_gamma(phi, 1)
    return np.concatenate([phi, np.linalg.solve(left_jacobian, np.asarray(columns).T).T.ravel()])
