"""Momentum-based balance controller (Macchietto 2008), robust by damped least squares.

Per optimizer tick, over ``x = q̈`` (eq. 5.1)::

    min  β_t C_t + β_bl C_bl + β_ba C_ba + Σ C_p
    s.t. J_sup q̈ + J̇_sup q̇ = 0          (supporting feet keep the ground's acceleration)

* ``C_t`` tracking toward a fixed pose or a motion clip (eq. 5.3–5.4), with
  per-joint weights and gains raised by soft joint limits (eq. 6.5–6.6);
* ``C_bl`` linear momentum toward ``c_des`` over the supports (eq. 5.9–5.10);
* ``C_ba`` angular momentum damped (eq. 5.15–5.16), weight ``β_0 + γ ‖p − g‖`` (eq. 5.17),
  with the COP ``p`` and CMP ``g`` of the state's measured ground wrenches
  when the client sends them (in either ``ground_force_mode``), else of the
  previous tick's commanded wrenches (none on the first tick: ``β_0``);
* ``C_p`` soft point-acceleration targets (eq. 6.1–6.3), added at run time;

solved by the closed-form KKT of App. D with damped least squares
(Maciejewski 1990). The optimizer may run every N-th tick (thesis ch. 4:
30–200 Hz); floating-base inverse dynamics (eq. 4.2) runs every tick on the
latest accelerations, with measured or distributed ground forces.

``tracking`` is the same controller with both momentum objectives off: the
thesis' baseline, and the first ablation of ch. 7.1.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from controller_server.balance_points import (
    support_polygon,
)
from controller_server.behaviors import behavior_parameters
from controller_server.constraints import compute_support_equalities
from controller_server.controllers.base import (
    CONTACT_PARAMETERS,
    KERNEL_PARAMETERS,
    ControlInput,
    Controller,
    ControllerFailed,
    ControlOutput,
    ParamSpec,
    check_finite_dynamics,
    normalized_configuration_part,
)
from controller_server.controllers.compiled_tick import CompiledWeightedTick
from controller_server.controllers.diagnostics import weighted_diagnostics
from controller_server.controllers.point_targets import POINT_PREFIX, point_target
from controller_server.dynamics import (
    CentroidalMotion,
    DynamicsTerms,
    centroidal_motion,
    compute_contact_geometry,
)
from controller_server.errors import InvalidParams
from controller_server.features import (
    JointLimitSet,
    Objective,
    load_motion_clip,
)
from controller_server.inverse_dynamics import (
    InverseDynamicsResult,
    exact_inverse_dynamics,
    solve_inverse_dynamics,
)
from controller_server.models import RobotModel
from controller_server.solvers import KKTSolution, build_weighted_problem, solve_weighted_kkt
from controller_server.tasks import (
    CopWeightedAngularMomentumTask,
    LinearMomentumTask,
    PointTask,
    TaskStack,
    TrackingTask,
)

__all__ = ["MomentumController", "TrackingController"]


class MomentumController(Controller):
    """Macchietto's weighted momentum-based balance controller."""

    name = "momentum"
    PARAMETERS: ClassVar[dict[str, ParamSpec]] = {
        "stiffness": ParamSpec(30.0, minimum=0.0, maximum=1e5, doc="k_s of eq. 5.3 (1/s²)"),
        "damping": ParamSpec(11.0, minimum=0.0, maximum=1e4, doc="k_d of eq. 5.3 (1/s)"),
        "weight_tracking": ParamSpec(1.0, minimum=0.0, maximum=1e6, doc="β_t of eq. 5.1 (1)"),
        "joint_weights": ParamSpec(
            None,
            kind="vector",
            minimum=0.0,
            maximum=1e6,
            doc="W_t² per joint DoF, wire order (default all 1)",
        ),
        "weight_root_orientation": ParamSpec(
            1.0, minimum=0.0, maximum=1e6, doc="W_t² on the root orientation DoFs (1)"
        ),
        "reference_joint_position": ParamSpec(
            None,
            kind="vector",
            minimum=-1e3,
            maximum=1e3,
            doc="fixed reference pose, wire joint order (rad; ball: xyzw); default the "
            "standing pose's",
        ),
        "reference_base_orientation_xyzw": ParamSpec(
            [0.0, 0.0, 0.0, 1.0],
            kind="vector",
            minimum=-1.0,
            maximum=1.0,
            doc="reference root orientation in world, scalar last; default the standing pose's",
        ),
        "clip": ParamSpec(
            "",
            kind="text",
            doc="motion clip to track: built-in name or a .json file in a --model-dir ('' = pose)",
        ),
        "clip_start_s": ParamSpec(
            0.0, minimum=-1e9, maximum=1e9, doc="state time of clip start (s)"
        ),
        "clip_speed": ParamSpec(1.0, minimum=0.0, maximum=100.0, doc="playback rate (1)"),
        "clip_loop": ParamSpec(False, kind="bool", doc="repeat the clip"),
        "joint_limit_stiffness": ParamSpec(
            200.0, minimum=0.0, maximum=1e6, doc="l_s of eq. 6.5 (1/s² per rad of violation)"
        ),
        "joint_limit_damping": ParamSpec(
            20.0, minimum=0.0, maximum=1e6, doc="l_d of eq. 6.6 (1/s per rad of violation)"
        ),
        "weight_linear_momentum": ParamSpec(
            10.0, minimum=0.0, maximum=1e6, doc="β_bl of eq. 5.1 on CM-acceleration rows (1)"
        ),
        "momentum_stiffness": ParamSpec(
            20.0, minimum=0.0, maximum=1e4, doc="k_s of eq. 5.9 (1/s²)"
        ),
        "momentum_damping": ParamSpec(9.0, minimum=0.0, maximum=1e4, doc="k_d of eq. 5.9 (1/s)"),
        "com_offset_xy": ParamSpec(
            [0.0, 0.0],
            kind="vector",
            minimum=-10.0,
            maximum=10.0,
            doc="c_des − s on x, y: desired CM relative to the support centre (m)",
        ),
        "cop_margin": ParamSpec(
            0.02,
            minimum=0.0,
            maximum=1.0,
            doc="L̇_des is limited so its COP stays this far inside the support polygon (m; "
            "at most a quarter of the polygon's width)",
        ),
        "angular_momentum_gain": ParamSpec(
            3000.0,
            minimum=0.0,
            maximum=1e6,
            doc="γ of eq. 5.17 (1/m); p, g of the measured wrenches if sent, else of the last"
            " command's",
        ),
        "angular_momentum_damping": ParamSpec(
            10.0,
            minimum=0.0,
            maximum=1e4,
            doc="k_H: Ḣ_des = −k_H H instead of eq. 5.15's Ḣ_des = 0 (1/s)",
        ),
        "weight_angular_momentum": ParamSpec(
            0.0, minimum=0.0, maximum=1e6, doc="β_0 added to eq. 5.17's β_ba = γ ‖p − g‖ (1)"
        ),
        "ground_force_mode": ParamSpec(
            "distributed",
            kind="choice",
            choices=("distributed", "measured"),
            doc="inverse dynamics with distributed forces, or the state's measured wrenches",
        ),
        **CONTACT_PARAMETERS,
        **KERNEL_PARAMETERS,
        **behavior_parameters("momentum"),
        "optimizer_period_ticks": ParamSpec(
            1,
            kind="int",
            minimum=1,
            maximum=1000,
            doc="run the optimizer every N-th state; inverse dynamics runs every state",
        ),
        "objective_gain_bound": ParamSpec(
            500.0,
            minimum=1.0,
            maximum=1e9,
            doc="B of the damped objective solve (Maciejewski eq. 18); λ ≤ 1/(2B)",
        ),
        "constraint_gain_bound": ParamSpec(
            1000.0,
            minimum=1.0,
            maximum=1e9,
            doc="B of the damped constraint solve: ‖Δq̈‖_M ≤ B ‖J_sup q̈ + J̇ q̇‖",
        ),
        "force_regularization": ParamSpec(
            1e-4,
            minimum=1e-12,
            maximum=1.0,
            doc="ε on ‖f‖² when q̈ cannot be realized exactly (1/kg)",
        ),
        "support_weight": ParamSpec(
            100.0,
            minimum=0.0,
            maximum=1e6,
            doc="w_s per kg on the supports' acceleration when q̈ cannot be realized (1)",
        ),
        "qp_solver": ParamSpec(
            "quadprog",
            kind="choice",
            choices=("quadprog", "daqp", "proxqp"),
            doc="QP solver for contact forces: quadprog (Goldfarb–Idnani's dual active-set "
            "method, exact feasibility; the compiled kernel runs the same method by eiquadprog); "
            "daqp and proxqp (via qpsolvers) need kernel 'python'",
        ),
    }

    def __init__(self, robot: RobotModel, params: Mapping[str, Any] | None = None):
        self._tracking = TrackingTask(robot)
        self.tasks = TaskStack()
        """``tracking``, ``linear_momentum``, ``angular_momentum``, then the point targets."""
        self.tasks.add(self._tracking)
        self.tasks.add(LinearMomentumTask())
        self.tasks.add(CopWeightedAngularMomentumTask())
        self._ticks = 0
        self._last_solution: KKTSolution | None = None
        self._last_flags: tuple[bool, ...] | None = None
        self._last_wrenches: np.ndarray | None = None
        self._last_optimizer: dict[str, Any] = {}
        self._compiled_tick: CompiledWeightedTick | None = None  # at the first compiled tick
        super().__init__(robot, params)

    # Parameters -----------------------------------------------------------------

    def default_value(self, key: str) -> Any:
        """Joint weights default to ones (the rest: :meth:`Controller.default_value`)."""
        if key == "joint_weights":
            return np.ones(self.robot.nv_joints)
        return super().default_value(key)

    def parameters(self) -> dict[str, Any]:
        """Every parameter, with point targets as ``point:<name>`` records."""
        values = super().parameters()
        for slot in self.tasks:
            if not isinstance(slot.task, PointTask):
                continue
            target = slot.task.target
            values[slot.task.name] = {
                "frame": target.frame,
                "offset_in_frame": target.offset_in_frame.tolist(),
                "target_position_in_world": target.target_position_in_world.tolist(),
                "target_velocity_in_world": target.target_velocity_in_world.tolist(),
                "stiffness": target.stiffness,
                "damping": target.damping,
                "weight": target.weight,
            }
        return values

    def set_params(self, params: Mapping[str, Any]) -> None:
        """Validate everything first (all or nothing), then apply, points included."""
        points = {k: v for k, v in params.items() if k.startswith(POINT_PREFIX)}
        rest = {k: v for k, v in params.items() if not k.startswith(POINT_PREFIX)}
        validated_points = {
            k[len(POINT_PREFIX) :]: point_target(self.robot, k, v) for k, v in points.items()
        }
        clip = self._tracking.clip
        if "clip" in rest and isinstance(rest["clip"], str):
            clip = load_motion_clip(rest["clip"], self.robot) if rest["clip"] else None
        super().set_params(rest)
        self._tracking.clip = clip
        for name, target in validated_points.items():
            if target is None:
                self.tasks.remove(POINT_PREFIX + name)
            else:
                self.tasks.add(PointTask(name, target), target.weight)

    def _check_together(self, params: Mapping[str, Any]) -> None:
        """The compiled kernel solves its contact-force QPs by Goldfarb–Idnani only."""
        if params["kernel"] == "compiled" and params["qp_solver"] != "quadprog":
            raise InvalidParams(
                "params.qp_solver",
                f"{params['qp_solver']!r} needs kernel 'python'; the compiled kernel solves its "
                "QPs with 'quadprog' (Goldfarb–Idnani, by eiquadprog)",
            )

    def _validate(self, key: str, value: Any) -> Any:
        array = super()._validate(key, value)
        parts = {
            "reference_joint_position": slice(7, None),
            "reference_base_orientation_xyzw": slice(3, 7),
        }
        if key in parts:
            array = normalized_configuration_part(self.robot, f"params.{key}", array, parts[key])
        return array

    # One tick -------------------------------------------------------------------

    def clip_sample(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The motion clip's ``q_ref, v_ref, a_ref`` at ``time_s``, or ``None`` for the pose."""
        return self._tracking.clip_sample(time_s, self.in_force())

    def joint_limits(self) -> JointLimitSet:
        """The soft joint limits of the tracking task (eq. 6.5–6.6)."""
        return self._tracking.joint_limits

    def compute(self, control_input: ControlInput) -> ControlOutput:
        """Optimizer (every N-th tick or when supports change), then inverse dynamics.

        With ``kernel = "compiled"`` the whole tick is the compiled core's
        (:class:`~controller_server.controllers.compiled_tick.CompiledWeightedTick`); what
        follows is the Python tick, its specification.

        Between optimizer runs the last ``q̈`` is realized by
        :func:`exact_inverse_dynamics` (two RNEA passes: the thesis' 1 kHz
        inverse-dynamics loop, ch. 4.3); the full terms are computed only when
        the optimizer runs, in measured mode, or when that exact case fails.

        Raises:
            InvalidParams: Measured ground-force mode without measured wrenches.
            ControllerFailed: The dynamics overflow at this state, or a linear solve failed
                (e.g. a mass matrix that is not positive definite).
        """
        try:
            if self.in_force()["kernel"] == "compiled":
                if self._compiled_tick is None:
                    self._compiled_tick = CompiledWeightedTick(self)
                return self._compiled_tick.compute(self, control_input)
            return self._compute(control_input)
        except np.linalg.LinAlgError as error:
            raise ControllerFailed(f"a linear solve failed at this state: {error}") from error

    def _compute(self, control_input: ControlInput) -> ControlOutput:
        p = self.in_force()
        robot, q, v = self.robot, control_input.q, control_input.v
        measured = p["ground_force_mode"] == "measured"
        if measured and control_input.contact_wrench_in_world is None:
            raise InvalidParams(
                "contact_wrench_in_world", "required in ground_force_mode 'measured'"
            )
        flags = self.supports(control_input)
        run_optimizer = (
            self._last_solution is None
            or flags != self._last_flags
            or self._ticks % p["optimizer_period_ticks"] == 0
        )
        self._ticks += 1
        friction = list(p["friction_coefficients"])
        dynamics, polygon = None, None
        if not run_optimizer and not measured:
            assert self._last_solution is not None
            geometry = compute_contact_geometry(robot, self._data, q)
            dynamics = exact_inverse_dynamics(
                robot,
                self._data,
                q,
                v,
                self._last_solution.x,
                geometry,
                flags,
                friction,
                robot.torque_limit,
            )
            points, origins = (
                geometry.position_points_in_world,
                geometry.position_contact_frames_in_world,
            )
        if dynamics is None:
            terms = self._dynamics_terms(control_input)
            check_finite_dynamics(terms)
            points, origins = terms.position_points_in_world, terms.position_contact_frames_in_world
            if run_optimizer:
                # A behaviour runs at the optimizer's rate: its targets steer the next solve.
                self._host(control_input, lambda: self._observation(control_input, terms))
                p = self.in_force()
                polygon = _support_polygon(points, flags)
                # β_ba's p and g (eq. 5.17) come from the body's measured ground wrench
                # whenever one is sent, whatever the inverse dynamics uses; without one,
                # from the previous command's wrench (the controller's own plan).
                wrenches = control_input.contact_wrench_in_world
                if wrenches is None:
                    wrenches = self._last_wrenches
                self._optimize(control_input, terms, wrenches, flags, polygon)
            assert self._last_solution is not None
            dynamics = solve_inverse_dynamics(
                terms,
                self._last_solution.x,
                flags,
                friction,
                robot.torque_limit,
                measured_wrenches=control_input.contact_wrench_in_world if measured else None,
                force_regularization=p["force_regularization"],
                support_weight=p["support_weight"],
                qp_solver=p["qp_solver"],
            )
        self._last_wrenches = dynamics.contact_wrench_in_world
        diagnostics = None
        if control_input.want_diagnostics:
            motion = centroidal_motion(robot.model, self._data, q, v, dynamics.acceleration)
            if polygon is None:  # not built for the optimizer this tick
                polygon = _support_polygon(points, flags)
            diagnostics = self._diagnostics(
                motion, origins, dynamics, flags, polygon, run_optimizer
            )
        return ControlOutput(
            acceleration=dynamics.acceleration,
            joint_torque=dynamics.joint_torque,
            contact_force_in_world=dynamics.contact_force_in_world,
            contact_wrench_in_world=dynamics.contact_wrench_in_world,
            diagnostics=diagnostics,
        )

    def _optimize(
        self,
        control_input: ControlInput,
        terms: DynamicsTerms,
        wrenches: np.ndarray | None,
        flags: tuple[bool, ...],
        polygon: np.ndarray,
    ) -> None:
        p = self.in_force()
        tick = self._tick(
            control_input,
            terms,
            flags,
            support_polygon_xy=polygon,
            contact_wrench_in_world=wrenches,
        )
        objectives = [solved.objective for solved in self.tasks.solve_rows(tick)]
        problem = build_weighted_problem(
            objectives,
            compute_support_equalities(terms, flags),
            p["objective_gain_bound"],
            p["constraint_gain_bound"],
        )
        solution = solve_weighted_kkt(problem)
        self._last_solution = solution
        self._last_flags = flags
        unknown = np.full(3, np.nan)
        self._last_optimizer = {
            "objectives": objectives,
            "linear_momentum_rate_desired": tick.reports.get("linear_momentum_rate", unknown),
            "angular_momentum_weight": tick.reports.get("angular_momentum_weight", 0.0),
            "angular_momentum_rate_desired": tick.reports.get("angular_momentum_rate", unknown),
        }

    def _diagnostics(
        self,
        motion: CentroidalMotion,
        position_contact_frames_in_world: np.ndarray,
        dynamics: InverseDynamicsResult,
        flags: tuple[bool, ...],
        polygon: np.ndarray,
        optimizer_ran: bool,
    ) -> dict[str, Any]:
        solution = self._last_solution
        assert solution is not None
        optimizer = self._last_optimizer
        objectives: list[Objective] = optimizer["objectives"]
        return weighted_diagnostics(
            self.robot.total_mass,
            self.in_force()["ground_height"],
            flags,
            {
                "position_com_in_world": motion.position_com_in_world,
                "linear_momentum": motion.linear_momentum,
                "angular_momentum": motion.angular_momentum,
                "linear_momentum_rate": motion.linear_momentum_rate,
                "angular_momentum_rate": motion.angular_momentum_rate,
                "linear_momentum_rate_desired": optimizer["linear_momentum_rate_desired"],
                "angular_momentum_rate_desired": optimizer["angular_momentum_rate_desired"],
                "angular_momentum_weight": optimizer["angular_momentum_weight"],
                "position_contact_frames_in_world": position_contact_frames_in_world,
                "contact_wrench_in_world": dynamics.contact_wrench_in_world,
                "support_polygon_xy": polygon,
                "objective_residuals": {
                    o.name: o.residual(dynamics.acceleration) for o in objectives
                },
                "constraint_residual": solution.constraint_residual,
                "root_wrench_residual": dynamics.root_wrench_residual,
                "saturated_joints": dynamics.saturated_joints,
                "optimizer_ran": optimizer_ran,
                "objective_condition_number": solution.objective_condition_number,
                "schur_condition_number": solution.schur_condition_number,
                "objective_damping": solution.objective_damping,
                "constraint_damping": solution.constraint_damping,
            },
        )


def _support_polygon(
    position_points_in_world: tuple[np.ndarray, ...], flags: tuple[bool, ...]
) -> np.ndarray:
    supporting = [pts for pts, on in zip(position_points_in_world, flags, strict=True) if on]
    return support_polygon(np.vstack(supporting)) if supporting else np.zeros((0, 2))


class TrackingController(MomentumController):
    """The baseline: tracking under the support constraint, no momentum objectives."""

    name = "tracking"
    PARAMETERS: ClassVar[dict[str, ParamSpec]] = {
        **MomentumController.PARAMETERS,
        **behavior_parameters("tracking"),
        "weight_linear_momentum": ParamSpec(
            0.0, minimum=0.0, maximum=1e6, doc="β_bl of eq. 5.1 (off in the baseline)"
        ),
        "angular_momentum_gain": ParamSpec(
            0.0, minimum=0.0, maximum=1e6, doc="γ of eq. 5.17 (off in the baseline)"
        ),
        "weight_angular_momentum": ParamSpec(
            0.0, minimum=0.0, maximum=1e6, doc="β_0 of the angular objective (off in the baseline)"
        ),
    }
