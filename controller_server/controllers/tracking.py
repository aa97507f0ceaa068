"""Tracking controller with support constraint (Macchietto 2008 baseline).

Per tick:

1. tracking objective toward a fixed reference pose (eq. 5.3–5.4) over
   ``x = q̈``: all joints, plus the root orientation toward upright;
2. support-acceleration equality for the feet whose contact flag is set
   (eq. 5.1), solved with the closed-form KKT of Appendix D;
3. floating-base inverse dynamics (eq. 4.2) with contact forces distributed
   in friction cones and torques within limits.

It tracks but does not balance: no momentum objective (those arrive with
the momentum-based controller).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from controller_server.constraints import compute_support_equalities
from controller_server.controllers.base import ControlInput, Controller, ControlOutput, ParamSpec
from controller_server.dynamics import compute_dynamics_terms
from controller_server.errors import InvalidParams
from controller_server.features import compute_tracking_objective
from controller_server.inverse_dynamics import solve_inverse_dynamics
from controller_server.models import RobotModel
from controller_server.solvers import build_weighted_problem, solve_weighted_kkt

__all__ = ["TrackingController"]


class TrackingController(Controller):
    """PD + feed-forward tracking under the support constraint, then inverse dynamics."""

    name = "tracking"
    PARAMETERS: ClassVar[dict[str, ParamSpec]] = {
        "stiffness": ParamSpec(100.0, minimum=0.0, maximum=1e5, doc="k_s of eq. 5.3 (1/s²)"),
        "damping": ParamSpec(20.0, minimum=0.0, maximum=1e4, doc="k_d of eq. 5.3 (1/s)"),
        "weight_joints": ParamSpec(1.0, minimum=0.0, maximum=1e6, doc="W_t² on joint DoFs (1)"),
        "weight_root_orientation": ParamSpec(
            1.0, minimum=0.0, maximum=1e6, doc="W_t² on the root orientation DoFs (1)"
        ),
        "reference_joint_position": ParamSpec(
            None, kind="vector", doc="reference pose, wire joint order (rad; ball: xyzw)"
        ),
        "reference_base_orientation_xyzw": ParamSpec(
            [0.0, 0.0, 0.0, 1.0],
            kind="vector",
            minimum=-1.0,
            maximum=1.0,
            doc="reference root orientation in world, scalar last",
        ),
        "regularization": ParamSpec(
            1e-6, minimum=1e-12, maximum=1.0, doc="ε on ‖q̈‖² in the KKT solve (1)"
        ),
        "force_regularization": ParamSpec(
            1e-6,
            minimum=1e-12,
            maximum=1.0,
            doc="ε on ‖f‖² when the cones cannot balance exactly (1/N²)",
        ),
        "qp_solver": ParamSpec(
            "daqp",
            kind="choice",
            choices=("daqp", "quadprog", "proxqp"),
            doc="QP solver for contact forces (via qpsolvers)",
        ),
    }

    def __init__(self, robot: RobotModel, params: Mapping[str, Any] | None = None):
        self._data = robot.model.createData()
        super().__init__(robot, params)

    def default_value(self, key: str) -> Any:
        """Reference pose defaults to the model's neutral (standing) pose."""
        if key == "reference_joint_position":
            return pin.neutral(self.robot.model)[7:]
        return super().default_value(key)

    def _validate(self, key: str, value: Any) -> Any:
        array = super()._validate(key, value)
        if key.startswith("reference"):
            # Quaternions (root and ball joints) are normalised through Pinocchio.
            q = pin.neutral(self.robot.model)
            if key == "reference_joint_position":
                q[7:] = array
            else:
                q[3:7] = array
            if np.linalg.norm(q[3:7]) < 1e-9:
                raise InvalidParams(f"params.{key}", "quaternion must be non-zero")
            pin.normalize(self.robot.model, q)
            array = q[7:] if key == "reference_joint_position" else q[3:7]
        return array

    def compute(self, control_input: ControlInput) -> ControlOutput:
        """One tick: KKT-solved tracking under support, then inverse dynamics."""
        p = self._params
        model = self.robot.model
        q, v = control_input.q, control_input.v
        terms = compute_dynamics_terms(self.robot, self._data, q, v)

        q_ref = np.concatenate(
            [q[:3], p["reference_base_orientation_xyzw"], p["reference_joint_position"]]
        )
        weight = np.concatenate(
            [
                np.zeros(3),
                np.full(3, p["weight_root_orientation"]),
                np.full(model.nv - 6, p["weight_joints"]),
            ]
        )
        zeros = np.zeros(model.nv)
        tracking = compute_tracking_objective(
            model, q, v, q_ref, zeros, zeros, p["stiffness"], p["damping"], weight
        )
        support = compute_support_equalities(terms, control_input.contact_flags)
        problem = build_weighted_problem([tracking], support, p["regularization"])
        solution = solve_weighted_kkt(problem)

        dynamics = solve_inverse_dynamics(
            terms,
            solution.x,
            control_input.contact_flags,
            [c.friction_coefficient for c in self.robot.contacts],
            self.robot.torque_limit,
            force_regularization=p["force_regularization"],
            qp_solver=p["qp_solver"],
        )
        return ControlOutput(
            acceleration=dynamics.acceleration,
            joint_torque=dynamics.joint_torque,
            contact_force_in_world=dynamics.contact_force_in_world,
            position_com_in_world=terms.position_com_in_world,
            kkt_condition_number=solution.schur_condition_number,
            root_wrench_residual=dynamics.root_wrench_residual,
            saturated_joints=dynamics.saturated_joints,
        )
