"""Prioritized feature-based balance controller (de Lasa, Mordatch & Hertzmann 2010).

Unknowns ``x = [τ, q̈, λ]`` (eq. 1), with the contact force of every support
point in the basis of its linearized friction cone, ``f = V λ`` (eq. 23).
Objectives are least-squares rows over ``x``, grouped in priority levels and
solved by Algorithm 1 (:func:`controller_server.solvers.solve_prioritized`):

0. equations of motion ``‖Sᵀ τ − M q̈ + J_cᵀ V λ − h‖²`` (eq. 22–24), as the
   top-priority objective §8.2 recommends instead of a hard equality;
1. ``contact``: setpoints on the sole points, toward their projections on
   the ground (Table 1, §4);
2. ``com``: the CM over the centroid of the support points,
   ``angular_momentum``: ``L̇_d = k_p (L_r − L)`` (eq. 8–9), ``trunk``: the
   root upright, ``pose``: rest pose of the joints (§4);
3. ``com_height``: the CM height (a target objective, eq. 6–7, while a new
   height is being reached; a setpoint otherwise), ``torque``: minimum
   torque on selected joints (eq. 15);
4. ``forces``: ``‖λ‖²``, below everything (not a parameter). The rest pose
   fixes ``q̈`` but not the internal forces between two feet, which would
   otherwise be whatever the QP solver returns (torques chattering to their
   limits); this picks the smallest, as the weighted controller's
   distribution does.

These default priorities differ from Table 1; see
:data:`~controller_server.controllers.prioritized_params.OBJECTIVES` for
why. Each level is scaled to unit norm before the solve (:func:`_normalized`),
so that one gain bound means the same in every level.

Priorities and weights (eq. 37) of every objective, and its gains and
references, change at run time through ``set_params``. Inequalities
``D x + f ≥ 0``: ``λ ≥ 0`` (eq. 25), non-penetration ``Vᵀ(J_c q̈ + J̇_c q̇) ≥ 0``
(eq. 26, flat static ground so ``V̇ = 0``), torque limits, and joints at a
limit may not accelerate further out (eq. 27), made velocity-aware: no 1-DoF
joint may reach past a limit within ``joint_limit_horizon_s`` (see
:meth:`~controller_server.controllers.prioritized_layout.LayoutIndex.joint_limit_bounds`).

Every objective on ``q̈`` is a feature of :mod:`controller_server.features`,
shared with the weighted controller; the layout
(:mod:`controller_server.controllers.prioritized_layout`) writes it over ``x``.

Setpoint gains follow eq. 4: ``k_v = 2 ζ √k_p`` with damping ratio ``ζ = 1``
by default (de Lasa's ``k_v = 2 √k_p``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from controller_server.balance_points import (
    admissible_cop_polygon,
)
from controller_server.behaviors import Targets
from controller_server.constraints import compute_support_equalities
from controller_server.controllers.base import (
    ControlInput,
    Controller,
    ControllerFailed,
    ControlOutput,
    ParamSpec,
    check_finite_dynamics,
    normalized_configuration_part,
)
from controller_server.controllers.diagnostics import core_diagnostics, with_extras
from controller_server.controllers.height_target import HeightTarget
from controller_server.controllers.prioritized_layout import (
    NUM_ROOT_DOFS,
    LayoutIndex,
    PrioritizedLayout,
    friction_cone_basis,
)
from controller_server.controllers.prioritized_levels import Term, normalized_level, term_residual
from controller_server.controllers.prioritized_params import PRIORITIZED_PARAMETERS
from controller_server.dynamics import DynamicsTerms, compute_dynamics_terms
from controller_server.features import (
    Objective,
    admissible_linear_momentum_rate,
    compute_angular_momentum_objective,
    compute_ground_contact_objective,
    compute_linear_momentum_objective,
    compute_posture_objectives,
)
from controller_server.features.point_from_com import compute_point_from_com_objective
from controller_server.features.setpoint import (
    critical_damping,
    setpoint_acceleration,
)
from controller_server.features.swing_foot import compute_swing_objective
from controller_server.inverse_dynamics import wrenches_from_point_forces
from controller_server.models import RobotModel
from controller_server.solvers.prioritized import (
    PrioritizedSolution,
    solve_prioritized,
)

__all__ = ["PrioritizedController", "friction_cone_basis"]

VERTICAL = slice(2, 3)
EXACT_GAIN_BOUND = 1e15
"""Gain bound of the equations of motion: only directions at the rounding floor are singular."""


class PrioritizedController(Controller):
    """de Lasa et al.'s prioritized balance controller (Table 1, Algorithm 1)."""

    name = "prioritized"
    PARAMETERS: ClassVar[dict[str, ParamSpec]] = PRIORITIZED_PARAMETERS

    def __init__(self, robot: RobotModel, params: Mapping[str, Any] | None = None):
        self._data = robot.model.createData()
        self._index = LayoutIndex(robot)
        self._derived: dict[str, Any] = {}  # from the parameters; cleared by set_params
        self._forces_cache: dict[int, Term] = {}
        self._gravity = float(np.linalg.norm(robot.model.gravity.linear))
        self._height = HeightTarget()
        self._height_changes_seen = 0  # the behaviour's requests of a new CM height so far
        super().__init__(robot, params)

    def default_value(self, key: str) -> Any:
        """Standing CM height, no torque selection (the rest: :meth:`Controller.default_value`)."""
        robot = self.robot
        if key == "torque_selection":
            return np.zeros(robot.nv_joints)
        if key == "com_height":
            q = robot.standing_configuration
            return float(pin.centerOfMass(robot.model, robot.model.createData(), q)[2])
        return super().default_value(key)

    def set_params(self, params: Mapping[str, Any]) -> None:
        """Apply parameters; a new ``com_height`` starts a target objective (eq. 6–7)."""
        old_height = self._params.get("com_height")
        super().set_params(params)
        self._derived = {}
        if old_height is not None and self._params["com_height"] != old_height:
            self._height.restart()
        if "behavior" in params:
            self._height_changes_seen = 0

    def _overrides_changed(self) -> None:
        self._derived = {}

    def _validate(self, key: str, value: Any) -> Any:
        validated = super()._validate(key, value)
        parts = {
            "reference_joint_position": slice(7, None),
            "reference_trunk_orientation_xyzw": slice(3, 7),
        }
        if key in parts:
            validated = normalized_configuration_part(
                self.robot, f"params.{key}", validated, parts[key]
            )
        return validated

    # One tick -------------------------------------------------------------------

    def compute(self, control_input: ControlInput) -> ControlOutput:
        """Build the levels and inequalities, solve them (Algorithm 1), read off τ, q̈, f.

        Raises:
            ControllerFailed: The problem data are not finite at this state, the equations of
                motion could not be solved (every QP solver failed, the QP time budget was
                spent, or the inequality terms are too large to check), or a linear solve
                failed.
        """
        try:
            return self._compute(control_input)
        except np.linalg.LinAlgError as error:
            raise ControllerFailed(f"a linear solve failed at this state: {error}") from error

    def _compute(self, control_input: ControlInput) -> ControlOutput:
        terms = compute_dynamics_terms(self.robot, self._data, control_input.q, control_input.v)
        check_finite_dynamics(terms)
        targets = self._host(control_input, terms, self._data)
        if targets is not None and targets.com_height_changes != self._height_changes_seen:
            self._height_changes_seen = targets.com_height_changes
            self._height.restart()
        p = self.in_force()
        flags = self.supports(control_input)
        layout = PrioritizedLayout(
            self._index,
            terms,
            self._planted(),
            flags,
            self._friction_key(),
            p["ground_height"],
            p["contact_distance"],
        )
        objectives, desired_rates = self._objectives(control_input, terms, layout, targets)
        D, f = layout.inequalities(
            control_input.q, control_input.v, p["non_penetration"], p["joint_limit_horizon_s"]
        )
        # One sum first: NaN and ±inf propagate through it; only a non-finite (or overflowing)
        # sum looks at each array.
        total = float(D.sum()) + float(f.sum())
        for term in objectives.values():
            total += float(term.objective.A.sum()) + float(term.objective.b.sum())
        if not math.isfinite(total) and (
            not all(
                np.isfinite(term.objective.A).all() and np.isfinite(term.objective.b).all()
                for term in objectives.values()
            )
            or not (np.isfinite(D).all() and np.isfinite(f).all())
        ):
            not_finite = [
                name
                for name, term in objectives.items()
                if not (np.isfinite(term.objective.A).all() and np.isfinite(term.objective.b).all())
            ] + ([] if np.isfinite(D).all() and np.isfinite(f).all() else ["inequalities"])
            # Velocities so large that the objectives overflow.
            raise ControllerFailed(
                f"non-finite {', '.join(not_finite)} at this state (the dynamics overflow); "
                "no command"
            )
        grouped: dict[int, list[Term]] = {}
        for name, term in objectives.items():
            if name not in ("dynamics", "forces") and term.active:
                grouped.setdefault(p[f"priority_{name}"], []).append(term)
        # The equations of motion have full row rank (M ≻ 0) and a small condition number;
        # the levels on q̈ see nothing of the motionless forces in their null space.
        levels = [
            normalized_level(
                [objectives["dynamics"]],
                layout.size,
                well_conditioned=True,
                null_space_part=layout.motionless_forces(),
            ),
            *(normalized_level(grouped[k], layout.size) for k in sorted(grouped)),
            normalized_level([objectives["forces"]], layout.size),
        ]
        # The equations of motion are kept exactly (rounding floor only): a gain bound there
        # would let lower levels bend the dynamics of a heavy robot.
        bounds = [EXACT_GAIN_BOUND] + [p["gain_bound"]] * (len(levels) - 1)
        solution = solve_prioritized(
            levels,
            D,
            f,
            gain_bound=bounds,
            qp_solver=p["qp_solver"],
            qp_time_budget_s=p["qp_time_budget_s"],
            check_finite=False,
            residuals=control_input.want_diagnostics,
        )
        top = solution.levels[0]
        if top.status != "solved":
            raise ControllerFailed(
                f"the equations of motion could not be solved ({top.status}, QP solver "
                f"{p['qp_solver']}{': ' + top.detail if top.detail else ''}); no command"
            )
        return self._output(
            terms,
            layout,
            flags,
            objectives,
            desired_rates,
            solution,
            control_input.want_diagnostics,
        )

    def _planted(self) -> tuple[bool, ...]:
        """Per contact, whether ``support_mask`` allows it (until the parameters change)."""
        planted = self._derived.get("planted")
        if planted is None:
            planted = tuple(bool(allowed > 0.5) for allowed in self.in_force()["support_mask"])
            self._derived["planted"] = planted
        return planted

    def _friction_key(self) -> tuple[float, ...]:
        """``friction_coefficients`` as a tuple (until the parameters change)."""
        mus = self._derived.get("friction")
        if mus is None:
            mus = tuple(float(mu) for mu in self.in_force()["friction_coefficients"])
            self._derived["friction"] = mus
        return mus

    def _objectives(
        self,
        control_input: ControlInput,
        terms: DynamicsTerms,
        layout: PrioritizedLayout,
        targets: Targets | None,
    ) -> tuple[dict[str, Term], dict[str, np.ndarray]]:
        """The objectives by name, each over its block of ``x``, and the desired momentum rates.

        The rates are for the diagnostics. Every objective on ``q̈`` comes from the feature library
        (:mod:`controller_server.features`), over the layout's ``q̈`` block. A behaviour's
        ``targets`` give ``com`` a CM acceleration and ``swing`` and ``ankle`` their references.
        """
        p, model = self.in_force(), self.robot.model
        q, v = control_input.q, control_input.v
        momentum, mass = terms.momentum, terms.total_mass
        ratio = p["damping_ratio"]
        on_acceleration: list[Objective] = []
        # Contact (Table 1, priority 1): each sole point toward its ground projection.
        if layout.point_jacobian.shape[0]:
            stiffness = p["contact_stiffness"]
            on_acceleration.append(
                compute_ground_contact_objective(
                    layout.point_jacobian,
                    layout.point_drift,
                    layout.point_positions,
                    v,
                    p["ground_height"],
                    stiffness,
                    critical_damping(stiffness, ratio),
                    p["weight_contact"],
                )
            )
        # CM over the support centroid and at its height (Table 1, priority 2).
        com = terms.position_com_in_world
        com_velocity = momentum.linear_momentum / mass
        desired_linear_rate = np.full(3, np.nan)
        if layout.support_positions.shape[0]:
            centroid = layout.support_positions[:, :2].mean(axis=0)
            stiffness = p["com_stiffness"]
            damping = critical_damping(stiffness, ratio)
            offset = p["com_offset_xy"]
            asked = None if targets is None else targets.com_acceleration_xy
            if asked is not None and stiffness > 0.0:
                # A behaviour's CM acceleration (a walk's pendulum): the offset whose eq. 4
                # setpoint asks for it, within the offset's range (`com_offset_xy`).
                offset = np.clip(
                    com[:2] + (asked + damping * com_velocity[:2]) / stiffness - centroid,
                    -10.0,
                    10.0,
                )
            desired_xy = setpoint_acceleration(
                centroid + offset, com[:2], com_velocity[:2], stiffness, damping
            )
            # Ask only what the ground can give without turning the body: the COP this
            # needs stays `cop_margin` inside the feet (as the weighted controller's L̇_des).
            # Otherwise `com` takes all of the COP's authority and the angular momentum
            # objective below it has none left (a 220 N head push then fells the robot).
            desired_linear_rate = admissible_linear_momentum_rate(
                mass * np.array([*desired_xy, 0.0]),
                mass,
                com,
                admissible_cop_polygon(layout.support_polygon, p["cop_margin"]),
                p["ground_height"],
                self._gravity,
                friction_coefficient=layout.smallest_friction_coefficient,
            )
            desired_linear_rate[2] = mass * self._height.acceleration(
                control_input.time_s, com, com_velocity, p
            )
            on_acceleration += [
                compute_linear_momentum_objective(
                    momentum, mass, desired_linear_rate, p["weight_com"], name="com"
                ),
                compute_linear_momentum_objective(
                    momentum,
                    mass,
                    desired_linear_rate,
                    p["weight_com_height"],
                    axes=VERTICAL,
                    name="com_height",
                ),
            ]
        # Angular momentum (eq. 8–9), rest pose and trunk (priority 2).
        desired_angular_rate = p["angular_momentum_stiffness"] * (
            p["reference_angular_momentum"] - momentum.angular_momentum
        )
        on_acceleration.append(
            compute_angular_momentum_objective(
                momentum, mass, p["weight_angular_momentum"], desired_rate=desired_angular_rate
            )
        )
        trunk, pose = compute_posture_objectives(
            model,
            q,
            v,
            p["reference_trunk_orientation_xyzw"],
            p["reference_joint_position"],
            p["trunk_stiffness"],
            p["pose_stiffness"],
            ratio,
            p["weight_trunk"],
            p["weight_pose"],
        )
        on_acceleration += [pose, trunk]
        feet = None if targets is None else targets.feet_from_com
        if p["weight_ankle"] > 0 and feet is not None:
            stiffness = p["ankle_stiffness"]
            on_acceleration.append(
                compute_point_from_com_objective(
                    [jacobian[:3] for jacobian in terms.support_jacobians],
                    [drift[:3] for drift in terms.support_drifts],
                    terms.position_contact_frames_in_world,
                    v,
                    momentum,
                    mass,
                    com,
                    feet.offsets_in_world,
                    stiffness,
                    critical_damping(stiffness, ratio),
                    p["weight_ankle"],
                    rotations=[self._data.oMf[c.frame_id].rotation for c in self.robot.contacts],
                    reference_rotations=feet.rotations_in_world,
                    angular_jacobians=[jacobian[3:] for jacobian in terms.support_jacobians],
                    angular_drifts=[drift[3:] for drift in terms.support_drifts],
                )
            )
        swing = None if targets is None else targets.swing
        if p["weight_swing"] > 0 and swing is not None:
            foot = swing.contact
            stiffness = swing.stiffness
            on_acceleration.append(
                compute_swing_objective(
                    swing,
                    control_input.time_s,
                    terms.support_jacobians[foot],
                    terms.support_drifts[foot],
                    terms.position_contact_frames_in_world[foot],
                    self._data.oMf[self.robot.contacts[foot].frame_id].rotation,
                    v,
                    stiffness,
                    critical_damping(stiffness, ratio),
                    p["weight_swing"],
                )
            )
        objectives = {
            "dynamics": Term(layout.equations_of_motion(terms), slice(0, layout.size), 1.0, True),
            **{
                o.name: Term(
                    o,
                    layout.acceleration,
                    weight,
                    weight > 0,
                    layout.contact_row_basis() if o.name == "contact" else None,
                )
                for o, weight in ((o, float(p[f"weight_{o.name}"])) for o in on_acceleration)
            },
            "forces": self._least_forces(layout),
            "torque": self._least_torque(layout),
        }
        desired_rates = {
            "linear_momentum_rate": desired_linear_rate,
            "angular_momentum_rate": desired_angular_rate,
        }
        return objectives, desired_rates

    def _least_forces(self, layout: PrioritizedLayout) -> Term:
        """``forces`` over the ``λ`` block (it depends on the number of loaded points only)."""
        term = self._forces_cache.get(layout.nl)
        if term is None:
            term = Term(layout.least_forces(), layout.force, 1.0, True)
            self._forces_cache[layout.nl] = term
        return term

    def _least_torque(self, layout: PrioritizedLayout) -> Term:
        """``torque`` over the ``τ`` block (eq. 15), until the parameters change."""
        term = self._derived.get("torque")
        if term is None:
            p = self.in_force()
            selection = np.asarray(p["torque_selection"], dtype=float)
            weight = float(p["weight_torque"])
            term = Term(
                layout.least_torque(selection, weight),
                layout.torque,
                None,
                weight > 0 and bool(np.any(selection > 0)),
            )
            self._derived["torque"] = term
        return term

    def _output(
        self,
        terms: DynamicsTerms,
        layout: PrioritizedLayout,
        flags: tuple[bool, ...],
        objectives: dict[str, Term],
        desired_rates: dict[str, np.ndarray],
        solution: PrioritizedSolution,
        want_diagnostics: bool = True,
    ) -> ControlOutput:
        x = solution.x
        index = self._index
        torque_unclipped = x[layout.torque]
        torque = np.clip(torque_unclipped, index.lower_torque_limit, index.torque_limit)
        forces = np.zeros((index.owner.size, 3))
        forces[layout.force_point_indices] = layout.point_forces(x)
        wrenches = wrenches_from_point_forces(terms, forces, index.counts)
        # The acceleration τ and f really produce (equal to x's q̈ when eq. 22 holds).
        generalized = layout.contact_force_map @ x[layout.force]
        generalized[NUM_ROOT_DOFS:] += torque
        # LAPACK's LU solve, as np.linalg.solve but without its dispatch.
        _, _, acceleration, info = lapack.dgesv(terms.mass_matrix, generalized - terms.bias_forces)
        if info:
            raise np.linalg.LinAlgError("Singular matrix")
        diagnostics = None
        if want_diagnostics:
            diagnostics = self._diagnostics(
                terms,
                layout,
                flags,
                objectives,
                desired_rates,
                solution,
                acceleration,
                wrenches,
                torque_unclipped,
            )
        return ControlOutput(
            acceleration=acceleration,
            joint_torque=torque,
            contact_force_in_world=forces,
            contact_wrench_in_world=wrenches,
            diagnostics=diagnostics,
        )

    def _diagnostics(
        self,
        terms: DynamicsTerms,
        layout: PrioritizedLayout,
        flags: tuple[bool, ...],
        objectives: dict[str, Term],
        desired_rates: dict[str, np.ndarray],
        solution: PrioritizedSolution,
        acceleration: np.ndarray,
        wrenches: np.ndarray,
        torque_unclipped: np.ndarray,
    ) -> dict[str, Any]:
        """The tick's diagnostics (only on ticks that send them)."""
        p, robot, x = self.in_force(), self.robot, solution.x
        momentum = terms.momentum
        support = compute_support_equalities(terms, flags)
        support_error = support.C @ acceleration - support.d
        dynamics = objectives["dynamics"].objective
        core = core_diagnostics(
            position_com_in_world=terms.position_com_in_world,
            linear_momentum=momentum.linear_momentum,
            angular_momentum=momentum.angular_momentum,
            total_mass=terms.total_mass,
            momentum_rates_desired=(
                desired_rates["linear_momentum_rate"],
                desired_rates["angular_momentum_rate"],
            ),
            momentum_rates_achieved=(
                momentum.R @ acceleration + momentum.r_bias,
                momentum.S @ acceleration + momentum.s_bias,
            ),
            position_contact_frames_in_world=terms.position_contact_frames_in_world,
            contact_wrench_in_world=wrenches,
            supports=flags,
            ground_height=p["ground_height"],
            support_polygon_xy=layout.support_polygon,
            objective_residuals={name: term_residual(term, x) for name, term in objectives.items()},
            constraint_residual=math.sqrt(float(support_error @ support_error)),
            root_wrench_residual=float(
                np.linalg.norm(dynamics.A[:NUM_ROOT_DOFS] @ x - dynamics.b[:NUM_ROOT_DOFS])
            ),
            saturated_joints=int(
                np.count_nonzero(np.abs(torque_unclipped) >= robot.torque_limit * (1 - 1e-6))
            ),
        )
        return with_extras(
            core,
            "prioritized",
            {
                "priority_levels": [
                    {
                        "objectives": list(level.names),
                        "status": level.status,
                        "residual": level.residual,
                        "rank": level.rank,
                        "null_space_dimension": level.null_space_dimension,
                        "damping": level.damping,
                        "used_qp": level.used_qp,
                    }
                    for level in solution.levels
                ],
                "inequality_violation": solution.inequality_violation,
            },
        )
