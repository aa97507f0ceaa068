"""Closed-form KKT solve of an equality-constrained weighted least squares.

Macchietto 2008, Appendix D::

    min_x ½ ‖W (b − A x)‖²   s.t.  C x = d                       (D.1)
    M = Aᵀ Wᵀ W A,  u = Aᵀ Wᵀ W b
    C M⁻¹ Cᵀ λ = d − C M⁻¹ u                                     (D.7)
    M x = u + Cᵀ λ                                               (D.8)

``M`` gets a small Tikhonov term ``ε I`` so that unknowns no objective
touches (e.g. the root position) stay determined; the Schur complement
``C M⁻¹ Cᵀ`` is solved through its eigen-decomposition, dropping directions
below a relative cut-off, so redundant or dependent support rows give the
minimum-norm multipliers instead of a failure.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from controller_server.constraints import Equality
from controller_server.features import Objective

__all__ = ["KKTSolution", "WeightedProblem", "build_weighted_problem", "solve_weighted_kkt"]

SCHUR_RELATIVE_CUTOFF = 1e-12
"""Eigenvalues of ``C M⁻¹ Cᵀ`` below this fraction of the largest are dropped."""


@dataclass(frozen=True)
class WeightedProblem:
    """Normal equations of eq. D.1 plus the equality: a plain, loggable object.

    Attributes:
        hessian: ``M = Σ Aᵀ W A + ε I``.
        gradient: ``u = Σ Aᵀ W b``.
        equality: ``C x = d``.
        objectives: The objectives the problem was built from.
        build_time_s: Time spent building (s).
    """

    hessian: np.ndarray
    gradient: np.ndarray
    equality: Equality
    objectives: tuple[Objective, ...]
    build_time_s: float


@dataclass(frozen=True)
class KKTSolution:
    """Result of :func:`solve_weighted_kkt`.

    Attributes:
        found: Whether a finite solution was found.
        x: Solution (zeros if not found).
        multipliers: ``λ`` of eq. D.7.
        schur_condition_number: ``σ_max / σ_min`` of ``C M⁻¹ Cᵀ`` (1 if no rows).
        constraint_residual: ``‖C x − d‖``.
        solve_time_s: Time spent solving (s).
    """

    found: bool
    x: np.ndarray
    multipliers: np.ndarray
    schur_condition_number: float
    constraint_residual: float
    solve_time_s: float


def build_weighted_problem(
    objectives: Sequence[Objective], equality: Equality, regularization: float
) -> WeightedProblem:
    """Stack objectives into ``M`` and ``u`` (eq. D.7–D.8 notation).

    Args:
        objectives: Weighted rows over the same unknowns.
        equality: Hard constraint rows.
        regularization: ``ε ≥ 0`` added to the diagonal of ``M``.
    """
    start = time.perf_counter()
    n = equality.C.shape[1]
    hessian = regularization * np.eye(n)
    gradient = np.zeros(n)
    for objective in objectives:
        weighted_A = objective.weight[:, None] * objective.A
        hessian += objective.A.T @ weighted_A
        gradient += weighted_A.T @ objective.b
    return WeightedProblem(
        hessian, gradient, equality, tuple(objectives), time.perf_counter() - start
    )


def solve_weighted_kkt(problem: WeightedProblem) -> KKTSolution:
    """Solve eq. D.1 by eliminating ``x`` (eq. D.7), then back-substituting (D.8)."""
    start = time.perf_counter()
    C, d = problem.equality.C, problem.equality.d
    n = problem.gradient.size
    try:
        factor = scipy.linalg.cho_factor(problem.hessian, check_finite=False)
    except np.linalg.LinAlgError:
        return KKTSolution(False, np.zeros(n), np.zeros(len(d)), np.inf, np.inf, 0.0)
    x_free = scipy.linalg.cho_solve(factor, problem.gradient, check_finite=False)
    if C.shape[0] == 0:
        multipliers = np.zeros(0)
        condition = 1.0
        x = x_free
    else:
        M_inv_CT = scipy.linalg.cho_solve(factor, C.T, check_finite=False)
        schur = C @ M_inv_CT
        eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (schur + schur.T))
        largest = max(float(eigenvalues[-1]), 0.0)
        keep = eigenvalues > SCHUR_RELATIVE_CUTOFF * largest
        condition = largest / eigenvalues[0] if eigenvalues[0] > 0 else np.inf
        rhs = eigenvectors.T @ (d - C @ x_free)
        multipliers = eigenvectors[:, keep] @ (rhs[keep] / eigenvalues[keep])
        x = x_free + M_inv_CT @ multipliers
    found = bool(np.all(np.isfinite(x)))
    residual = float(np.linalg.norm(C @ x - d)) if found else np.inf
    return KKTSolution(
        found,
        x if found else np.zeros(n),
        multipliers,
        float(condition),
        residual,
        time.perf_counter() - start,
    )
