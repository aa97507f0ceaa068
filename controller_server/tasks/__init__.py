"""Tasks: each objective of the papers as an object, and the stack both controllers solve.

A :class:`Task` owns where its reference comes from and its rows over one block of the
unknowns; a :class:`TaskStack` holds tasks by name with a weight and a priority level.
The weighted controller (Macchietto 2008) sums its stack's rows; the prioritized
controller (de Lasa et al. 2010) solves them level by level. Adding an objective is one
module here and one line in a controller's stack (its ``TASKS``).
"""

from controller_server.tasks.angular_momentum import (
    AngularMomentumTask,
    CopWeightedAngularMomentumTask,
)
from controller_server.tasks.com import VERTICAL, ComTask, desired_com_rate
from controller_server.tasks.contact import ContactTask
from controller_server.tasks.feet import AnkleTask, SwingTask
from controller_server.tasks.height_target import TARGET_HANDOVER_S, HeightTarget
from controller_server.tasks.linear_momentum import LinearMomentumTask
from controller_server.tasks.point import POINT_PREFIX, PointTask
from controller_server.tasks.posture import PoseTask, TrunkTask
from controller_server.tasks.stack import Slot, SolvedTask, TaskStack
from controller_server.tasks.task import LoadedPoints, Task, Tick
from controller_server.tasks.torque import TorqueTask
from controller_server.tasks.tracking import TrackingTask

__all__ = [
    "POINT_PREFIX",
    "TARGET_HANDOVER_S",
    "VERTICAL",
    "AngularMomentumTask",
    "AnkleTask",
    "ComTask",
    "ContactTask",
    "CopWeightedAngularMomentumTask",
    "HeightTarget",
    "LinearMomentumTask",
    "LoadedPoints",
    "PointTask",
    "PoseTask",
    "Slot",
    "SolvedTask",
    "SwingTask",
    "Task",
    "TaskStack",
    "Tick",
    "TorqueTask",
    "TrackingTask",
    "TrunkTask",
    "desired_com_rate",
]
