"""``tracking``: every DoF toward a pose or a motion clip (Macchietto 2008, eq. 5.3–5.4).

The weighted controller's ``C_t``: PD tracking of a fixed reference pose, or of a motion
clip's ``q, q̇, q̈``, with each joint's gains raised as it passes a soft limit
(eq. 6.5–6.6). The root position is left to the balance objectives.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from controller_server.features import (
    JointLimitSet,
    MotionClip,
    Objective,
    compute_tracking_objective,
    default_joint_limits,
    soft_limit_gains,
)
from controller_server.models import RobotModel
from controller_server.tasks.task import Task, Tick

__all__ = ["TrackingTask"]


class TrackingTask(Task):
    """PD tracking of ``reference_*`` or of :attr:`clip` on every DoF but the root position.

    Row weights ``W_t²``: 0 on the root position, ``weight_root_orientation`` on its
    orientation, the stack's weight (β_t) times ``joint_weights`` on the joints; kept until
    the parameters change. Gains ``stiffness``, ``damping``, raised by
    ``joint_limit_stiffness`` and ``joint_limit_damping`` past a limit.

    Attributes:
        clip: The motion clip to track (``clip`` parameter), or ``None`` for the fixed pose.
    """

    uniform = False

    def __init__(self, robot: RobotModel, name: str = "tracking"):
        super().__init__(name)
        self.clip: MotionClip | None = None
        self._limits = JointLimitSet(default_joint_limits(robot), robot.model.nv)
        self._row_weights: np.ndarray | None = None
        self._weight = 0.0

    def reset(self) -> None:
        """Forget the rows' weights (the parameters changed)."""
        self._row_weights = None

    def clip_sample(
        self, time_s: float, params: Mapping[str, Any]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The clip's ``q, v, a`` at ``time_s`` (by ``clip_start_s``, ``_speed``, ``_loop``)."""
        if self.clip is None:
            return None
        sample = self.clip.sample(
            time_s,
            start_s=params["clip_start_s"],
            speed=params["clip_speed"],
            loop=params["clip_loop"],
        )
        return sample.q, sample.v, sample.a

    @property
    def joint_limits(self) -> JointLimitSet:
        """The soft joint limits whose violations ``e`` raise the gains (eq. 6.5–6.6)."""
        return self._limits

    def reference(self, tick: Tick) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q_ref, v_ref, a_ref``: the clip's sample at the tick's time, or the fixed pose."""
        p, model = tick.params, tick.robot.model
        sample = self.clip_sample(tick.time_s, p)
        if sample is not None:
            q_ref, v_ref, a_ref = sample[0].copy(), sample[1], sample[2]
        else:
            q_ref = pin.neutral(model)
            q_ref[3:7] = p["reference_base_orientation_xyzw"]
            q_ref[7:] = p["reference_joint_position"]
            v_ref = a_ref = np.zeros(model.nv)
        q_ref[:3] = tick.q[:3]  # the root position is left to the balance objectives
        return q_ref, v_ref, a_ref

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows of every DoF toward the reference (eq. 5.3), weighted ``W_t²``."""
        p, q = tick.params, tick.q
        q_ref, v_ref, a_ref = self.reference(tick)
        stiffness, damping = soft_limit_gains(
            p["stiffness"],
            p["damping"],
            p["joint_limit_stiffness"],
            p["joint_limit_damping"],
            self._limits.errors(q),
        )
        if self._row_weights is None or weight != self._weight:
            self._weight = weight
            self._row_weights = np.concatenate(
                [
                    np.zeros(3),
                    np.full(3, p["weight_root_orientation"]),
                    weight * np.asarray(p["joint_weights"]),
                ]
            )
        return compute_tracking_objective(
            tick.robot.model, q, tick.v, q_ref, v_ref, a_ref, stiffness, damping, self._row_weights
        )
