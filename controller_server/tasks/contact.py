"""``contact``: the sole points toward the ground (de Lasa et al. 2010, Table 1, §4)."""

from __future__ import annotations

import numpy as np

from controller_server.features import Objective, compute_ground_contact_objective
from controller_server.features.setpoint import critical_damping
from controller_server.tasks.task import Task, Tick

__all__ = ["ContactTask"]


class ContactTask(Task):
    """Each planted sole point toward its projection on the ground, by an eq. 4 setpoint.

    Rows over ``q̈`` of the points the prioritized controller's layout loads
    (:class:`~controller_server.tasks.task.LoadedPoints`); none when no point is planted.
    Parameters: ``contact_stiffness``, ``damping_ratio``, ``ground_height``.
    """

    def __init__(self, name: str = "contact"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows ``J_c`` toward ``p̈_d − J̇_c q̇`` of the planted points; none without one."""
        loaded, p = tick.loaded, tick.params
        if loaded is None or not loaded.point_jacobian.shape[0]:
            return None
        stiffness = p["contact_stiffness"]
        return compute_ground_contact_objective(
            loaded.point_jacobian,
            loaded.point_drift,
            loaded.point_positions,
            tick.v,
            p["ground_height"],
            stiffness,
            critical_damping(stiffness, p["damping_ratio"]),
            weight,
        )

    def row_basis(self, tick: Tick) -> np.ndarray | None:
        """The loaded points' rows span fewer dimensions than they are (rigid feet)."""
        assert tick.loaded is not None
        return tick.loaded.contact_row_basis()
