"""Closed-form KKT solve of an equality-constrained weighted least squares.

Macchietto 2008, Appendix D::

    min_x ½ ‖W (b − A x)‖²   s.t.  C x = d                       (D.1)
    M = Aᵀ Wᵀ W A,  u = Aᵀ Wᵀ W b
    C M⁻¹ Cᵀ λ = d − C M⁻¹ u                                     (D.7)
    M x = u + Cᵀ λ                                               (D.8)

Both linear solves are damped least squares (Maciejewski 1990, eq. 15–18)
with damping chosen from the smallest singular value so a gain bound holds
(:mod:`controller_server.math.damped`):

* the objective stack ``W^{½} A`` with bound ``B_obj``: ``M ← M + λ_obj² I``.
  Unknowns that no objective touches (σ = 0, e.g. the root translation) get
  λ_obj = 1/(2 B_obj), which keeps them determined by the constraints;
* the constraint rows in the metric of ``M``, ``C̃ = C L⁻ᵀ`` (``M = L Lᵀ``),
  whose Gram matrix is the Schur complement ``C M⁻¹ Cᵀ``, with bound ``B_con``:
  the correction ``x − x_free`` then obeys ``‖x − x_free‖_M ≤ B_con ‖d − C x_free‖``
  however close the supports come to a singularity (straight knees,
  dropped supports), and varies continuously along the way. Away from
  singularities nothing is damped and the constraint holds exactly.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controller_server.constraints import Equality
from controller_server.features.objective import Objective
from controller_server.math.damped import DampedFactor, damped_cholesky, damped_solve_psd

__all__ = ["KKTSolution", "WeightedProblem", "build_weighted_problem", "solve_weighted_kkt"]


@dataclass(frozen=True)
class WeightedProblem:
    """Normal equations of eq. D.1 plus the equality: a plain, loggable object.

    Attributes:
        hessian: ``M = Σ Aᵀ W A`` (undamped).
        gradient: ``u = Σ Aᵀ W b``.
        equality: ``C x = d``.
        objectives: The objectives the problem was built from.
        objective_gain_bound: ``B_obj`` for the objective solve.
        constraint_gain_bound: ``B_con`` for the constraint solve.
        build_time_s: Time spent building (s).
    """

    hessian: np.ndarray
    gradient: np.ndarray
    equality: Equality
    objectives: tuple[Objective, ...]
    objective_gain_bound: float
    constraint_gain_bound: float
    build_time_s: float


@dataclass(frozen=True)
class KKTSolution:
    """Result of :func:`solve_weighted_kkt`.

    Attributes:
        found: Whether a finite solution was found.
        x: Solution (zeros if not found).
        x_free: Minimizer of the objectives alone (``M⁻¹ u``).
        multipliers: ``λ`` of eq. D.7.
        objective_damping: λ_obj used on the objective stack.
        constraint_damping: λ_con used on the Schur complement.
        constraint_residual: ``‖C x − d‖`` (non-zero only where damped).
        solve_time_s: Time spent solving (s).
        objective_factor: Factor of the damped ``M`` (``None`` if it failed).
        schur_conditioning: Factor of the Schur complement, or its condition number
            where that is known without one.
    """

    found: bool
    x: np.ndarray
    x_free: np.ndarray
    multipliers: np.ndarray
    objective_damping: float
    constraint_damping: float
    constraint_residual: float
    solve_time_s: float
    objective_factor: DampedFactor | None
    schur_conditioning: DampedFactor | float

    @property
    def objective_condition_number(self) -> float:
        """Condition number of the damped ``M`` (estimated on demand: diagnostics only)."""
        factor = self.objective_factor
        return factor.damped_condition if factor is not None else math.inf

    @property
    def schur_condition_number(self) -> float:
        """Condition number of ``C M⁻¹ Cᵀ`` before damping (estimated on demand)."""
        schur = self.schur_conditioning
        return schur.damped_condition if isinstance(schur, DampedFactor) else schur


def build_weighted_problem(
    objectives: Sequence[Objective],
    equality: Equality,
    objective_gain_bound: float = 500.0,
    constraint_gain_bound: float = 1e3,
) -> WeightedProblem:
    """Stack objectives into ``M`` and ``u`` (eq. D.7–D.8 notation).

    Args:
        objectives: Weighted rows over the same unknowns.
        equality: Hard constraint rows.
        objective_gain_bound: ``B_obj`` (see module docstring).
        constraint_gain_bound: ``B_con``.
    """
    start = time.perf_counter()
    n = equality.C.shape[1]
    hessian = np.zeros((n, n))
    gradient = np.zeros(n)
    for objective in objectives:
        weighted_A = objective.weight[:, None] * objective.A
        hessian += objective.A.T @ weighted_A
        gradient += weighted_A.T @ objective.b
    return WeightedProblem(
        hessian,
        gradient,
        equality,
        tuple(objectives),
        objective_gain_bound,
        constraint_gain_bound,
        time.perf_counter() - start,
    )


def solve_weighted_kkt(problem: WeightedProblem) -> KKTSolution:
    """Solve eq. D.1 by eliminating ``x`` (eq. D.7), then back-substituting (D.8)."""
    start = time.perf_counter()
    C, d = problem.equality.C, problem.equality.d
    n = problem.gradient.size
    factor = damped_cholesky(problem.hessian, problem.objective_gain_bound)
    if factor is None:
        failed = np.zeros(n)
        return KKTSolution(
            False, failed, failed, np.zeros(len(d)), math.nan, 0.0, math.inf,
            time.perf_counter() - start, None, math.inf,
        )  # fmt: skip
    x_free = factor.solve(problem.gradient)
    schur_conditioning: DampedFactor | float
    if C.shape[0] == 0:
        multipliers, constraint_damping, schur_conditioning, x = np.zeros(0), 0.0, 1.0, x_free
    else:
        M_inv_CT = factor.solve(C.T)
        schur = C @ M_inv_CT
        schur_factor = damped_cholesky(schur, problem.constraint_gain_bound)
        if schur_factor is None:
            multipliers, constraint_damping, schur_conditioning = damped_solve_psd(
                schur, d - C @ x_free, problem.constraint_gain_bound
            )
        else:
            multipliers = schur_factor.solve(d - C @ x_free)
            constraint_damping = schur_factor.damping
            schur_conditioning = schur_factor
            if constraint_damping > 0:  # report the undamped Schur complement's conditioning
                eigenvalues = np.linalg.eigvalsh(schur)
                schur_conditioning = (
                    float(eigenvalues[-1] / eigenvalues[0]) if eigenvalues[0] > 0 else math.inf
                )
        x = x_free + M_inv_CT @ multipliers
    found = bool(np.all(np.isfinite(x)))
    if not found:
        x = np.zeros(n)
    return KKTSolution(
        found=found,
        x=x,
        x_free=x_free,
        multipliers=multipliers,
        objective_damping=factor.damping,
        constraint_damping=constraint_damping,
        constraint_residual=float(np.linalg.norm(C @ x - d)) if found else math.inf,
        solve_time_s=time.perf_counter() - start,
        objective_factor=factor,
        schur_conditioning=schur_conditioning,
    )
