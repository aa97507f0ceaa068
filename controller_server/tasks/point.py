"""``point:<name>``: a point-acceleration target added at run time (Macchietto 2008, eq. 6.1–3)."""

from __future__ import annotations

import dataclasses

from controller_server.dynamics import point_kinematics
from controller_server.features import Objective, PointTarget, compute_point_objective
from controller_server.tasks.task import Task, Tick

__all__ = ["POINT_PREFIX", "PointTask"]

POINT_PREFIX = "point:"
"""Prefix of a point task's name (and of its ``set_params`` key)."""


class PointTask(Task):
    """A point of a frame toward a position and velocity in world, by PD (eq. 6.1–6.3).

    Named ``point:<name>``; its weight on the stack is the target's ``weight``.
    """

    def __init__(self, name: str, target: PointTarget):
        super().__init__(POINT_PREFIX + name)
        self.target = target

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows ``Q`` toward ``p̈_des − q_bias`` of the point."""
        model, target = tick.robot.model, self.target
        if weight != target.weight:
            target = dataclasses.replace(target, weight=weight)
        point = point_kinematics(
            model, tick.data, model.getFrameId(target.frame), target.offset_in_frame[None, :]
        )
        return compute_point_objective(self.name[len(POINT_PREFIX) :], target, point)
