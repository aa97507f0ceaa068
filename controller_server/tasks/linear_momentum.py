"""``linear_momentum``: the CM toward ``c_des`` over the supports (Macchietto 2008, eq. 5.9–10)."""

from __future__ import annotations

import numpy as np

from controller_server.balance_points import admissible_cop_polygon
from controller_server.features import (
    Objective,
    admissible_linear_momentum_rate,
    compute_linear_momentum_objective,
    desired_linear_momentum_rate,
)
from controller_server.tasks.task import Task, Tick

__all__ = ["LinearMomentumTask"]


class LinearMomentumTask(Task):
    """``L̇_des`` toward ``c_des`` = the supports' centre plus ``com_offset_xy`` (eq. 5.9).

    Moving with the supports' velocity, limited to what the ground can give with the COP
    ``cop_margin`` inside the support polygon (``momentum_stiffness``, ``momentum_damping``).
    No rows without support or at weight 0. Reports ``linear_momentum_rate``.
    """

    def __init__(self, name: str = "linear_momentum"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows ``R / m_T`` toward ``L̇_des`` on x and y; none without support or at weight 0."""
        p, terms, flags, v = tick.params, tick.terms, tick.supports, tick.v
        supporting = [index for index, on in enumerate(flags) if on]
        tick.reports["linear_momentum_rate"] = np.full(3, np.nan)
        if not supporting or weight <= 0:
            return None
        assert tick.support_polygon_xy is not None
        momentum, mass = terms.momentum, terms.total_mass
        support_jacobian = sum(terms.support_jacobians[index][:3] for index in supporting)
        support_velocity = support_jacobian @ v / len(supporting)
        com_desired = terms.position_contact_frames_in_world[supporting].sum(axis=0) / len(
            supporting
        )
        com_desired[:2] += p["com_offset_xy"]
        desired_rate = desired_linear_momentum_rate(
            momentum,
            mass,
            terms.position_com_in_world,
            com_desired,
            support_velocity,
            p["momentum_stiffness"],
            p["momentum_damping"],
        )
        desired_rate = admissible_linear_momentum_rate(
            desired_rate,
            mass,
            terms.position_com_in_world,
            admissible_cop_polygon(tick.support_polygon_xy, p["cop_margin"]),
            p["ground_height"],
            tick.gravity,
            friction_coefficient=min(
                mu for mu, on in zip(p["friction_coefficients"], flags, strict=True) if on
            ),
        )
        tick.reports["linear_momentum_rate"] = desired_rate
        return compute_linear_momentum_objective(momentum, mass, desired_rate, weight)
