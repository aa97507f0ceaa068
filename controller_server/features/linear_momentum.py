"""Linear balance objective: steer the CM with the linear momentum rate.

Macchietto 2008, eq. 5.9–5.10, on the two horizontal axes only::

    L̇_des = k_s m_T (c_des − c) + k_d (L_des − L),   L_des = m_T ṡ
    C_bl  = ‖L̇_des − (R q̈ + r_bias)‖²

``c_des`` is a user offset from ``s``, the centre of the supporting feet. The
thesis prints ``− k_d (L_des − L)``; that sign would pump momentum in, so the
damping sign (as in eq. 6.1) is used. Rows are divided by ``m_T`` so the
weight is comparable across robots (the rows are then CM accelerations, m/s²).

The thesis notes (ch. 7.1) that this objective can drive the CM "too
quickly", and a rate the ground cannot push is worse than none: with the
angular momentum held, a horizontal rate ``L̇_xy`` needs the centre of
pressure at ``p = c_xy − (c_z − h) L̇_xy / (m_T g)``, and the feet can only
put it inside their support polygon. :func:`admissible_linear_momentum_rate`
limits ``L̇_des`` to the rate whose ``p`` is the nearest point of the polygon
shrunk by a margin (the admissible rate of Lee & Goswami 2012, here a
projection in the COP plane).
"""

from __future__ import annotations

import math

import numpy as np

from controller_server.balance_points import closest_point_in_polygon
from controller_server.features.objective import Objective
from controller_server.momentum import MomentumRates

__all__ = [
    "HORIZONTAL",
    "admissible_linear_momentum_rate",
    "compute_linear_momentum_objective",
    "desired_linear_momentum_rate",
]

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


def admissible_linear_momentum_rate(
    desired_rate: np.ndarray,
    total_mass: float,
    position_com_in_world: np.ndarray,
    admissible_cop_polygon_xy: np.ndarray,
    ground_height: float,
    gravity: float = 9.81,
    friction_coefficient: float = math.inf,
) -> np.ndarray:
    """``L̇_des`` with its horizontal part limited so the ground can push it.

    The COP it needs must be in the polygon, and the horizontal force it needs
    within friction, ``|L̇_x|, |L̇_y| ≤ μ m_T g / √2`` (the pyramid inscribed in
    the cone that the inverse dynamics uses; thesis ch. 7.3: on ice the CM may
    only be steered as fast as the feet can grip).

    Args:
        desired_rate: ``L̇_des`` (N), z ignored and returned unchanged.
        total_mass: ``m_T`` (kg).
        position_com_in_world: ``c`` (m).
        admissible_cop_polygon_xy: Counter-clockwise ``(m, 2)`` polygon where
            the COP may go (the support polygon shrunk by a margin), m ≥ 1.
        ground_height: Ground plane height ``h`` (m).
        gravity: ``g`` (m/s²).
        friction_coefficient: Smallest μ of the supports.
    """
    if not gravity > 0.0 or len(admissible_cop_polygon_xy) == 0:
        return desired_rate
    lever = (position_com_in_world[2] - ground_height) / (total_mass * gravity)
    if not 0.0 < lever < math.inf:
        return desired_rate
    # Two horizontal components: scalar arithmetic beats numpy's per-call overhead here.
    com_x, com_y = float(position_com_in_world[0]), float(position_com_in_world[1])
    rate_x, rate_y, rate_z = desired_rate.tolist()
    cop = np.array([com_x - lever * rate_x, com_y - lever * rate_y])
    cop_x, cop_y = closest_point_in_polygon(cop, admissible_cop_polygon_xy).tolist()
    # Per axis, as the inverse dynamics' pyramid inscribed in the cone allows.
    grip = friction_coefficient / math.sqrt(2.0) * total_mass * gravity
    return np.array(
        [
            min(max((com_x - cop_x) / lever, -grip), grip),
            min(max((com_y - cop_y) / lever, -grip), grip),
            rate_z,
        ]
    )


def compute_linear_momentum_objective(
    momentum: MomentumRates,
    total_mass: float,
    desired_rate: np.ndarray,
    weight: float,
    axes: slice = HORIZONTAL,
    name: str = "linear_momentum",
) -> Objective:
    """Rows ``R / m_T`` and ``(L̇_des − r_bias) / m_T`` on ``axes`` with weight β_bl (eq. 5.10).

    Divided by ``m_T`` the rows are CM accelerations (m/s²): on x and y this is
    the weighted controller's C_bl and the prioritized controller's ``com``
    (de Lasa's E_com∥); on z (``axes=slice(2, 3)``) its ``com_height`` (E_com⊥).
    """
    return Objective(
        name,
        momentum.R[axes] / total_mass,
        (desired_rate - momentum.r_bias)[axes] / total_mass,
        np.full(len(range(3)[axes]), weight),
    )
