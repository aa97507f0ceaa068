"""``com`` and ``com_height``: the CM over the support and at its height (de Lasa et al. 2010).

Both are rows of one desired linear momentum rate (:func:`desired_com_rate`, computed once a
tick): ``com`` its horizontal axes (Table 1, ``E_com∥``), ``com_height`` its vertical one
(``E_com⊥``: a target objective, eq. 6–7, while a new height is reached; eq. 4 otherwise).
Two tasks of one class (:class:`ComTask`), so that each has its own weight and priority.
"""

from __future__ import annotations

import numpy as np

from controller_server.balance_points import admissible_cop_polygon
from controller_server.features import (
    Objective,
    admissible_linear_momentum_rate,
    compute_linear_momentum_objective,
)
from controller_server.features.linear_momentum import HORIZONTAL
from controller_server.features.setpoint import critical_damping, setpoint_acceleration
from controller_server.tasks.height_target import HeightTarget
from controller_server.tasks.task import Task, Tick

__all__ = ["VERTICAL", "ComTask", "desired_com_rate"]

VERTICAL = slice(2, 3)
"""The vertical axis: ``com_height``'s rows."""


def desired_com_rate(tick: Tick, height: HeightTarget) -> np.ndarray | None:
    """``ṗ_d`` (N): the CM toward the support centroid plus ``com_offset_xy``, at its height.

    Horizontally an eq. 4 setpoint (``com_stiffness``), or the CM acceleration a hosted
    behaviour asks (a walk's pendulum) as the offset whose setpoint asks for it, within the
    offset's range; limited to what the ground can give with the COP ``cop_margin`` inside
    the feet (as the weighted controller's ``L̇_des``); vertically ``height``'s ``z̈_d``.
    ``None`` without support. Reported as ``linear_momentum_rate``; computed once a tick.
    """
    if "com_rate" in tick.shared:
        return tick.shared["com_rate"]
    p, terms, loaded = tick.params, tick.terms, tick.loaded
    momentum, mass = terms.momentum, terms.total_mass
    desired: np.ndarray | None = None
    if loaded is not None and loaded.support_positions.shape[0]:
        com = terms.position_com_in_world
        com_velocity = momentum.linear_momentum / mass
        centroid = loaded.support_positions[:, :2].mean(axis=0)
        stiffness = p["com_stiffness"]
        damping = critical_damping(stiffness, p["damping_ratio"])
        offset = p["com_offset_xy"]
        asked = None if tick.targets is None else tick.targets.com_acceleration_xy
        if asked is not None and stiffness > 0.0:
            offset = np.clip(
                com[:2] + (asked + damping * com_velocity[:2]) / stiffness - centroid,
                -10.0,
                10.0,
            )
        desired_xy = setpoint_acceleration(
            centroid + offset, com[:2], com_velocity[:2], stiffness, damping
        )
        # Ask only what the ground can give without turning the body: otherwise `com` takes
        # all of the COP's authority and the angular momentum objective below it has none
        # left (a 220 N head push then fells the robot).
        desired = admissible_linear_momentum_rate(
            mass * np.array([*desired_xy, 0.0]),
            mass,
            com,
            admissible_cop_polygon(loaded.support_polygon, p["cop_margin"]),
            p["ground_height"],
            tick.gravity,
            friction_coefficient=loaded.smallest_friction_coefficient,
        )
        desired[2] = mass * height.acceleration(tick.time_s, com, com_velocity, p)
    tick.shared["com_rate"] = desired
    tick.reports["linear_momentum_rate"] = np.full(3, np.nan) if desired is None else desired
    return desired


class ComTask(Task):
    """Rows of the CM's acceleration on ``axes`` toward :func:`desired_com_rate`.

    ``com``: x and y (Table 1, ``E_com∥``); ``com_height``: z (``E_com⊥``; eq. 6–7 on a
    change of ``com_height``). The two share ``height`` and the tick's desired rate.
    """

    def __init__(self, height: HeightTarget, name: str = "com", axes: slice = HORIZONTAL):
        super().__init__(name)
        self.height = height
        self.axes = axes

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows ``R / m_T`` toward ``ṗ_d`` on the task's axes; none without support."""
        desired = desired_com_rate(tick, self.height)
        if desired is None:
            return None
        terms = tick.terms
        return compute_linear_momentum_objective(
            terms.momentum, terms.total_mass, desired, weight, axes=self.axes, name=self.name
        )
