"""Ground contact objective: planted sole points toward the ground (de Lasa et al. 2010, §4).

Table 1's first feature, "keep feet planted": each planted point ``p`` is
servoed to its projection on the ground plane ``z = h`` by a setpoint
(eq. 4), so a foot a push lifted is brought back down::

    p̈_d = k_p (p_ground − p) − k_v ṗ,      rows  J_c q̈ = p̈_d − J̇_c q̇   (eq. 5)
"""

from __future__ import annotations

import numpy as np

from controller_server.features.objective import Objective
from controller_server.features.setpoint import setpoint_acceleration

__all__ = ["compute_ground_contact_objective"]


def compute_ground_contact_objective(
    point_jacobian: np.ndarray,
    point_drift: np.ndarray,
    position_points_in_world: np.ndarray,
    v: np.ndarray,
    ground_height: float,
    stiffness: float,
    damping: float,
    weight: float,
) -> Objective:
    """Rows ``J_c`` and ``p̈_d − J̇_c q̇`` over ``q̈``, weight α on every row.

    Args:
        point_jacobian: ``(3s, nv)`` stacked point Jacobians in world.
        point_drift: ``(3s,)`` stacked ``J̇ q̇`` of the points (m/s²).
        position_points_in_world: ``(s, 3)`` point positions (m).
        v: Generalized velocity ``(nv,)``.
        ground_height: ``h`` (m).
        stiffness: ``k_p`` (1/s²).
        damping: ``k_v`` (1/s).
        weight: α of the objective.
    """
    velocities = (point_jacobian @ v).reshape(-1, 3)
    targets = position_points_in_world.copy()
    targets[:, 2] = ground_height
    desired = setpoint_acceleration(
        targets, position_points_in_world, velocities, stiffness, damping
    ).reshape(-1)
    return Objective(
        "contact", point_jacobian, desired - point_drift, np.full(desired.size, float(weight))
    )
