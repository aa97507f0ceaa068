"""Angular balance objective: keep the angular momentum about the CM when unstable.

Macchietto 2008, eq. 5.15–5.17::

    Ḣ_des = 0
    C_ba  = ‖Ḣ_des − (S q̈ + s_bias)‖²
    β_ba  = γ ‖p − g‖

with ``p`` the centre of pressure (eq. 3.3–3.6) and ``g`` the centroidal
moment pivot (eq. 3.9–3.10): the farther apart they are, the more the ground
is changing the angular momentum, and the harder the objective holds it.
Rows are divided by ``m_T`` like the linear objective's.
"""

from __future__ import annotations

import numpy as np

from controller_server.features.objective import Objective
from controller_server.momentum import MomentumRates

__all__ = ["angular_momentum_weight", "compute_angular_momentum_objective"]


def angular_momentum_weight(
    gain: float, center_of_pressure: np.ndarray, centroidal_moment_pivot: np.ndarray
) -> float:
    """``β_ba = γ ‖p − g‖`` (eq. 5.17); zero when either point is undefined (no ground force)."""
    distance = np.linalg.norm((center_of_pressure - centroidal_moment_pivot)[:2])
    return float(gain * distance) if np.isfinite(distance) else 0.0


def compute_angular_momentum_objective(
    momentum: MomentumRates, total_mass: float, weight: float
) -> Objective:
    """Rows ``S / m_T`` toward ``Ḣ_des = 0`` (eq. 5.16) with weight β_ba."""
    return Objective(
        "angular_momentum",
        momentum.S / total_mass,
        -momentum.s_bias / total_mass,
        np.full(3, weight),
    )
