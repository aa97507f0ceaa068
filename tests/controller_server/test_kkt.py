"""The closed-form KKT solve (Macchietto 2008, App. D) against direct solves and QP solvers."""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from controller_server.constraints import Equality
from controller_server.features import Objective
from controller_server.solvers import (
    KKTSolution,
    WeightedProblem,
    build_weighted_problem,
    solve_weighted_kkt,
)

REGULARIZATION = 1e-6
"""λ_obj² the solver uses on unknowns no objective touches: (1 / (2 B_obj))², B_obj = 500."""


def random_objectives(rng: np.random.Generator, n: int, count: int = 2) -> list[Objective]:
    """Objectives whose stacked rows (≥ n of them) make ``H`` well conditioned."""
    objectives = []
    for index in range(count):
        rows = int(rng.integers(n, 2 * n + 1))
        objectives.append(
            Objective(
                f"objective_{index}",
                rng.normal(size=(rows, n)),
                rng.normal(size=rows),
                rng.uniform(0.1, 10.0, rows),
            )
        )
    return objectives


def random_equality(rng: np.random.Generator, n: int, rows: int) -> Equality:
    return Equality(rng.normal(size=(rows, n)), rng.normal(size=rows))


def reference_normal_equations(
    objectives: list[Objective], n: int, regularization: float
) -> tuple[np.ndarray, np.ndarray]:
    """``H = Σ Aᵀ diag(w) A + ε I`` and ``g = Σ Aᵀ diag(w) b``, written out independently."""
    H = regularization * np.eye(n)
    g = np.zeros(n)
    for objective in objectives:
        W = np.diag(objective.weight)
        H += objective.A.T @ W @ objective.A
        g += objective.A.T @ W @ objective.b
    return H, g


def full_kkt_solve(
    H: np.ndarray, g: np.ndarray, equality: Equality
) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``[[H, Cᵀ], [C, 0]] [x; μ] = [g; d]``; the paper's ``λ`` (eq. D.5) is ``−μ``."""
    n, p = H.shape[0], equality.C.shape[0]
    kkt = np.block([[H, equality.C.T], [equality.C, np.zeros((p, p))]])
    solution = np.linalg.solve(kkt, np.concatenate([g, equality.d]))
    return solution[:n], -solution[n:]


def build_and_solve(
    objectives: list[Objective], equality: Equality, objective_gain_bound: float = 500.0
) -> tuple[WeightedProblem, KKTSolution]:
    problem = build_weighted_problem(objectives, equality, objective_gain_bound)
    return problem, solve_weighted_kkt(problem)


def scale_of(*arrays: np.ndarray) -> float:
    return max(1.0, *(float(np.max(np.abs(a), initial=0.0)) for a in arrays))


@pytest.mark.parametrize("seed", range(10))
def test_matches_full_kkt_block_system(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 30))
    p = int(rng.integers(1, n))
    objectives = random_objectives(rng, n)
    equality = random_equality(rng, n, p)
    problem, solution = build_and_solve(objectives, equality)

    assert solution.objective_damping == 0.0  # well-conditioned: no damping
    assert solution.constraint_damping == 0.0
    H, g = reference_normal_equations(objectives, n, 0.0)
    np.testing.assert_allclose(problem.hessian, H, atol=1e-12 * scale_of(H))
    np.testing.assert_allclose(problem.gradient, g, atol=1e-12 * scale_of(g))
    x, multipliers = full_kkt_solve(H, g, equality)
    assert solution.found
    np.testing.assert_allclose(solution.x, x, atol=1e-9 * scale_of(x))
    np.testing.assert_allclose(solution.multipliers, multipliers, atol=1e-8 * scale_of(multipliers))
    np.testing.assert_allclose(equality.C @ solution.x, equality.d, atol=1e-9)
    assert solution.constraint_residual < 1e-9
    assert solution.schur_condition_number >= 1.0
    assert solution.solve_time_s >= 0.0 and problem.build_time_s >= 0.0


@pytest.mark.parametrize("solver", ["quadprog", "proxqp"])
@pytest.mark.parametrize("seed", range(5))
def test_matches_qpsolvers(seed: int, solver: str) -> None:
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(3, 25))
    p = int(rng.integers(1, n))
    objectives = random_objectives(rng, n)
    equality = random_equality(rng, n, p)
    _, solution = build_and_solve(objectives, equality)

    H, g = reference_normal_equations(objectives, n, solution.objective_damping**2)
    options = {"eps_abs": 1e-12, "eps_rel": 0.0} if solver == "proxqp" else {}
    expected = qpsolvers.solve_qp(H, -g, A=equality.C, b=equality.d, solver=solver, **options)
    assert expected is not None
    tolerance = 1e-9 if solver == "quadprog" else 1e-7
    np.testing.assert_allclose(solution.x, expected, atol=tolerance * scale_of(expected))


@pytest.mark.parametrize("seed", range(5))
def test_without_constraints_solves_damped_normal_equations(seed: int) -> None:
    rng = np.random.default_rng(2000 + seed)
    n = int(rng.integers(2, 20))
    objectives = [
        Objective(o.name, o.A * 1e-3, o.b, o.weight) for o in random_objectives(rng, n, count=3)
    ]  # small singular values: the bound forces damping
    bound = 10.0 ** rng.uniform(0, 3)
    _, solution = build_and_solve(objectives, Equality(np.zeros((0, n)), np.zeros(0)), bound)

    H, g = reference_normal_equations(objectives, n, solution.objective_damping**2)
    sigma_min = np.sqrt(
        max(np.linalg.eigvalsh(reference_normal_equations(objectives, n, 0.0)[0])[0], 0)
    )
    assert (solution.objective_damping > 0) == (sigma_min < 1 / bound)
    assert solution.found
    np.testing.assert_allclose(solution.x, np.linalg.solve(H, g), atol=1e-10 * scale_of(solution.x))
    assert solution.multipliers.shape == (0,)
    assert solution.schur_condition_number == 1.0
    assert solution.constraint_residual == 0.0


def test_untouched_unknowns_are_held_at_zero_by_regularization() -> None:
    rng = np.random.default_rng(3)
    A = np.hstack([rng.normal(size=(4, 3)), np.zeros((4, 2))])
    objective = Objective("partial", A, rng.normal(size=4), np.ones(4))
    _, solution = build_and_solve([objective], Equality(np.zeros((0, 5)), np.zeros(0)))
    assert solution.found
    np.testing.assert_array_equal(solution.x[3:], 0.0)


@pytest.mark.parametrize("seed", range(5))
def test_redundant_rows_give_feasible_solution_and_minimum_norm_multipliers(seed: int) -> None:
    rng = np.random.default_rng(4000 + seed)
    n = int(rng.integers(6, 25))
    p = int(rng.integers(2, n // 2 + 1))
    objectives = random_objectives(rng, n)
    equality = random_equality(rng, n, p)
    duplicated = Equality(
        np.vstack([equality.C, equality.C[:2], 2.0 * equality.C[-1:]]),
        np.concatenate([equality.d, equality.d[:2], 2.0 * equality.d[-1:]]),
    )
    _, solution = build_and_solve(objectives, duplicated)

    H, g = reference_normal_equations(objectives, n, solution.objective_damping**2)
    x, _ = full_kkt_solve(H, g, equality)
    assert solution.found
    # The Schur complement is singular, so it is damped (λ = 1/(2 B_con)): the
    # constraint then holds up to O(λ²/σ²) and x stays next to the exact solution.
    assert solution.constraint_damping == pytest.approx(0.5e-3)
    np.testing.assert_allclose(duplicated.C @ solution.x, duplicated.d, atol=1e-4)
    np.testing.assert_allclose(solution.x, x, atol=1e-4 * scale_of(x))
    # Stationarity H x − g = Cᵀ λ (eq. D.5), with the smallest λ that satisfies it.
    stationarity = H @ solution.x - g
    np.testing.assert_allclose(
        duplicated.C.T @ solution.multipliers, stationarity, atol=1e-5 * scale_of(stationarity)
    )
    minimum_norm = np.linalg.pinv(duplicated.C.T) @ stationarity
    np.testing.assert_allclose(
        solution.multipliers, minimum_norm, atol=1e-4 * scale_of(minimum_norm)
    )
    assert solution.schur_condition_number >= 1.0
    assert solution.schur_condition_number > 1e8  # the Schur complement is singular


@pytest.mark.parametrize("seed", range(5))
def test_controller_like_problem_with_untracked_unknowns(seed: int) -> None:
    """As in the tracking controller: some unknowns only held by ``ε``, support-like rows on them.

    ``H`` then has eigenvalues ``ε`` and ``cond(H) ≈ 1/ε``; the Schur-complement route
    loses about ``cond(H) · machine ε`` of accuracy relative to a direct block solve.
    """
    rng = np.random.default_rng(5000 + seed)
    n, untracked, p = 30, 3, 12
    A = np.hstack([np.zeros((n - untracked, untracked)), np.eye(n - untracked)])
    objective = Objective(
        "tracking", A, rng.normal(size=n - untracked), rng.uniform(0.5, 2.0, n - untracked)
    )
    equality = random_equality(rng, n, p)
    _, solution = build_and_solve([objective], equality)

    assert solution.objective_damping**2 == pytest.approx(REGULARIZATION)
    H, g = reference_normal_equations([objective], n, REGULARIZATION)
    x, _ = full_kkt_solve(H, g, equality)
    assert solution.found
    np.testing.assert_allclose(solution.x, x, atol=1e-7 * scale_of(x))
    assert solution.constraint_residual < 1e-7 * scale_of(equality.d)
    np.testing.assert_allclose(
        equality.C @ solution.x, equality.d, atol=1e-7 * scale_of(equality.d)
    )


def check_optimal_on_the_constraint_set(
    objectives: list[Objective],
    equality: Equality,
    problem: WeightedProblem,
    solution: KKTSolution,
) -> None:
    """Optimal on ``C x = d`` (eq. D.8); feasible, or, with damped constraints, within the bound."""
    n, p = problem.hessian.shape[0], equality.C.shape[0]
    H, g = reference_normal_equations(objectives, n, solution.objective_damping**2)
    assert solution.found
    assert np.all(np.isfinite(solution.x))
    scale = scale_of(H) * scale_of(solution.x) + scale_of(g)
    # Optimal on the constraint set (eq. D.8: M x − u lies in the span of Cᵀ), damped or not.
    N = scipy.linalg.null_space(equality.C) if p else np.eye(n)
    np.testing.assert_allclose(N.T @ (H @ solution.x - g), np.zeros(N.shape[1]), atol=1e-9 * scale)
    if solution.constraint_damping == 0:  # feasible
        np.testing.assert_allclose(
            equality.C @ solution.x,
            equality.d,
            atol=1e-9 * scale_of(equality.C) * scale_of(solution.x, equality.d),
        )
    else:  # near-singular constraints: the correction obeys the gain bound instead
        x_free = np.linalg.solve(H, g)
        correction = solution.x - x_free
        correction_norm = float(np.sqrt(max(float(correction @ H @ correction), 0.0)))
        gap = float(np.linalg.norm(equality.d - equality.C @ x_free))
        assert correction_norm <= problem.constraint_gain_bound * gap * (1 + 1e-6) + 1e-9 * scale


@settings(max_examples=300, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 15),
    constraint_fraction=st.floats(0.0, 0.95),
    objective_count=st.integers(1, 3),
)
def test_solution_is_feasible_and_optimal_on_the_constraint_set(
    seed: int, n: int, constraint_fraction: float, objective_count: int
) -> None:
    rng = np.random.default_rng(seed)
    p = int(constraint_fraction * n)
    objectives = random_objectives(rng, n, objective_count)
    equality = random_equality(rng, n, p)
    problem, solution = build_and_solve(objectives, equality)
    check_optimal_on_the_constraint_set(objectives, equality, problem, solution)
    assert solution.schur_condition_number >= 1.0


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(3, 15),
    log_gap=st.floats(-12.0, -6.0),
)
def test_near_dependent_constraints_are_damped_within_the_gain_bound(
    seed: int, n: int, log_gap: float
) -> None:
    """Two constraint rows 10⁻¹²–10⁻⁶ apart (a support at a singularity): damped, bounded."""
    rng = np.random.default_rng(seed)
    C = rng.normal(size=(2, n))
    C[1] = C[0] + 10.0**log_gap * rng.normal(size=n)
    equality = Equality(C, rng.normal(size=2))
    objectives = random_objectives(rng, n, 2)
    problem, solution = build_and_solve(objectives, equality)
    assert solution.constraint_damping > 0
    check_optimal_on_the_constraint_set(objectives, equality, problem, solution)
