"""Linear balance objective: steer the CM with the linear momentum rate.

Macchietto 2008, eq. 5.9–5.10, on the two horizontal axes only::

    L̇_des = k_s m_T (c_des − c) + k_d (L_des − L),   L_des = m_T ṡ
    C_bl  = ‖L̇_des − (R q̈ + r_bias)‖²

``c_des`` is a user offset from ``s``, the centre of the supporting feet. The
thesis prints ``− k_d (L_des − L)``; that sign would pump momentum in, so the
damping sign (as in eq. 6.1) is used. Rows are divided by ``m_T`` so the
weight is comparable across robots (the rows are then CM accelerations, m/s²).
"""

from __future__ import annotations

import numpy as np

from controller_server.features.objective import Objective
from controller_server.momentum import MomentumRates

__all__ = ["compute_linear_momentum_objective", "desired_linear_momentum_rate"]

HORIZONTAL = slice(0, 2)


def desired_linear_momentum_rate(
    momentum: MomentumRates,
    total_mass: float,
    position_com_in_world: np.ndarray,
    position_com_desired_in_world: np.ndarray,
    velocity_support_center_in_world: np.ndarray,
    stiffness: float,
    damping: float,
) -> np.ndarray:
    """``L̇_des`` (N) on x and y (eq. 5.9 with the damping sign); z is NaN (not controlled)."""
    desired = np.full(3, np.nan)
    desired[HORIZONTAL] = (
        stiffness * total_mass * (position_com_desired_in_world - position_com_in_world)[HORIZONTAL]
        + damping
        * (total_mass * velocity_support_center_in_world - momentum.linear_momentum)[HORIZONTAL]
    )
    return desired


def compute_linear_momentum_objective(
    momentum: MomentumRates, total_mass: float, desired_rate: np.ndarray, weight: float
) -> Objective:
    """Rows ``R_xy / m_T`` and ``(L̇_des − r_bias)_xy / m_T`` with weight β_bl (eq. 5.10)."""
    return Objective(
        "linear_momentum",
        momentum.R[HORIZONTAL] / total_mass,
        (desired_rate - momentum.r_bias)[HORIZONTAL] / total_mass,
        np.full(2, weight),
    )
