"""Soft point-acceleration objectives: drag points of the body around.

Macchietto 2008, eq. 6.1–6.3 and App. C::

    p̈_des = k_s (p_des − p) + k_d (ṗ_des − ṗ)
    C_p   = ‖p̈_des − (Q q̈ + q_bias)‖²

``Q`` and ``q_bias`` are the point's Jacobian and drift
(:func:`controller_server.dynamics.point_kinematics`). Targets are added,
moved and removed at run time through the controller's ``point:<name>``
parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller_server.dynamics import PointKinematics
from controller_server.features.objective import Objective

__all__ = ["PointTarget", "compute_point_objective"]


@dataclass(frozen=True)
class PointTarget:
    """Where one point of one frame should go.

    Attributes:
        frame: Model frame name the point is fixed to.
        offset_in_frame: Point in that frame (m).
        target_position_in_world: ``p_des`` (m).
        target_velocity_in_world: ``ṗ_des`` (m/s).
        stiffness: ``k_s`` (1/s²).
        damping: ``k_d`` (1/s).
        weight: Objective weight.
    """

    frame: str
    offset_in_frame: np.ndarray
    target_position_in_world: np.ndarray
    target_velocity_in_world: np.ndarray
    stiffness: float
    damping: float
    weight: float


def compute_point_objective(name: str, target: PointTarget, point: PointKinematics) -> Objective:
    """Rows ``Q`` and ``p̈_des − q_bias`` (eq. 6.1–6.3) for one point."""
    position, velocity = point.position_in_world[0], point.velocity_in_world[0]
    acceleration_desired = target.stiffness * (
        target.target_position_in_world - position
    ) + target.damping * (target.target_velocity_in_world - velocity)
    return Objective(
        f"point:{name}",
        point.jacobian,
        acceleration_desired - point.drift,
        np.full(3, target.weight),
    )
