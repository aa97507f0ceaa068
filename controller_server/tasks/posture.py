"""``trunk`` and ``pose``: the root upright and the joints at rest (de Lasa et al. 2010, §4).

Both come from one difference of configurations (:func:`compute_posture_objectives`),
computed once a tick; each task has its own weight and priority.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from controller_server.features import Objective, compute_posture_objectives
from controller_server.tasks.task import Task, Tick

__all__ = ["PoseTask", "TrunkTask"]


def _posture(tick: Tick) -> tuple[Objective, Objective]:
    """``(trunk, pose)`` rows at unit weight, once a tick (``reference_*``, ``*_stiffness``)."""
    posture = tick.shared.get("posture")
    if posture is None:
        p = tick.params
        posture = compute_posture_objectives(
            tick.robot.model,
            tick.q,
            tick.v,
            p["reference_trunk_orientation_xyzw"],
            p["reference_joint_position"],
            p["trunk_stiffness"],
            p["pose_stiffness"],
            p["damping_ratio"],
            1.0,
            1.0,
        )
        tick.shared["posture"] = posture
    return posture


def _weighted(objective: Objective, weight: float) -> Objective:
    return dataclasses.replace(objective, weight=np.full(objective.b.shape[0], weight))


class TrunkTask(Task):
    """The root orientation toward ``reference_trunk_orientation_xyzw`` (cf. Table 2, E_trunk)."""

    def __init__(self, name: str = "trunk"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """The root orientation's rows, weight α."""
        return _weighted(_posture(tick)[0], weight)


class PoseTask(Task):
    """The joints toward ``reference_joint_position`` (§4, E_pose)."""

    def __init__(self, name: str = "pose"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """The joints' rows, weight α."""
        return _weighted(_posture(tick)[1], weight)
