"""Prioritized least squares (de Lasa 2010, Algorithm 1) checked against closed forms and its
defining properties: strict priority, inequalities, bounded and continuous near-singular levels."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import qpsolvers
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from controller_server.features import Objective
from controller_server.solvers import level_svd, prioritized
from controller_server.solvers.prioritized import (
    GRAM_CONDITION_LIMIT,
    Level,
    LevelReport,
    PrioritizedSolution,
    solve_prioritized,
)
from controller_server.solvers.qp import solve_qp_bounded

SOLVERS = ("daqp", "quadprog", "proxqp")
FEASIBILITY = 1e-7


def objective(name: str, A, b, weight: float = 1.0) -> Objective:
    A = np.atleast_2d(np.asarray(A, dtype=float))
    b = np.atleast_1d(np.asarray(b, dtype=float))
    return Objective(name, A, b, np.full(b.shape, float(weight)))


def no_inequalities(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((0, n)), np.zeros(0)


def low_rank(rng: np.random.Generator, m: int, n: int, rank: int) -> np.ndarray:
    return rng.normal(size=(m, rank)) @ rng.normal(size=(rank, n))


def weighted_rows(level: list[Objective]) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 37 for rows Σ w (A x − b)²: rows scaled by √w (independent of the solver's code)."""
    A = np.vstack([np.sqrt(o.weight)[:, None] * o.A for o in level])
    b = np.concatenate([np.sqrt(o.weight) * o.b for o in level])
    return A, b


def feasible_inequalities(rng, n: int, rows: int, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Random ``D x + f ≥ 0`` that a random point satisfies with slack in [0, margin]."""
    D = rng.normal(size=(rows, n))
    inside = rng.normal(size=n)
    return D, -D @ inside + rng.uniform(0.0, margin, rows)


def test_public_names():
    assert set(prioritized.__all__) == {
        "GRAM_CONDITION_LIMIT",
        "Level",
        "QP_TIME_BUDGET_S",
        "LevelReport",
        "PrioritizedSolution",
        "qp_data_limit",
        "solve_prioritized",
    }


# 1. Closed form ------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_two_unconstrained_levels_match_the_closed_form(seed):
    """x* = C₁ d₂ + d₁ (eq. 31, 36) with C₁ = null(A₁) and least-squares d₁, d₂ (scipy)."""
    rng = np.random.default_rng(seed)
    n = 15
    A1, b1 = low_rank(rng, 9, n, 6), rng.normal(size=9)  # rank 6, inconsistent
    A2, b2 = rng.normal(size=(12, n)), rng.normal(size=12)
    d1 = scipy.linalg.lstsq(A1, b1)[0]
    C1 = scipy.linalg.null_space(A1)
    d2 = scipy.linalg.lstsq(A2 @ C1, b2 - A2 @ d1)[0]
    expected = C1 @ d2 + d1

    solution = solve_prioritized(
        [[objective("first", A1, b1)], [objective("second", A2, b2)]], *no_inequalities(n)
    )

    np.testing.assert_allclose(solution.x, expected, rtol=1e-9, atol=1e-9)
    assert solution.found
    assert [level.status for level in solution.levels] == ["solved", "solved"]
    assert [level.rank for level in solution.levels] == [6, 9]
    assert [level.null_space_dimension for level in solution.levels] == [9, 0]
    assert solution.levels[0].damping == 0.0  # exact zeros are rank, not ill-conditioning
    assert solution.levels[0].residual == pytest.approx(np.linalg.norm(A1 @ d1 - b1), rel=1e-9)
    assert solution.levels[1].residual == pytest.approx(np.linalg.norm(A2 @ expected - b2))
    # One level alone: the minimum-norm least-squares solution (pseudo-inverse, λ = 0).
    alone = solve_prioritized([[objective("first", A1, b1)]], *no_inequalities(n))
    np.testing.assert_allclose(alone.x, d1, rtol=1e-9, atol=1e-10)


def test_objectives_in_a_level_combine_by_weight():
    """Eq. 16 and 37: one level of weighted objectives is their weighted least squares."""
    rng = np.random.default_rng(3)
    n = 6
    level = [
        objective("a", rng.normal(size=(4, n)), rng.normal(size=4), weight=9.0),
        objective("b", rng.normal(size=(5, n)), rng.normal(size=5), weight=0.25),
    ]
    A, b = weighted_rows(level)
    solution = solve_prioritized([level], *no_inequalities(n))
    np.testing.assert_allclose(solution.x, np.linalg.lstsq(A, b, rcond=None)[0], atol=1e-12)
    assert solution.levels[0].names == ("a", "b")
    assert solution.levels[0].residual == pytest.approx(np.linalg.norm(A @ solution.x - b))


# 2. Priority ---------------------------------------------------------------------------------


@st.composite
def priority_cases(draw):
    """A random level stack (rank-deficient above the last level) and a change below level 0."""
    n = draw(st.integers(4, 12))
    levels = draw(st.integers(2, 4))
    ranks = [draw(st.integers(1, max(1, n // levels))) for _ in range(levels - 1)]
    return {
        "seed": draw(st.integers(0, 2**32 - 1)),
        "n": n,
        "ranks": ranks,
        "constrained": draw(st.booleans()),
        "target": draw(st.integers(1, levels - 1)),
        "change": draw(st.sampled_from(["add objective", "reweight", "add level"])),
        "factor": draw(st.floats(1e-3, 1e3)),
        # proxqp is left out: identical calls can differ by ~1e-6 (run-to-run), more than the
        # 1e-8 this property is checked to.
        "solver": draw(st.sampled_from(["daqp", "quadprog"])),
    }


def build_stack(rng, n: int, ranks: list[int]) -> list[list[Objective]]:
    stack = []
    for i, rank in enumerate(ranks):
        rows = rank + int(rng.integers(0, 3))  # tall ones are inconsistent: nonzero residual
        stack.append([objective(f"level{i}", low_rank(rng, rows, n, rank), rng.normal(size=rows))])
    stack.append([objective("last", rng.normal(size=(n, n)), rng.normal(size=n))])
    return stack


@settings(max_examples=60, deadline=None, derandomize=True)
@given(priority_cases())
def test_lower_levels_never_change_higher_residuals(case):
    """Adding or re-weighting a lower-priority objective leaves every higher residual alone."""
    rng = np.random.default_rng(case["seed"])
    n = case["n"]
    stack = build_stack(rng, n, case["ranks"])
    if case["constrained"]:
        inequalities = feasible_inequalities(rng, n, 2 * n, margin=0.3)
    else:
        inequalities = no_inequalities(n)
    changed = [list(level) for level in stack]
    target = case["target"]
    extra = objective("extra", rng.normal(size=(3, n)), 10 * rng.normal(size=3), case["factor"])
    if case["change"] == "add objective":
        changed[target].append(extra)
    elif case["change"] == "add level":
        changed.insert(target, [extra])
    else:
        first = changed[target][0]
        changed[target][0] = Objective(first.name, first.A, first.b, first.weight * case["factor"])

    before = solve_prioritized(stack, *inequalities, qp_solver=case["solver"])
    after = solve_prioritized(changed, *inequalities, qp_solver=case["solver"])

    for i in range(target):
        scale = max(1.0, float(np.linalg.norm(weighted_rows(stack[i])[1])))
        assert abs(after.levels[i].residual - before.levels[i].residual) <= 1e-8 * scale
        assert after.levels[i].status == before.levels[i].status
    for solution in (before, after):
        if case["solver"] == "daqp":  # the others may fail at degenerate vertices
            assert solution.found
        if solution.levels[0].status == "solved":
            assert solution.inequality_violation <= FEASIBILITY


# 3. Inequalities -----------------------------------------------------------------------------


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(3, 12),
    rows=st.integers(1, 30),
    solver=st.sampled_from(SOLVERS),
)
def test_inequalities_hold_whenever_a_level_is_solved(seed, n, rows, solver):
    rng = np.random.default_rng(seed)
    stack = build_stack(rng, n, [max(1, n // 3)])
    D, f = feasible_inequalities(rng, n, rows, margin=0.1)
    solution = solve_prioritized(stack, D, f, qp_solver=solver)
    if solver == "daqp":  # quadprog and proxqp may fail at degenerate vertices
        assert [level.status for level in solution.levels] == ["solved", "solved"]
    if solution.levels[0].status == "solved":
        assert np.min(D @ solution.x + f) >= -FEASIBILITY
        assert solution.inequality_violation <= FEASIBILITY
    assert solution.found == all(level.status != "infeasible" for level in solution.levels)


@pytest.mark.parametrize("solver", SOLVERS)
def test_infeasible_inequalities_stop_at_the_first_level_with_zeros(solver):
    """Algorithm 1, lines 7–8: return d̄ (here 0), never raise."""
    n = 4
    D = np.zeros((2, n))
    D[0, 0], D[1, 0] = 1.0, -1.0
    f = np.array([-1.0, 0.0])  # x₀ ≥ 1 and x₀ ≤ 0
    rng = np.random.default_rng(0)
    levels = [
        [],
        [objective("top", rng.normal(size=(2, n)), [1.0, 2.0])],
        [objective("low", np.eye(n), np.ones(n))],
    ]
    solution = solve_prioritized(levels, D, f, qp_solver=solver)
    assert [level.status for level in solution.levels] == ["empty", "infeasible", "not reached"]
    np.testing.assert_array_equal(solution.x, np.zeros(n))
    assert not solution.found
    assert solution.inequality_violation == pytest.approx(1.0)
    assert solution.qp_solver == solver


@pytest.mark.parametrize("solver", SOLVERS)
def test_inactive_inequalities_leave_the_closed_form(solver):
    """Inequalities strictly satisfied by every intermediate d̄ change nothing and need no QP."""
    rng = np.random.default_rng(5)
    n = 8
    stack = build_stack(rng, n, [3, 2])
    intermediate = [solve_prioritized(stack[: i + 1], *no_inequalities(n)).x for i in range(3)]
    D = rng.normal(size=(10, n))
    f = np.max([-D @ d for d in intermediate], axis=0) + 0.1
    constrained = solve_prioritized(stack, D, f, qp_solver=solver)
    np.testing.assert_allclose(constrained.x, intermediate[-1], atol=1e-12)
    assert not any(level.used_qp for level in constrained.levels)
    # Tighten one row that only the last closed form violates: the last level needs a QP, and
    # its strictly convex optimum on the same affine set then lies on that row.
    f[0] = -D[0] @ intermediate[-1] - 0.5
    assert D[0] @ intermediate[0] + f[0] > 0 and D[0] @ intermediate[1] + f[0] > 0
    tightened = solve_prioritized(stack, D, f, qp_solver=solver)
    assert tightened.found
    assert [level.used_qp for level in tightened.levels] == [False, False, True]
    assert D[0] @ tightened.x + f[0] == pytest.approx(0.0, abs=FEASIBILITY)


# 4. Priority versus weights ------------------------------------------------------------------


def test_top_equality_is_met_and_only_the_conflicting_level_degrades():
    """Level 1: x₀ + x₁ = 1 (like the equations of motion); level 2: x₀ = 5, x₁ = 5."""
    top = objective("equation", [[1.0, 1.0]], [1.0])
    targets = objective("targets", np.eye(2), [5.0, 5.0])
    solution = solve_prioritized([[top], [targets]], *no_inequalities(2))
    assert solution.levels[0].residual <= 1e-9
    # Best for level 2 on the line of level 1's optima x = d₁ + C₁ t (eq. 31), by scipy.
    d1 = scipy.linalg.lstsq(top.A, top.b)[0]
    C1 = scipy.linalg.null_space(top.A)
    t = scipy.linalg.lstsq(C1, targets.b - d1)[0]
    np.testing.assert_allclose(solution.x, C1 @ t + d1, atol=1e-12)
    assert solution.levels[1].residual == pytest.approx(np.linalg.norm(C1 @ t + d1 - targets.b))

    # Weighted combination (eq. 16): the heavy lower objective pulls the top residual away.
    for weight, least in [(1.0, 2.9), (100.0, 8.8)]:
        heavy = objective("targets", np.eye(2), [5.0, 5.0], weight)
        weighted = solve_prioritized([[top, heavy]], *no_inequalities(2))
        A, b = weighted_rows([top, heavy])
        np.testing.assert_allclose(weighted.x, np.linalg.solve(A.T @ A, A.T @ b), atol=1e-12)
        assert abs(weighted.x.sum() - 1.0) > least


@pytest.mark.parametrize("solver", SOLVERS)
def test_top_equality_holds_when_an_inequality_is_active(solver):
    """With x₁ ≤ 0.2 the best point of level 2 on x₀ + x₁ = 1 is (0.8, 0.2)."""
    top = objective("equation", [[1.0, 1.0]], [1.0])
    targets = objective("targets", np.eye(2), [5.0, 5.0])
    solution = solve_prioritized(
        [[top], [targets]], np.array([[0.0, -1.0]]), np.array([0.2]), qp_solver=solver
    )
    assert solution.found
    assert solution.levels[0].residual <= 1e-9
    assert solution.levels[1].used_qp
    np.testing.assert_allclose(solution.x, [0.8, 0.2], atol=1e-7)


# 5. Near-singular levels ---------------------------------------------------------------------


def rotation(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def test_near_singular_level_is_bounded_and_continuous_through_one_over_B():
    """Maciejewski 1990, eq. 16–19: ‖x‖ ≤ B ‖b‖ and no jump as σ₂ crosses 1/B."""
    B = 100.0
    U, V = rotation(0.3), rotation(-1.1)
    b = np.array([0.3, -0.7])
    sigmas = np.linspace(0.2 / B, 3.0 / B, 2801)

    def solve(sigma: float) -> PrioritizedSolution:
        A = U @ np.diag([1.0, sigma]) @ V.T
        return solve_prioritized([[objective("ill", A, b)]], *no_inequalities(2), gain_bound=B)

    solutions = [solve(s) for s in sigmas]
    xs = np.array([solution.x for solution in solutions])
    assert np.all(np.linalg.norm(xs, axis=1) <= B * np.linalg.norm(b) * (1 + 1e-12))
    # σ/(σ² + λ(σ)²) is 4B²-Lipschitz in σ, and only the v₂ component moves.
    step = sigmas[1] - sigmas[0]
    jumps = np.linalg.norm(np.diff(xs, axis=0), axis=1)
    assert np.max(jumps) <= 4 * B**2 * step * abs(U[:, 1] @ b) * (1 + 1e-9)
    ranks = np.array([solution.levels[0].rank for solution in solutions])
    dampings = np.array([solution.levels[0].damping for solution in solutions])
    clear = np.abs(sigmas * B - 1.0) > 1e-9  # the SVD returns σ₂ to rounding
    np.testing.assert_array_equal(ranks[clear], np.where(sigmas >= 1.0 / B, 2, 1)[clear])
    np.testing.assert_array_equal(dampings[clear] > 0, (sigmas < 1.0 / B)[clear])
    # The test has teeth: a hard cut at 1/B (pseudo-inverse of the kept part) jumps by ≈ B |u₂ᵀb|.
    truncated = np.array(
        [V[:, 0] * (U[:, 0] @ b) + (s >= 1 / B) * V[:, 1] * (U[:, 1] @ b) / s for s in sigmas]
    )
    assert np.max(np.linalg.norm(np.diff(truncated, axis=0), axis=1)) > 100 * np.max(jumps)
    # Far below 1/B the damped gain vanishes (eq. 19) where the pseudo-inverse would explode.
    tiny = solve(1e-9)
    assert abs(tiny.x @ V[:, 1]) <= 4 * B**2 * 1e-9 * abs(U[:, 1] @ b) * (1 + 1e-9)


def test_directions_below_the_tolerance_cost_the_higher_level_at_most_tol_times_the_move():
    """The documented trade-off: σ < 1/B is passed down, the higher residual moves ≤ σ ‖Δx‖."""
    B = 100.0
    rng = np.random.default_rng(1)
    Q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    b = np.array([0.4, 0.9])
    lower = objective("lower", np.eye(3), [2.0, -3.0, 1.0])
    for sigma in [0.3 / B, 0.9 / B, 0.999 / B, 1.001 / B, 2.0 / B]:
        top = objective("top", np.diag([1.0, sigma]) @ Q[:, :2].T, b)
        alone = solve_prioritized([[top]], *no_inequalities(3), gain_bound=B)
        both = solve_prioritized([[top], [lower]], *no_inequalities(3), gain_bound=B)
        move = np.linalg.norm(both.x - alone.x)
        change = both.levels[0].residual - alone.levels[0].residual
        assert abs(change) <= sigma * move + 1e-12
        if sigma >= 1.0 / B:
            assert both.levels[0].residual <= 1e-12  # kept directions are never given away
        else:
            assert both.levels[0].rank == 1 and both.levels[0].null_space_dimension == 2
        if sigma == 0.999 / B:  # just below: the claim is soft, the lower level takes it back
            assert change > 0.5 * abs(b[1])


# 6. Solvers agree ----------------------------------------------------------------------------


def check_kkt(A: np.ndarray, b: np.ndarray, D: np.ndarray, f: np.ndarray, x: np.ndarray) -> None:
    """x solves min ‖A x − b‖² s.t. D x + f ≥ 0 (A full column rank): active-set KKT by scipy."""
    active = D @ x + f <= 1e-7
    G = D[active]
    n, k = A.shape[1], G.shape[0]
    kkt = np.block([[2 * A.T @ A, -G.T], [G, np.zeros((k, k))]])
    solution = scipy.linalg.solve(kkt, np.concatenate([2 * A.T @ b, -f[active]]))
    np.testing.assert_allclose(x, solution[:n], atol=1e-6)
    assert np.all(solution[n:] >= -1e-6)  # multipliers of ≥ constraints


@pytest.mark.parametrize("seed", range(8))
def test_qp_solvers_agree_on_a_strictly_convex_constrained_problem(seed):
    rng = np.random.default_rng(seed)
    n = 12
    A, b = rng.normal(size=(20, n)), 3 * rng.normal(size=20)  # full column rank
    D, f = feasible_inequalities(rng, n, 18, margin=0.2)
    xs = {}
    for solver in SOLVERS:
        solution = solve_prioritized([[objective("only", A, b)]], D, f, qp_solver=solver)
        assert solution.found and solution.levels[0].used_qp
        xs[solver] = solution.x
    for first, second in itertools.combinations(SOLVERS, 2):
        np.testing.assert_allclose(xs[first], xs[second], atol=1e-6)
    check_kkt(A, b, D, f, xs["daqp"])


# Cost: the same problem through faster paths -------------------------------------------------


def well_conditioned(rng: np.random.Generator, m: int, k: int, condition: float) -> np.ndarray:
    """``(m, k)`` with singular values spread from 1 down to ``1 / condition``."""
    left, _ = np.linalg.qr(rng.normal(size=(m, min(m, k))))
    right, _ = np.linalg.qr(rng.normal(size=(k, min(m, k))))
    return left @ np.diag(np.geomspace(1.0, 1.0 / condition, min(m, k))) @ right.T


@pytest.mark.parametrize(("m", "k"), [(45, 104), (12, 30), (47, 33), (20, 14)])
def test_gram_svd_is_the_svd_of_a_well_conditioned_level(m, k):
    """Singular values and the kept subspace as the SVD's; a complete orthonormal V.

    Within ε κ² (κ = 100): squaring the condition is what the Gram matrix costs."""
    rng = np.random.default_rng(m * k)
    A = well_conditioned(rng, m, k, 100.0)
    decomposition = (level_svd.gram_svd if m <= k else level_svd.gram_svd_tall)(A)
    assert decomposition is not None
    U, sigma, V = decomposition
    np.testing.assert_allclose(sigma, np.linalg.svd(A, compute_uv=False), rtol=1e-11)
    np.testing.assert_allclose(V.T @ V, np.eye(V.shape[1]), atol=1e-11)
    r = min(m, k)
    np.testing.assert_allclose(U[:, :r] @ np.diag(sigma) @ V[:, :r].T, A, atol=1e-12)
    if m < k:
        np.testing.assert_allclose(A @ V[:, m:], 0.0, atol=1e-12)


def test_gram_svd_declines_an_ill_conditioned_level():
    rng = np.random.default_rng(4)
    A = well_conditioned(rng, 10, 25, 10 * GRAM_CONDITION_LIMIT)
    assert level_svd.gram_svd(A) is None
    assert level_svd.gram_svd_tall(A.T) is None


@pytest.mark.parametrize(("k", "m"), [(104, 59), (20, 6), (7, 6), (5, 1)])
def test_orthogonal_complement_completes_an_orthonormal_basis(k, m):
    rng = np.random.default_rng(k + m)
    V, _ = np.linalg.qr(rng.normal(size=(k, m)))
    complement = level_svd.orthogonal_complement(V)
    basis = np.hstack([V, complement])
    np.testing.assert_allclose(basis.T @ basis, np.eye(k), atol=1e-14)


def test_daqp_is_called_as_qpsolvers_calls_it():
    """The direct call of solve_qp_bounded returns qpsolvers' DAQP solution bit for bit."""
    rng = np.random.default_rng(5)
    n = 30
    D, f = feasible_inequalities(rng, n, 40, margin=0.1)
    problem = qpsolvers.Problem(np.diag(rng.uniform(1e-12, 1.0, n)), rng.normal(size=n), -D, f)
    settings = {"primal_tol": 1e-9, "eta_prox": 1e-10}
    direct = solve_qp_bounded(problem, "daqp", **settings)
    through = qpsolvers.solve_problem(problem, solver="daqp", iter_limit=1000, **settings)
    assert direct.found and through.found
    np.testing.assert_array_equal(direct.x, through.x)
    np.testing.assert_array_equal(direct.z, through.z)
    assert direct.obj == through.obj


@pytest.mark.parametrize("seed", range(4))
def test_rows_given_as_a_level_solve_as_the_objectives(seed):
    rng = np.random.default_rng(seed)
    n = 12
    first = [objective("a", rng.normal(size=(3, n)), rng.normal(size=3), 4.0)]
    second = [
        objective("b", rng.normal(size=(4, n)), rng.normal(size=4), 2.0),
        objective("c", rng.normal(size=(5, n)), rng.normal(size=5)),
    ]
    D, f = feasible_inequalities(rng, n, 10, margin=0.1)
    rows = [Level(tuple(o.name for o in level), *weighted_rows(level)) for level in (first, second)]
    as_objectives = solve_prioritized([first, second], D, f)
    as_rows = solve_prioritized(rows, D, f)
    np.testing.assert_allclose(as_rows.x, as_objectives.x, rtol=1e-12, atol=1e-12)
    assert [level.names for level in as_rows.levels] == [("a",), ("b", "c")]


@pytest.mark.parametrize("seed", range(4))
def test_a_null_space_part_the_levels_below_cannot_see_changes_nothing(seed, monkeypatch):
    """Equations of motion, then a level on q̈ alone and one on λ, as in the controller: the
    motionless forces kept apart (the q̈ level leaves them out of its SVD) or not, the same
    solution."""
    rng = np.random.default_rng(seed)
    nu, nv, nl = 6, 8, 12
    n = nu + nv + nl
    S_T = np.vstack([np.zeros((nv - nu, nu)), np.eye(nu)])
    M = well_conditioned(rng, nv, nv, 3.0)
    M = M @ M.T + np.eye(nv)
    G = rng.normal(size=(nv, nl))
    dynamics = np.hstack([S_T, -M, G])
    # (τ, 0, λ) with Sᵀ τ + G λ = 0: λ in null(G_root), τ = −G_joints λ.
    balanced = scipy.linalg.null_space(G[: nv - nu])
    motionless, _ = np.linalg.qr(
        np.vstack([-G[nv - nu :] @ balanced, np.zeros((nv, balanced.shape[1])), balanced])
    )
    on_acceleration = np.zeros((5, n))
    on_acceleration[:, nu : nu + nv] = rng.normal(size=(5, nv))
    targets, bias = rng.normal(size=5), rng.normal(size=nv)
    forces = np.hstack([np.zeros((nl, nu + nv)), np.eye(nl)])
    D, f = forces.copy(), np.zeros(nl)  # λ ≥ 0
    gram_results = []
    real_gram_svd = prioritized.gram_svd

    def spy(*args):
        gram_results.append(real_gram_svd(*args))
        return gram_results[-1]

    monkeypatch.setattr(prioritized, "gram_svd", spy)

    def solve(part):
        levels = [
            Level(("dynamics",), dynamics, bias, well_conditioned=True, null_space_part=part),
            Level(("pose",), on_acceleration, targets),
            Level(("forces",), forces, np.zeros(nl)),
        ]
        return solve_prioritized(levels, D, f, gain_bound=[1e15, 1e4, 1e4])

    without, with_part = solve(None), solve(motionless)
    assert all(result is not None for result in gram_results)
    np.testing.assert_allclose(with_part.x, without.x, rtol=1e-8, atol=1e-8)
    assert [lv.rank for lv in with_part.levels] == [lv.rank for lv in without.levels]
    assert with_part.found and without.found


@pytest.mark.parametrize("seed", range(4))
def test_a_row_basis_solves_the_same_least_squares(seed):
    """24 rows of rank 12 (two rigid soles) solved in their 12-dimensional span: the same x,
    ranks and residuals, under inequalities and a level below."""
    rng = np.random.default_rng(seed)
    n = 20
    span, _ = np.linalg.qr(rng.normal(size=(24, 12)))
    A = span @ rng.normal(size=(12, n))
    b = rng.normal(size=24)  # partly outside the span: a residual no x removes
    below = rng.normal(size=(n, n)), rng.normal(size=n)
    D, f = feasible_inequalities(rng, n, 15, margin=0.1)

    def solve(basis):
        levels = [Level(("soles",), A, b, row_basis=basis), Level(("below",), *below)]
        return solve_prioritized(levels, D, f, gain_bound=1e4)

    full, reduced = solve(None), solve(span)
    np.testing.assert_allclose(reduced.x, full.x, rtol=1e-9, atol=1e-9)
    for mine, theirs in zip(reduced.levels, full.levels, strict=True):
        assert (mine.rank, mine.null_space_dimension) == (theirs.rank, theirs.null_space_dimension)
        assert mine.residual == pytest.approx(theirs.residual, rel=1e-9)


# Reports and validation ----------------------------------------------------------------------


def test_a_full_rank_level_leaves_the_rest_not_reached():
    rng = np.random.default_rng(2)
    n = 5
    levels = [
        objective("full", rng.normal(size=(n, n)), rng.normal(size=n)),
        [],
        [objective("after", np.eye(n), np.zeros(n))],
    ]
    solution = solve_prioritized(levels, *no_inequalities(n))
    statuses = [level.status for level in solution.levels]
    assert statuses == ["solved", "not reached", "not reached"]
    assert isinstance(solution.levels[0], LevelReport)
    assert solution.levels[0].null_space_dimension == 0
    assert solution.levels[2].residual == pytest.approx(np.linalg.norm(solution.x))
    assert solution.solve_time_s > 0


def test_invalid_input_is_refused_with_context():
    with pytest.raises(ValueError, match="'bad'"):
        solve_prioritized([[objective("bad", np.ones((2, 3)), np.ones(2))]], *no_inequalities(4))
    with pytest.raises(ValueError, match="'negative'"):
        solve_prioritized(
            [[objective("negative", np.ones((1, 2)), [1.0], -1.0)]], *no_inequalities(2)
        )
    with pytest.raises(ValueError, match="qp_solver"):
        solve_prioritized([], *no_inequalities(2), qp_solver="no such solver")
    with pytest.raises(ValueError, match="gain_bound"):
        solve_prioritized([], *no_inequalities(2), gain_bound=0.0)


def test_a_qp_failure_below_the_top_level_skips_only_that_level(monkeypatch):
    """Below a solved level w = 0 is feasible: a failing QP solver is not infeasibility."""
    monkeypatch.setattr(prioritized, "solve_qp_chain", lambda *args, **kwargs: None)
    levels = [
        [Objective("first", np.array([[1.0, 0.0, 0.0]]), np.array([1.0]), np.ones(1))],
        [Objective("needs a QP", np.array([[0.0, 1.0, 0.0]]), np.array([5.0]), np.ones(1))],
        [Objective("third", np.array([[0.0, 0.0, 1.0]]), np.array([3.0]), np.ones(1))],
    ]
    D = np.array([[0.0, -1.0, 0.0]])  # x1 ≤ 0.2: the second level's closed form violates it
    f = np.array([0.2])
    solution = solve_prioritized(levels, D, f)
    assert [level.status for level in solution.levels] == ["solved", "solver failed", "solved"]
    np.testing.assert_allclose(solution.x, [1.0, 0.0, 3.0], atol=1e-12)
    assert not solution.found
