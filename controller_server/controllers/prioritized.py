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
from controller_server.controllers.prioritized_layout import (
    NUM_ROOT_DOFS,
    LayoutIndex,
    PrioritizedLayout,
    friction_cone_basis,
)
from controller_server.controllers.prioritized_levels import Term, normalized_level, term_residual
from controller_server.controllers.prioritized_params import OBJECTIVES, PRIORITIZED_PARAMETERS
from controller_server.dynamics import DynamicsTerms
from controller_server.inverse_dynamics import wrenches_from_point_forces
from controller_server.models import RobotModel
from controller_server.solvers.prioritized import (
    PrioritizedSolution,
    solve_prioritized,
)
from controller_server.tasks import (
    HeightTarget,
    TaskStack,
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
        self._index = LayoutIndex(robot)
        self._derived: dict[str, Any] = {}  # from the parameters; cleared by set_params
        self._forces_cache: dict[int, Term] = {}
        self._height = HeightTarget()
        self.tasks = TaskStack()
        """The objectives below the equations of motion and above ``forces``, by name."""
        for entry in OBJECTIVES.values():
            self.tasks.add(entry.make(self._height), entry.weight, entry.level)
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
        terms = self._dynamics_terms(control_input)
        check_finite_dynamics(terms)
        targets = self._host(control_input, lambda: self._observation(control_input, terms))
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
        objectives, desired_rates = self._objectives(control_input, terms, layout, flags, targets)
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
                grouped.setdefault(self.tasks[name].level, []).append(term)
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
        flags: tuple[bool, ...],
        targets: Targets | None,
    ) -> tuple[dict[str, Term], dict[str, np.ndarray]]:
        """The objectives by name, each over its block of ``x``, and the desired momentum rates.

        The equations of motion and ``forces`` are the problem's own; every other objective
        is a task of the stack (:attr:`tasks`), over the layout's ``q̈`` or ``τ`` block. The
        rates are for the diagnostics.
        """
        tick = self._tick(control_input, terms, flags, targets=targets, loaded=layout)
        blocks = {"acceleration": layout.acceleration, "torque": layout.torque}
        objectives = {
            "dynamics": Term(layout.equations_of_motion(terms), slice(0, layout.size), 1.0, True),
            **{
                solved.name: Term(
                    solved.objective,
                    blocks[solved.slot.task.block],
                    solved.slot.weight if solved.slot.task.uniform else None,
                    solved.active,
                    solved.slot.task.row_basis(tick),
                )
                for solved in self.tasks.solve_rows(tick)
            },
            "forces": self._least_forces(layout),
        }
        unknown = np.full(3, np.nan)
        desired_rates = {
            "linear_momentum_rate": tick.reports.get("linear_momentum_rate", unknown),
            "angular_momentum_rate": tick.reports.get("angular_momentum_rate", unknown),
        }
        return objectives, desired_rates

    def _least_forces(self, layout: PrioritizedLayout) -> Term:
        """``forces`` over the ``λ`` block (it depends on the number of loaded points only)."""
        term = self._forces_cache.get(layout.nl)
        if term is None:
            term = Term(layout.least_forces(), layout.force, 1.0, True)
            self._forces_cache[layout.nl] = term
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
