"""Desired feature accelerations: setpoint and target objectives (de Lasa et al. 2010, §3.1).

A feature ``y = f(q)`` is servoed by asking for an acceleration ``ÿ_d`` and
penalizing ``‖ÿ_d − ÿ‖²`` with ``ÿ = J q̈ + J̇ q̇`` (eq. 5). Two ways to choose
``ÿ_d``:

* setpoint (eq. 4): ``ÿ_d = k_p (y_r − y) − k_v ẏ``, with ``k_v = 2 √k_p``
  (critical damping) unless given;
* target (eq. 6–7): the acceleration at ``t = 0`` of a linear-in-time
  acceleration profile ``ÿ(t) = (1 − t/T) a + (t/T) b`` that reaches
  ``(y_T, ẏ_T)`` from ``(y_0, ẏ_0)`` in ``T``, solved per element with a
  singularity-robust (damped) pseudoinverse, so ``T → 0`` gives bounded
  accelerations instead of blowing up.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller_server.math.damped import damping_for_gain_bound

__all__ = ["critical_damping", "setpoint_acceleration", "target_acceleration"]


def critical_damping(stiffness: Any, damping_ratio: float = 1.0) -> Any:
    """``k_v = 2 ζ √k_p``: de Lasa's default ``k_v = 2 √k_p`` at ``ζ = 1`` (eq. 4).

    ``stiffness`` is a scalar (a float comes back) or per DoF (an array comes back).
    """
    damping = 2.0 * damping_ratio * np.sqrt(np.maximum(stiffness, 0.0))
    return float(damping) if np.ndim(damping) == 0 else damping


def setpoint_acceleration(
    reference: np.ndarray,
    value: np.ndarray,
    rate: np.ndarray,
    stiffness: float,
    damping: float,
) -> np.ndarray:
    """``ÿ_d = k_p (y_r − y) − k_v ẏ`` (eq. 4)."""
    return stiffness * (np.asarray(reference) - value) - damping * np.asarray(rate)


def target_acceleration(
    value: np.ndarray,
    rate: np.ndarray,
    target_value: np.ndarray,
    target_rate: np.ndarray,
    duration_s: float,
    gain_bound: float = 1e3,
) -> np.ndarray:
    """``ÿ_d(0) = a`` of the boundary-value problem of eq. 6–7, element by element.

    ``[[T²/3, T²/6], [T/2, T/2]] [a, b]ᵀ = [y_T − y_0 − ẏ_0 T, ẏ_T + ẏ_0]ᵀ``
    is solved by damped least squares (Maciejewski 1990, eq. 15–16) with the
    damping chosen so that ``‖[a, b]‖ ≤ B ‖rhs‖`` (``B = gain_bound``, in
    1/s² per m): exact for ``T`` well above ``1/√B``, bounded and continuous
    as ``T → 0``.

    Note:
        Eq. 7's second row as printed, ``ẏ_T + ẏ_0``, integrates eq. 6 to
        ``ẏ_T = ẏ_0 + T (a + b)/2``; its right-hand side must then be
        ``ẏ_T − ẏ_0``. We use the difference, which is what reaches the target
        velocity (a test integrates the profile and checks it).

    Args:
        value: ``y_0``, current feature value.
        rate: ``ẏ_0``.
        target_value: ``y_T``.
        target_rate: ``ẏ_T``.
        duration_s: ``T ≥ 0`` (s).
        gain_bound: ``B``.

    Returns:
        ``ÿ_d(0)``, same shape as ``value``.
    """
    T = max(float(duration_s), 0.0)
    system = np.array([[T * T / 3.0, T * T / 6.0], [T / 2.0, T / 2.0]])
    y0, v0 = np.asarray(value, dtype=float), np.asarray(rate, dtype=float)
    rhs = np.stack([np.asarray(target_value) - y0 - v0 * T, np.asarray(target_rate) - v0]).reshape(
        2, -1
    )
    U, sigma, Vt = np.linalg.svd(system)
    damping = damping_for_gain_bound(float(sigma[-1]), gain_bound)
    gains = sigma / (sigma**2 + damping**2) if sigma[0] > 0 else np.zeros(2)
    coefficients = Vt.T @ (gains[:, None] * (U.T @ rhs))  # rows: a, b
    return coefficients[0].reshape(np.shape(value))
