"""Dense QPs within iteration caps, by any solver ``qpsolvers`` knows.

Both controllers solve small dense QPs every tick: the prioritized levels
(de Lasa et al. 2010, Algorithm 1) and the inverse dynamics' nearest feasible
motion. Every solve is capped in iterations (:data:`QP_ITERATION_LIMITS`), so
a hard problem costs a bounded time. DAQP (the default) and ProxQP are called
directly with the arguments ``qpsolvers`` would pass them: its checks and
conversions cost more than the solve of a small problem, and it passes ProxQP
no inner-iteration cap.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse
from qpsolvers.conversions import combine_linear_box_inequalities
from qpsolvers.exceptions import QPError

try:
    from proxsuite import proxqp
except ImportError:  # optional backend: qpsolvers then reports it as not installed
    proxqp = None
try:
    from daqp import solve as _daqp_solve
except ImportError:  # optional backend: qpsolvers then reports it as not installed
    _daqp_solve = None

__all__ = [
    "FALLBACK_ORDER",
    "QP_BACKENDS",
    "QP_ITERATION_LIMITS",
    "QPBackend",
    "QPClock",
    "solve_qp_bounded",
    "solve_qp_chain",
]

QP_ITERATION_LIMITS: dict[str, dict[str, int]] = {
    # Active-set iterations; at most 77 on seeded near-standing states of the built-in models
    # (p99 222 on the test stacks). Each costs ~5–10 µs at 116 unknowns.
    "daqp": {"iter_limit": 1000},
    # Outer (augmented Lagrangian) and inner (semi-smooth Newton) iterations: converged solves
    # of the built-in models took up to 731 outer and ~2 inner ones each. ProxQP's default of
    # 1500 inner iterations per outer one made a capped solve still run for minutes.
    "proxqp": {"max_iter": 1000, "max_iter_in": 20},
}
"""Iteration caps of every QP solve (:func:`solve_qp_bounded`); quadprog needs none."""


def solve_qp_bounded(
    problem: qpsolvers.Problem, solver: str, **settings: Any
) -> qpsolvers.Solution:
    """:func:`qpsolvers.solve_problem` within the iteration caps of :data:`QP_ITERATION_LIMITS`.

    ``settings`` may lower a cap but not raise it. ProxQP is called through its own dense
    ``QP`` class (same settings, same defaults), because ``qpsolvers`` passes on only the
    options of ``proxqp.dense.solve``, which lack the inner-iteration cap ``max_iter_in``.
    DAQP, on dense inequality-only problems (the prioritized levels' QPs), is called
    directly with exactly the arguments ``qpsolvers`` would pass it: its checks and
    conversions cost more than the solve of a small level.

    A problem without unknowns (no contact force when no foot is in support) is solved
    here, for every solver: quadprog indexes out of bounds and ProxQP refuses a size of 0.

    Raises:
        qpsolvers.exceptions.QPError: As :func:`qpsolvers.solve_problem` (unknown solver,
            inconsistent problem).
    """
    limits = QP_ITERATION_LIMITS.get(solver, {})
    capped = {**settings, **{key: min(cap, settings.get(key, cap)) for key, cap in limits.items()}}
    P, q, G, h, A, b, lb, ub = problem.unpack()
    if q.size == 0:
        return _solve_empty(problem, h, b)
    if (
        solver == "daqp"
        and _daqp_solve is not None
        and type(P) is np.ndarray
        and type(G) is np.ndarray
        and h is not None
        and (A is None or type(A) is np.ndarray)
        and lb is None
        and ub is None
    ):
        return _solve_daqp(problem, P, q, G, h, A, b, capped)
    dense = not any(scipy.sparse.issparse(matrix) for matrix in (P, G, A))
    if solver != "proxqp" or proxqp is None or not dense:
        if solver == "proxqp":  # qpsolvers' proxqp_solve_problem knows no max_iter_in
            capped.pop("max_iter_in", None)
        return qpsolvers.solve_problem(problem, solver=solver, **capped)
    C, upper, lower = combine_linear_box_inequalities(G, h, lb, ub, q.size, False)
    model = proxqp.dense.QP(
        q.size,
        0 if A is None else A.shape[0],
        0 if C is None else C.shape[0],
        dense_backend=proxqp.dense.DenseBackend.PrimalDualLDLT,  # as proxqp.dense.solve
    )
    for key, value in capped.items():
        if not hasattr(model.settings, key):
            raise qpsolvers.ParamError(f"unknown ProxQP setting {key!r}")
        setattr(model.settings, key, value)
    start = time.perf_counter()
    model.init(P, q, A, b, C, lower, upper)
    model.solve()
    info = model.results.info
    return qpsolvers.Solution(
        problem,
        extras={"info": info},
        found=info.status == proxqp.QPSolverOutput.PROXQP_SOLVED,
        x=np.array(model.results.x),
        solve_time=time.perf_counter() - start,
    )


def _solve_empty(
    problem: qpsolvers.Problem, h: np.ndarray | None, b: np.ndarray | None
) -> qpsolvers.Solution:
    """The QP of no unknowns: ``x = []``, found if ``0 ≤ h`` and ``b = 0`` (rows of no unknown)."""
    solution = qpsolvers.Solution(problem)
    h = np.zeros(0) if h is None else np.asarray(h, float)
    b = np.zeros(0) if b is None else np.asarray(b, float)
    solution.found = bool(np.all(h >= 0.0) and np.all(b == 0.0))
    if solution.found:
        solution.x = np.zeros(0)
        solution.obj = 0.0
        solution.z, solution.y, solution.z_box = np.zeros(h.size), np.zeros(b.size), np.zeros(0)
    solution.build_time = solution.solve_time = 0.0
    return solution


def _solve_daqp(
    problem: qpsolvers.Problem,
    P: np.ndarray,
    q: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    A: np.ndarray | None,
    b: np.ndarray | None,
    settings: dict[str, Any],
) -> qpsolvers.Solution:
    """``min ½ xᵀ P x + qᵀ x  s.t.  G x ≤ h, A x = b`` by ``daqp.solve``, as ``qpsolvers`` calls it.

    The same arguments as ``qpsolvers.solvers.daqp_.daqp_solve_problem`` (``h`` then ``b`` as
    the upper bounds, ``-1e30`` below, the equality rows last with DAQP's ``sense`` 5), so the
    same result.
    """
    if G.ndim != 2 or h.shape != (G.shape[0],):  # what Problem.check_constraints refuses
        raise qpsolvers.ProblemError(f"inconsistent G x ≤ h: {G.shape=}, {h.shape=}")
    inequalities = G.shape[0]
    build_start = time.perf_counter()
    if A is not None and b is not None and len(A):
        if A.ndim != 2 or b.shape != (A.shape[0],):
            raise qpsolvers.ProblemError(f"inconsistent A x = b: {A.shape=}, {b.shape=}")
        G, h = np.vstack([G, A]), np.concatenate([h, b])
    rows = G.shape[0]
    lower = np.full(rows, -1e30)
    sense = np.zeros(rows, dtype=np.intc)
    sense[inequalities:] = 5
    solve_start = time.perf_counter()
    x, objective, exitflag, info = _daqp_solve(P, q, G, h, lower, sense, **settings)
    solve_end = time.perf_counter()
    solution = qpsolvers.Solution(problem)
    solution.found = exitflag > 0
    if exitflag > 0:
        solution.x = x
        solution.obj = objective
        solution.z_box = info["lam"][:0]
        solution.z = info["lam"][:inequalities]
        solution.y = info["lam"][inequalities:]
    solution.build_time = solve_start - build_start
    solution.solve_time = solve_end - solve_start
    return solution


# The chain of solvers a prioritized level tries ---------------------------------------------

FALLBACK_ORDER = ("daqp", "quadprog", "proxqp")
"""Solvers tried, in this order, after the chosen one fails on a QP."""


@dataclass(frozen=True)
class QPBackend:
    """How one QP solver is called (values measured on random prioritized stacks).

    Attributes:
        settings: Solver options; tolerances well below the feasibility tolerance (1e-7) the
            result is checked against.
        retry: Options changed for a second attempt after a failure.
        curvature_floor: Floor on the curvature of the directions passed down, relative to
            the largest curvature.
        bound_relaxation: Inequalities relaxed by this fraction of the feasibility tolerance.
    """

    settings: dict[str, float | bool]
    retry: dict[str, float] | None = None
    curvature_floor: float = 0.0
    bound_relaxation: float = 0.0


QP_BACKENDS: dict[str, QPBackend] = {
    # Default primal tolerance 1e-6. Automatic proximal-point iterations (on Hessians daqp finds
    # singular) stop at eta_prox = 1e-6 by default, leaving top-level residuals ~1e-8, and at
    # 1e-12 sometimes hit the iteration limit. Hessians it finds regular but spanning ≳ 1e10
    # (small σ_max next to 1/(4B²)) can make it report a feasible level infeasible: forced
    # proximal iterations solve those, but are slow on large levels, hence only on retry.
    "daqp": QPBackend({"primal_tol": 1e-9, "eta_prox": 1e-10}, retry={"eps_prox": 1e-6}),
    # Goldfarb–Idnani, built on the inverse Cholesky factor: violated active inequalities by
    # ~1e-6 at curvature ratios (2 B σ_max)² ≈ 1e16, and fails at degenerate vertices unless
    # they are perturbed into small polytopes.
    "quadprog": QPBackend({}, curvature_floor=1e-12, bound_relaxation=1e-2),
    # Default eps_abs 1e-5. Declares degenerate feasible levels infeasible; asked for the closest
    # feasible point instead, it returns the optimum there (checked by _solve_level), but in that
    # mode once stopped early (objective 2e-5 off) unless the duality gap is checked too. The
    # iteration caps (QP_ITERATION_LIMITS) make a truly infeasible level cost ~10 ms (both
    # attempts) instead of ~1 s.
    "proxqp": QPBackend(
        {
            "eps_abs": 1e-9,
            "eps_rel": 0.0,
            "primal_infeasibility_solving": True,
            "check_duality_gap": True,
        },
        retry={"eps_abs": 1e-8},
    ),
}


_DEFAULT_BACKEND = QPBackend({})


@dataclass
class QPClock:
    """The QP solves of one prioritized solve, against its time budget."""

    budget_s: float
    attempts: int = 0
    spent_s: float = 0.0
    refusals: int = 0

    def allows(self, fallback: bool) -> bool:
        """Whether a QP may start: a solver's first attempt always, a fallback within budget."""
        allowed = not fallback or self.spent_s < self.budget_s
        self.refusals += not allowed
        return allowed


def solve_qp_chain(
    curvature: np.ndarray,
    linear: np.ndarray,
    D_C_bar_V: np.ndarray,
    bound: np.ndarray,
    qp_solver: str,
    rank: int,
    feasibility_tolerance: float,
    fallbacks: bool,
    clock: QPClock,
    first: bool,
) -> np.ndarray | None:
    """``min ½ Σ hᵢ zᵢ² − Σ lᵢ zᵢ  s.t.  D C̄ V z + bound ≥ 0`` (eq. 35 in ``z = Vᵀ w``).

    The chosen solver first (with its retry settings), then, with
    ``fallbacks``, the other tested solvers: an active-set solver stalling on a
    degenerate vertex does not make the problem infeasible. Each call is capped in
    iterations (:func:`solve_qp_bounded`). With ``first`` (the level's first curvature) each
    solver's first settings always run; retry settings, and every attempt without
    ``first``, only while ``clock``'s budget lasts.
    """
    names = [qp_solver]
    if fallbacks:
        names += [
            name
            for name in FALLBACK_ORDER
            if name != qp_solver and name in qpsolvers.available_solvers
        ]
    gradient = np.zeros(curvature.size)
    np.negative(linear, out=gradient[: linear.size])
    G = -D_C_bar_V
    for name in names:
        backend = QP_BACKENDS.get(name, _DEFAULT_BACKEND)
        problem_curvature = curvature
        if backend.curvature_floor:  # only in the directions passed down, never the kept ones
            problem_curvature = curvature.copy()
            floor = backend.curvature_floor * curvature.max()
            np.maximum(problem_curvature[rank:], floor, out=problem_curvature[rank:])
        relaxed = bound
        if backend.bound_relaxation:
            relaxed = bound + backend.bound_relaxation * feasibility_tolerance
        problem = qpsolvers.Problem(np.diag(problem_curvature), gradient, G, relaxed)
        attempts = [backend.settings]
        if backend.retry is not None:
            attempts.append({**backend.settings, **backend.retry})
        for retry, settings in enumerate(attempts):
            # Past the budget every solver of the chain is still tried once, but nothing
            # twice: no retry settings, no second curvature.
            if not clock.allows(fallback=retry > 0 or not first):
                break
            start = time.perf_counter()
            try:
                solution = solve_qp_bounded(problem, name, **settings)
            except (QPError, ValueError, np.linalg.LinAlgError):
                continue
            finally:
                clock.attempts += 1
                clock.spent_s += time.perf_counter() - start
            info = solution.extras.get("info") if isinstance(solution.extras, dict) else None
            closest = info is not None and str(info.status).endswith("CLOSEST_PRIMAL_FEASIBLE")
            z = solution.x
            if (solution.found or closest) and z is not None and np.isfinite(z).all():
                return z
    return None
