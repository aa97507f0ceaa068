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
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse
from qpsolvers.conversions import combine_linear_box_inequalities

try:
    from proxsuite import proxqp
except ImportError:  # optional backend: qpsolvers then reports it as not installed
    proxqp = None
try:
    from daqp import solve as _daqp_solve
except ImportError:  # optional backend: qpsolvers then reports it as not installed
    _daqp_solve = None

__all__ = ["QP_ITERATION_LIMITS", "solve_qp_bounded"]

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
