"""The prioritized controller's objectives and parameters (de Lasa, Mordatch & Hertzmann 2010).

:data:`OBJECTIVES` names every objective of the controller with its default priority level
and weight (eq. 16, 37); :data:`PRIORITIZED_PARAMETERS` is its ``set_params`` table: each
objective's ``priority_`` and ``weight_``, gains and references, the behaviours it hosts, the
contacts, and the solver's settings.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from controller_server.behaviors import behavior_parameters
from controller_server.controllers.base import CONTACT_PARAMETERS, KERNEL_PARAMETERS, ParamSpec
from controller_server.controllers.prioritized_layout import DEFAULT_LIMIT_HORIZON_S
from controller_server.solvers.prioritized import QP_TIME_BUDGET_S
from controller_server.tasks import (
    VERTICAL,
    AngularMomentumTask,
    AnkleTask,
    ComTask,
    ContactTask,
    HeightTarget,
    PoseTask,
    SwingTask,
    Task,
    TorqueTask,
    TrunkTask,
)

__all__ = ["OBJECTIVES", "PRIORITIZED_PARAMETERS", "TaskEntry"]


class TaskEntry(NamedTuple):
    """One task of the prioritized controller: default level and weight α, role, factory."""

    level: int
    weight: float
    role: str
    make: Callable[[HeightTarget], Task]


OBJECTIVES: dict[str, TaskEntry] = {
    "contact": TaskEntry(
        1, 1.0, "sole points toward the ground (Table 1)", lambda height: ContactTask()
    ),
    "com": TaskEntry(
        2,
        10.0,
        "CM over the centroid of the support points (Table 1, E_com∥)",
        ComTask,
    ),
    "com_height": TaskEntry(
        3,
        1.0,
        "CM height (Table 1, E_com⊥: priority 2)",
        lambda height: ComTask(height, "com_height", VERTICAL),
    ),
    "angular_momentum": TaskEntry(
        2,
        10.0,
        "L̇_d = k_p (L_r − L) (eq. 8–9; Table 1: priority 3)",
        lambda height: AngularMomentumTask(),
    ),
    "pose": TaskEntry(
        2,
        1.0,
        "rest pose of the joints (§4, E_pose; Table 1: priority 3)",
        lambda height: PoseTask(),
    ),
    "trunk": TaskEntry(
        2,
        1.0,
        "root (pelvis) orientation upright (cf. E_trunk of Table 2)",
        lambda height: TrunkTask(),
    ),
    "ankle": TaskEntry(
        2,
        0.0,
        "each foot at its take-off offset from the CM in a jump's flight (E_ankle, §5)",
        lambda height: AnkleTask(),
    ),
    "swing": TaskEntry(
        2,
        10.0,
        "a walk's swing foot toward its foothold, lifted by the step height (E_swing, §6.1)",
        lambda height: SwingTask(),
    ),
    "torque": TaskEntry(
        3, 1.0, "minimum torque on `torque_selection` (eq. 15)", lambda height: TorqueTask()
    ),
}
"""The controller's tasks in stack order (the order their rows are stacked in a level).

Each one registration: its default priority and weight (the ``priority_<name>`` and
``weight_<name>`` parameters) and how to make it, given the CM-height target the ``com``
tasks share.

Table 1's order (contact; CM and CM height; angular momentum and rest
pose) is one ``set_params`` away, but it is not the default, because the
thesis humanoid falls under the thesis pushes with it (measured, see
docs/control.md): a CM objective strictly above the angular momentum takes all of
the centre of pressure's authority to stop the CM, and the body pitches
with nothing left to damp its rotation; and the CM height of a body
standing on straight knees is a singular feature that, ranked above the
rest pose, folds the legs. So the centroidal momentum (linear and angular,
driven by the same ground wrench) is one level, weighted as the weighted
controller weights it (α = 10 each against 1 for the pose), under the
contacts; the CM height ranks below it.

With these defaults ``pose`` uses every joint's freedom at level 2, so the
level-3 objectives (``com_height``, ``torque``) have none left and do
nothing: rank them at 2 (or ``pose`` at 3) to use them.
"""


def _priority_spec(name: str) -> ParamSpec:
    default, role = OBJECTIVES[name].level, OBJECTIVES[name].role
    return ParamSpec(
        default, kind="int", minimum=1, maximum=10, doc=f"priority level of `{name}`: {role}"
    )


def _weight_spec(name: str) -> ParamSpec:
    return ParamSpec(
        OBJECTIVES[name].weight,
        minimum=0.0,
        maximum=1e6,
        doc=f"weight of `{name}` within its level: α of eq. 16 (rows × √α); 0 = off",
    )


PRIORITIZED_PARAMETERS: dict[str, ParamSpec] = {
    **{f"priority_{name}": _priority_spec(name) for name in OBJECTIVES},
    **{f"weight_{name}": _weight_spec(name) for name in OBJECTIVES},
    "contact_stiffness": ParamSpec(
        100.0, minimum=0.0, maximum=1e6, doc="k_p of the contact setpoints (1/s²)"
    ),
    "com_stiffness": ParamSpec(20.0, minimum=0.0, maximum=1e6, doc="k_p of `com` (1/s²)"),
    "com_offset_xy": ParamSpec(
        [0.0, 0.0],
        kind="vector",
        minimum=-10.0,
        maximum=10.0,
        doc="y_r of `com` minus the centroid of the support points, x and y (m)",
    ),
    "cop_margin": ParamSpec(
        0.02,
        minimum=0.0,
        maximum=1.0,
        doc="`com` asks at most the CM acceleration whose COP stays this far inside "
        "the support polygon (m; at most a quarter of the polygon's width)",
    ),
    "com_height": ParamSpec(
        None,
        minimum=0.0,
        maximum=100.0,
        doc="y_r of `com_height` above the ground (m); default the standing pose's",
    ),
    "com_height_stiffness": ParamSpec(
        20.0, minimum=0.0, maximum=1e6, doc="k_p of `com_height` (1/s²)"
    ),
    "com_height_velocity": ParamSpec(
        0.0,
        minimum=-10.0,
        maximum=10.0,
        doc="ẏ_T of the target objective that reaches a new `com_height` (m/s; eq. 7), "
        "held after T (a jump's take-off speed); 0: the height is held",
    ),
    "com_height_duration_s": ParamSpec(
        0.5,
        minimum=0.0,
        maximum=100.0,
        doc="T of the target objective (eq. 6–7) that reaches a new `com_height` (s)",
    ),
    "angular_momentum_stiffness": ParamSpec(
        10.0, minimum=0.0, maximum=1e6, doc="k_p of eq. 9 (1/s)"
    ),
    "reference_angular_momentum": ParamSpec(
        [0.0, 0.0, 0.0],
        kind="vector",
        minimum=-1e4,
        maximum=1e4,
        doc="L_r of eq. 9 about the CM, world axes (kg·m²/s); 0 damps rotation",
    ),
    "pose_stiffness": ParamSpec(30.0, minimum=0.0, maximum=1e6, doc="k_p of `pose` (1/s²)"),
    "reference_joint_position": ParamSpec(
        None,
        kind="vector",
        minimum=-1e3,
        maximum=1e3,
        doc="rest pose q_r, wire joint order (rad; ball: xyzw); default the standing pose's",
    ),
    "trunk_stiffness": ParamSpec(30.0, minimum=0.0, maximum=1e6, doc="k_p of `trunk` (1/s²)"),
    "reference_trunk_orientation_xyzw": ParamSpec(
        [0.0, 0.0, 0.0, 1.0],
        kind="vector",
        minimum=-1.0,
        maximum=1.0,
        doc="y_r of `trunk`: root orientation in world, scalar last; default the standing pose's",
    ),
    "torque_selection": ParamSpec(
        None,
        kind="vector",
        minimum=0.0,
        maximum=1e6,
        doc="diagonal of S in eq. 15 per joint DoF, wire order; default all 0 (off)",
    ),
    "ankle_stiffness": ParamSpec(100.0, minimum=0.0, maximum=1e6, doc="k_p of `ankle` (1/s²)"),
    **behavior_parameters("prioritized"),
    "damping_ratio": ParamSpec(
        1.0, minimum=0.0, maximum=100.0, doc="ζ of every setpoint: k_v = 2 ζ √k_p (eq. 4)"
    ),
    **CONTACT_PARAMETERS,
    "kernel": ParamSpec(
        "python",
        kind="choice",
        choices=KERNEL_PARAMETERS["kernel"].choices,
        doc="the compiled core (here: the dynamics terms and the IMU path's estimator; the "
        "rest of the tick is issue 36's) or the Python specification; python by default "
        "until the tick is compiled: the revolute humanoid's MuJoCo walk from the exact "
        "crouch stumbles with the compiled terms (CHANGELOG, known limitations)",
    ),
    "non_penetration": ParamSpec(
        True, kind="bool", doc="enforce eq. 26 at the points carrying force"
    ),
    "contact_distance": ParamSpec(
        0.005,
        minimum=0.0,
        maximum=1.0,
        doc="sole points of a contact `support_mask` allows carry force when this close "
        "to the ground, whatever the contact flags (m)",
    ),
    "joint_limit_horizon_s": ParamSpec(
        DEFAULT_LIMIT_HORIZON_S,
        minimum=0.005,
        maximum=10.0,
        doc="T of the joint-limit inequalities: no 1-DoF joint may reach past a limit "
        "within T at its planned acceleration (eq. 27, velocity-aware) (s)",
    ),
    "gain_bound": ParamSpec(
        1e4,
        minimum=10.0,
        maximum=1e12,
        doc="B of Algorithm 1 below the equations of motion, on levels scaled to unit "
        "norm: σ < 1/B is singular, damped steps ‖w‖ ≤ B ‖b̄‖ (Maciejewski eq. 18)",
    ),
    "qp_solver": ParamSpec(
        "daqp",
        kind="choice",
        choices=("daqp", "quadprog", "proxqp"),
        doc="QP solver of the constrained levels (via qpsolvers)",
    ),
    "qp_time_budget_s": ParamSpec(
        QP_TIME_BUDGET_S,
        minimum=0.0,
        maximum=60.0,
        doc="wall time of a tick's QP solves after which no QP is tried twice (no retry "
        "settings, no second curvature): bounds a tick on a slow machine, at the price of "
        "commands that depend on its load near the limits; a batch run that must not (a "
        "push sweep) raises it (s)",
    ),
}
"""The prioritized controller's parameters (docs/controllers.md is generated from them)."""
