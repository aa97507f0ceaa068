"""Angular balance objective: keep the angular momentum about the CM when unstable.

Macchietto 2008, eq. 5.15–5.17::

    Ḣ_des = 0
    C_ba  = ‖Ḣ_des − (S q̈ + s_bias)‖²
    β_ba  = γ ‖p − g‖

with ``p`` the centre of pressure (eq. 3.3–3.6) and ``g`` the centroidal
moment pivot (eq. 3.9–3.10): the farther apart they are, the more the ground
is changing the angular momentum, and the harder the objective holds it.
Rows are divided by ``m_T`` like the linear objective's.

Extensions (off in these functions' defaults): ``Ḣ_des = −k_H H`` damps the
angular momentum instead of holding it (``k_H = 10`` in ``MomentumController``),
and an optional floor ``β_0`` on the weight keeps the objective alive when the
COP and CMP coincide (``β_ba = β_0 + γ ‖p − g‖``; ``β_0 = 0`` by default, so
the weight is the thesis' instability indicator alone, ``γ = 3000`` /m: about
340 at the 0.11 m of a 220 N head push, about 0 at rest). A push above the
CM leaves the body pitching; holding that angular momentum (eq. 5.15) keeps
it pitching, damping it brings it to rest (the centroidal momentum control of
Lee & Goswami 2012).
"""

from __future__ import annotations

import numpy as np

from controller_server.features.objective import Objective
from controller_server.momentum import MomentumRates

__all__ = ["angular_momentum_weight", "compute_angular_momentum_objective"]


def angular_momentum_weight(
    gain: float,
    center_of_pressure: np.ndarray,
    centroidal_moment_pivot: np.ndarray,
    floor: float = 0.0,
) -> float:
    """``β_ba = β_0 + γ ‖p − g‖`` (eq. 5.17, ``β_0 = 0``); ``β_0`` alone without ground force."""
    distance = np.linalg.norm((center_of_pressure - centroidal_moment_pivot)[:2])
    return floor + (float(gain * distance) if np.isfinite(distance) else 0.0)


def compute_angular_momentum_objective(
    momentum: MomentumRates,
    total_mass: float,
    weight: float,
    damping: float = 0.0,
    desired_rate: np.ndarray | None = None,
) -> Objective:
    """Rows ``S / m_T`` toward ``Ḣ_des``, weight β_ba (eq. 5.16).

    ``Ḣ_des = −k_H H`` (``k_H = 0``: eq. 5.15) unless ``desired_rate`` is
    given (de Lasa's ``L̇_d = k_p (L_r − L)``, eq. 8–9). Divided by ``m_T``,
    as the CM rows, so weights of the two compare.
    """
    if desired_rate is None:
        desired_rate = -damping * momentum.angular_momentum
    return Objective(
        "angular_momentum",
        momentum.S / total_mass,
        (desired_rate - momentum.s_bias) / total_mass,
        np.full(3, weight),
    )
