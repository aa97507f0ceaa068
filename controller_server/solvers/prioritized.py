"""Constrained prioritized least squares (de Lasa, Mordatch & Hertzmann 2010, Algorithm 1).

Objectives are grouped into priority levels, highest first. Level ``i``
minimizes its weighted residual ``‖W^{½}(Aᵢ x − bᵢ)‖²`` only over the
solutions left optimal by the levels above it, subject to inequalities
``D x + f ≥ 0`` (de Lasa 2010, eq. 17, 28–30). Within a level, objectives
are combined by weights (eq. 16): each row is scaled by ``√weight``, the
form of eq. 37 for our :class:`~controller_server.features.Objective`
convention ``Σ wᵢ (Aᵢ x − bᵢ)²``.

The reparameterization method (§8.2, eq. 31–36) keeps the optimal set of
the levels solved so far as ``x = C̄ w + d̄`` with orthonormal ``C̄``::

    C̄ ← I, d̄ ← 0
    for each level (A, b):
        Ā = A C̄,  b̄ = b − A d̄                                   (eq. 33)
        w = argmin ‖Ā w − b̄‖² + damping  s.t.  D C̄ w + D d̄ + f ≥ 0  (eq. 34–35)
        if infeasible: return d̄
        d̄ ← d̄ + C̄ w                                             (eq. 36)
        if Ā has full column rank: return d̄
        C̄ ← C̄ null(Ā)

Rank and null space, from one SVD ``Ā = U Σ Vᵀ`` per level: a singular
direction with ``σᵢ < 1/B`` could only be used with a gain
``‖w‖ / ‖b̄‖ > B`` (Maciejewski 1990, eq. 18), so it is treated as singular
and passed on to the lower levels, like the exact null space. The rank
tolerance is ``max(1/B, σ_max · max(m, k) · ε)``; the second term is the
rounding floor, below which a singular value is noise rather than small
(those directions get no gain at all, as if σ = 0). Trade-off: a
direction with ``0 < σ < tol`` may be moved by a lower level by ``Δw``,
which changes this level's residual by at most ``σ ‖Δw‖ < tol ‖Δw‖``; in
such directions the level's claim is soft. ``1/B`` compares singular
values with unit weights, so levels should be expressed in comparable
units (rows scaled so that a unit of residual means as much in every
level); the default ``B = 10⁶`` assumes that.

Damping (Maciejewski 1990, eq. 15–19): each singular direction gets its
own ``λᵢ = damping_for_gain_bound(σᵢ, B)``
(:mod:`controller_server.math.damped`). The directions a level keeps
(``σᵢ ≥ tol ≥ 1/B``) get ``λᵢ = 0``: the level is met exactly there, and
nothing below can disturb it. The directions passed down get the damped
gain ``σᵢ / (σᵢ² + λᵢ²) ≤ B`` (eq. 16, 18), which tends to ``B = 1/σᵢ`` as
``σᵢ → 1/B`` and to 0 as ``σᵢ → 0`` (eq. 19). So every step obeys
``‖w‖ ≤ B ‖b̄‖`` and is a continuous function of ``Ā`` and ``b̄`` while
singular values cross ``1/B``. A single λ for the whole level, chosen from
its smallest singular value, would also damp the kept directions and leave
residuals there that no lower level may remove; with one λ per direction
the reported damping is the largest, ``damping_for_gain_bound(σ_min, B)``
over the singular values above the rounding floor. What is not continuous
is the lower levels' freedom: when ``σᵢ`` crosses the tolerance they gain
or lose direction ``i``, bounded as above.

Inequalities: without rows in ``D`` every level is solved in closed form
from its SVD. With rows, the closed form is tried first and kept if it
satisfies the inequalities (it is then the QP's optimum); otherwise the QP
``min ‖Ā w − b̄‖² + Σᵢ λᵢ² (vᵢᵀ w)²`` (eq. 35, damped) is solved with
:func:`qpsolvers.solve_problem` in the coordinates ``z = Vᵀ w``, where its
Hessian is the diagonal ``σᵢ² + λᵢ²`` (λ = 1/(2B) for the weak directions
σ < 1/(2B)), and ``(10⁻⁶ σ_max)²`` in the directions without gain (σ = 0
or at the rounding floor): strictly convex, yet small against the level's
own residual, so an active inequality is met by moving along the null
space rather than by giving up part of the level. If every solver fails on
that QP (DAQP and quadprog once declared a feasible equations-of-motion
level infeasible), it is solved again with ``(10⁻⁴ σ_max)²``. Below the first
level ``w = 0`` is feasible; violations already accepted there may persist
but not grow, so the QP starts exactly feasible. Solver failures (an
exception, no solution, non-finite output) and solutions violating
``D x + f ≥ 0`` by more than the feasibility tolerance count as infeasible
(Algorithm 1, line 7); below the first level that can only be a solver
failure.

The QP is ill-conditioned by design (curvature ratio up to
``(2 B σ_max)² ≈ 10¹⁶``) and lower levels often sit at degenerate vertices
(more active inequalities than unknowns left), so each solver gets settings
of its own (:data:`~.qp.QP_BACKENDS`). quadprog alone needs regularization: the
curvature of the directions passed down is floored at ``10⁻¹² σ_max²``, and
the inequalities are relaxed by 1 % of the feasibility tolerance. The
floor makes a level a little less willing to move those directions to meet
an inequality, its residual growing by about ``10⁻¹² σ_max² ‖w_null‖ / σ``
(up to 3e-8 against daqp's 1e-13 on 100-unknown tests). On 3000 random stacks
(3–12 unknowns, 2–5 levels, 1–30 inequalities, many of them degenerate)
daqp (the default) solved all, quadprog failed on 0.2 % and proxqp on
1.2 %. Relative to daqp's, their ``x`` differed by a median of 3e-9
(quadprog) and 3e-10 (proxqp), at worst by 4e-5 and 1e-3 (ill-conditioned
vertices, where the inequality tolerances matter); proxqp is moreover not
exactly repeatable (identical calls once differed by 1e-6).

Every QP solve is bounded. Each solver call has an iteration cap
(:data:`~.qp.QP_ITERATION_LIMITS`; quadprog, an active-set method, ends by
itself), and one call of :func:`solve_prioritized` tries no QP twice (retry
settings, second curvature) once its QP solves have taken
:data:`QP_TIME_BUDGET_S` of wall time: a level whose solvers have each failed
once then fails. Nor is a QP started on inequality data too large for the
feasibility test to mean anything (:func:`qp_data_limit`): with ``|D x + f|``
beyond ``tolerance / ε``, rounding alone exceeds the tolerance, no solver can
meet it (their own tolerances are absolute too), and the iterative ones spin
to their caps, or overflow into NaN residuals they never recover from. With
joint velocities of 1e150 (data ~1e300) ProxQP ran the full 1500 inner
iterations of each of its 1000 outer ones: ~24 s per call, minutes per tick.

The equations of motion are not special: as de Lasa 2010 (§8.2, after eq.
36) recommend, give them as the top-priority level rather than as
equality constraints.

Blocks. ``C̄`` is kept as orthonormal blocks, mutually orthogonal, side by
side. A level whose rows ``A`` are exactly zero on a block (``A B = 0``
bit for bit) cannot see it: those directions would be exactly null in the
SVD of ``A C̄``, so they are left out of it and given, in the QP, the
curvature of the directions without gain (which any orthonormal basis of
them gets alike: the QP is the same problem). The first level may name a
part of its null space to keep as a block of its own
(:attr:`Level.null_space_part`); the prioritized controller names the
contact forces that torques balance without any motion, which every
objective on ``q̈`` is blind to, so that the SVDs of those levels have
``nλ − 6`` fewer columns and the CM-height level below a pose that fixes
every ``q̈`` sees nothing at all.

Cost. A level's SVD, its QP and a few products make the solve; at the sizes
of a humanoid (``Ā`` up to 45 × 104) LAPACK's small-matrix routines and
each call's dispatch dominate. A wide level known to have independent,
well-conditioned rows (:attr:`Level.well_conditioned`: the equations of
motion, ``M ≻ 0``, condition ~100) takes its SVD from the eigendecomposition
of ``Ā Āᵀ`` and its null space from one Householder QR; a tall one
(``m ≥ k ≥ 8``) tries ``Āᵀ Ā``. Squaring loses ``ε κ²`` relative in the
smallest singular value, so both are used only up to ``κ =``
:data:`GRAM_CONDITION_LIMIT` (the SVD otherwise). A level whose rows combine
fewer dimensions than they are (the points of a rigid sole: 24 rows, rank 12)
may come with an orthonormal basis of their span (:attr:`Level.row_basis`):
solved in it, the level is the same least squares with ``r`` rows, the
wide, well-conditioned kind that the eigendecomposition serves. DAQP is called directly
with the arguments ``qpsolvers`` would give it (:func:`~.qp.solve_qp_bounded`).
None of this changes the problem, only rounding: its QPs are fed the same
data up to it (their proximal-point iterations make the solution depend on
the coordinates, so ``z = Vᵀ w`` stays the SVD's, up to rotations of
directions that share one curvature).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import qpsolvers
from scipy.linalg import lapack as _lapack

from controller_server.features.objective import Objective
from controller_server.math.damped import damping_for_gain_bound
from controller_server.solvers.level_svd import (
    GRAM_CONDITION_LIMIT,
    GRAM_MIN_COLUMNS,
    gram_svd,
    gram_svd_tall,
)
from controller_server.solvers.levels import (
    Level,
    LevelReport,
    PrioritizedSolution,
    stack_level,
)
from controller_server.solvers.qp import QPClock, solve_qp_chain
from controller_server.solvers.seen_blocks import SeenBlocks

__all__ = [
    "GRAM_CONDITION_LIMIT",
    "QP_TIME_BUDGET_S",
    "Level",
    "LevelReport",
    "PrioritizedSolution",
    "qp_data_limit",
    "solve_prioritized",
]

QP_TIME_BUDGET_S = 0.02
"""Wall time (s) of the QP solves of one :func:`solve_prioritized` call after which no QP is
tried twice: no solver's retry settings, no second null-space curvature. A level whose QP
has not succeeded by then fails as if every solver had (``"solver failed"``, or
``"infeasible"`` at the top level). Each solver of a level's chain (the chosen one; at the
top level also the others) is still tried once, capped by :data:`~.qp.QP_ITERATION_LIMITS`: a
slow machine loses only second tries, and the top level keeps its rescue by another solver
(ProxQP, when chosen, can take 50 ms on a feasible level near standing). A tick thus costs
at most about this budget plus one capped call per level and solver. With daqp, ticks near
standing spend under 1 ms in QPs."""

_EPSILON = float(np.finfo(float).eps)
_TINY = float(np.finfo(float).tiny)
_NULL_CURVATURES = (1e-6, 1e-4)
"""QP curvature of the directions without gain (σ = 0 or at the rounding floor), relative to
σ_max, tried in turn: strictly convex yet small against every kept direction (σ ≥ 1/B), so
that an active inequality is met by moving along the null space rather than by giving up this
level's residual; the larger one only when the solvers fail on the worse-conditioned QP."""


def solve_prioritized(
    levels: Sequence[Level | Sequence[Objective] | Objective],
    inequality_matrix: np.ndarray,
    inequality_offset: np.ndarray,
    *,
    gain_bound: float | Sequence[float] = 1e6,
    qp_solver: str = "daqp",
    feasibility_tolerance: float = 1e-7,
    qp_time_budget_s: float = QP_TIME_BUDGET_S,
    check_finite: bool = True,
    residuals: bool = True,
) -> PrioritizedSolution:
    """Solve the prioritized problem of de Lasa 2010, eq. 17, by Algorithm 1.

    See the module docstring for the rank tolerance, the damping and the QP.

    Args:
        levels: Priority levels, highest first; each a sequence of objectives over the same
            ``n`` unknowns, combined by their row weights (eq. 16, 37), or a :class:`Level`
            of rows already combined. A single :class:`Objective` counts as a level of one.
            Empty levels are skipped.
        inequality_matrix: ``D``, ``(p, n)`` (``p`` may be 0; it also fixes ``n``).
        inequality_offset: ``f``, ``(p,)``, for ``D x + f ≥ 0`` (eq. 28's ``D₀, f₀``).
        gain_bound: ``B``: singular values below ``1/B`` are treated as singular and the
            damping keeps every level's step within ``‖w‖ ≤ B ‖b̄‖``. Levels should be in
            comparable units. One value for all levels, or one per level.
        qp_solver: A :mod:`qpsolvers` solver name (tested: ``"daqp"``, ``"quadprog"``,
            ``"proxqp"``).
        feasibility_tolerance: Largest accepted violation of ``D x + f ≥ 0`` after a QP.
        qp_time_budget_s: No QP is tried twice (retry settings, second curvature) once the
            QP solves took this long (s). See :data:`QP_TIME_BUDGET_S`.
        check_finite: Refuse non-finite ``A`` or ``b`` of a :class:`Level` (``False``: the
            caller has checked them).
        residuals: Report each level's residual (``False``: NaN, for a caller that will not
            read them).

    Returns:
        The solution and per-level reports. Never raises for infeasible inequalities,
        solver failures, a spent time budget or inequality data too large to check: see
        :attr:`LevelReport.status` and :attr:`LevelReport.detail`.

    Raises:
        ValueError: On inconsistent shapes, negative or non-finite weights, non-finite
            ``A`` or ``b``, ``B ≤ 0``, or a QP solver that is not installed.
    """
    start = time.perf_counter()
    given = [float(gain_bound)] if isinstance(gain_bound, int | float) else list(gain_bound)
    bounds = given * len(levels) if isinstance(gain_bound, int | float) else given
    if len(bounds) != len(levels) or not all(b > 0.0 for b in given):
        raise ValueError(f"need one positive gain bound, or one per level; got {gain_bound=}")
    if qp_solver not in qpsolvers.available_solvers:
        raise ValueError(
            f"{qp_solver=} is not an installed qpsolvers backend; "
            f"available: {qpsolvers.available_solvers}"
        )
    D = np.asarray(inequality_matrix, dtype=float)
    f = np.asarray(inequality_offset, dtype=float)
    if D.ndim != 2 or f.shape != (D.shape[0],):
        raise ValueError(
            f"inequalities D x + f ≥ 0 need D (p, n) and f (p,), got {D.shape=}, {f.shape=}"
        )
    n = D.shape[1]
    stacked = [stack_level(level, n, check_finite) for level in levels]

    # C̄ as orthonormal blocks (basis, D basis); None stands for I (saves an n × n product).
    blocks: list[tuple[np.ndarray, np.ndarray]] | None = None
    d_bar: np.ndarray | None = None  # None stands for 0
    slack = f.copy()  # D d̄ + f, kept up to date with d̄
    reports: list[LevelReport] = []
    clock = QPClock(qp_time_budget_s)
    stopped = infeasible = failed = solved_any = False
    for level_index, level in enumerate(stacked):
        names, A, b = level.names, level.A, level.b
        if level.row_basis is not None:  # the same least squares in r ≤ m rows
            A, b = level.row_basis.T @ A, level.row_basis.T @ b
        if stopped:
            reports.append(LevelReport(names, "not reached", 0.0, 0, 0, 0.0, 0.0, False))
            continue
        dimension = n if blocks is None else sum(basis.shape[1] for basis, _ in blocks)
        if A.shape[0] == 0:
            reports.append(LevelReport(names, "empty", 0.0, 0, dimension, 0.0, 0.0, False))
            continue
        seen = SeenBlocks.of(A, D, blocks)  # Algorithm 1, line 3: Ā = A C̄, block by block
        b_bar = b if d_bar is None else b - A @ d_bar  # line 4
        step = _solve_level(
            seen,
            b_bar,
            slack,
            dimension,
            bounds[level_index],
            qp_solver,
            feasibility_tolerance,
            persist=level_index == 0,
            clock=clock,
            gram=level.well_conditioned or level.row_basis is not None,
            rows=level.A.shape[0],
            null_space_part=level.null_space_part if blocks is None else None,
        )
        if step.w is None and level_index > 0 and solved_any:
            # Below a solved level w = 0 is feasible, so this is the QP solver failing, not
            # Algorithm 1's infeasibility: keep d̄ and C̄ and go on with the next level.
            reports.append(
                LevelReport(
                    names,
                    "solver failed",
                    0.0,
                    0,
                    dimension,
                    step.damping,
                    step.tolerance,
                    True,
                    step.detail,
                )
            )
            failed = True
            continue
        if step.w is None:  # lines 7–8: keep d̄ of the levels above
            reports.append(
                LevelReport(
                    names,
                    "infeasible",
                    0.0,
                    0,
                    0,
                    step.damping,
                    step.tolerance,
                    step.used_qp,
                    step.detail,
                )
            )
            stopped = infeasible = True
            continue
        move = seen.to_x(step.w, step.w_unseen)
        d_bar = move if d_bar is None else d_bar + move  # line 10
        slack = step.slack
        blocks = seen.null_blocks(step.null_parts)  # line 14: C̄ ← C̄ null(Ā)
        dimension = sum(basis.shape[1] for basis, _ in blocks)
        solved_any = True
        reports.append(
            LevelReport(
                names,
                "solved",
                0.0,
                step.rank,
                dimension,
                step.damping,
                step.tolerance,
                step.used_qp,
            )
        )
        if dimension == 0:  # lines 11–12: Ā has full column rank
            stopped = True

    x = np.zeros(n) if d_bar is None else d_bar
    violation = max(0.0, -float((D @ x + f).min())) if D.shape[0] else 0.0
    return PrioritizedSolution(
        found=not (infeasible or failed) and violation <= feasibility_tolerance,
        x=x,
        levels=tuple(
            report
            if level.A.shape[0] == 0
            else replace(report, residual=_norm(level.A @ x - level.b) if residuals else math.nan)
            for report, level in zip(reports, stacked, strict=True)
        ),
        inequality_violation=violation,
        qp_solver=qp_solver,
        solve_time_s=time.perf_counter() - start,
        qp_attempts=clock.attempts,
        qp_time_s=clock.spent_s,
    )


def qp_data_limit(feasibility_tolerance: float) -> float:
    """Largest ``|D x + f|`` (and step ``|D w|``) a level's QP is attempted with.

    Beyond ``feasibility_tolerance / ε`` the rounding of ``D x + f`` alone exceeds the
    tolerance: whether the inequalities hold can no longer be decided, and no solver can
    meet tolerances that fine (1e-7 allows terms up to about 4.5e8).
    """
    return feasibility_tolerance / float(np.finfo(float).eps)


@dataclass(frozen=True)
class _LevelStep:
    """One level's step (``w`` is ``None`` if infeasible) and what Algorithm 1 needs next.

    Attributes:
        w: The step on the seen blocks, in their coordinates.
        w_unseen: The step on the unseen blocks (the QP may move them), or ``None``.
        slack: ``D x + f`` after the step.
        null_parts: The null space of ``Ā`` in the seen blocks' coordinates, in one or more
            orthonormal parts, each with ``D C̄ part`` when the QP computed it already.
        rank: Directions kept.
        damping: Largest λᵢ applied.
        tolerance: The rank tolerance.
        used_qp: Whether the level needed a QP.
        detail: Why the QP gave no solution.
    """

    w: np.ndarray | None
    w_unseen: np.ndarray | None
    slack: np.ndarray
    null_parts: list[tuple[np.ndarray, np.ndarray | None]]
    rank: int
    damping: float
    tolerance: float
    used_qp: bool
    detail: str = ""


def _solve_level(
    seen: SeenBlocks,
    b_bar: np.ndarray,
    slack: np.ndarray,
    dimension: int,
    gain_bound: float,
    qp_solver: str,
    feasibility_tolerance: float,
    persist: bool,
    clock: QPClock,
    gram: bool = False,
    null_space_part: np.ndarray | None = None,
    rows: int | None = None,
) -> _LevelStep:
    """Algorithm 1, lines 5–6 and ``null(Ā)``, from one SVD of ``Ā``.

    ``Ā`` is the level on the blocks of ``C̄`` it sees (``dimension`` counts all of ``C̄``):
    on the others it is exactly zero, like the directions without a singular value. With
    ``gram`` (a level known to be well conditioned), the SVD of a wide ``Ā`` comes from
    :func:`~.level_svd.gram_svd` when its condition allows, and ``null_space_part`` becomes a null
    part of its own; a tall ``Ā`` tries :func:`~.level_svd.gram_svd_tall` first. ``rows`` counts the
    level's rows before a :attr:`Level.row_basis` reduced them (the rounding floor is the
    SVD's of all of them).
    """
    A_bar, D_seen, D_unseen = seen.A_bar, seen.D_seen, seen.D_unseen
    m, k = A_bar.shape
    decomposition = None
    if gram and 0 < m <= k:
        decomposition = gram_svd(A_bar, null_space_part)
    elif m >= k >= GRAM_MIN_COLUMNS:
        decomposition = gram_svd_tall(A_bar)
    given = 0
    if decomposition is not None:
        U, sigma, V = decomposition
        given = 0 if null_space_part is None else null_space_part.shape[1]
    elif k:
        # Thin SVD, except for wide Ā, whose null space needs all k rows of Vᵀ.
        U, sigma, Vt, info = _lapack.dgesdd(A_bar, full_matrices=int(m < k))
        if info:  # as numpy.linalg.svd
            raise np.linalg.LinAlgError("SVD did not converge")
        V = Vt.T
    else:  # the level sees nothing of what is left
        U, sigma, V = np.zeros((m, 0)), np.zeros(0), np.zeros((0, 0))
    # σ sorted descending, as floats: the counts below are of a prefix.
    singular_values = sigma.tolist()
    sigma_max = singular_values[0] if singular_values else 0.0
    rounding_floor = sigma_max * max(m if rows is None else rows, dimension) * _EPSILON
    tolerance = max(1.0 / gain_bound, rounding_floor)
    rank = _prefix(singular_values, lambda s: s >= tolerance)
    # Singular values at the rounding floor are noise, not small: like the directions without
    # a singular value (wide Ā, or blocks Ā does not see) they count as σ = 0 and get no gain.
    used = _prefix(singular_values, lambda s: s > rounding_floor or s >= tolerance)
    # Curvature σᵢ² + λᵢ² of the damped problem in z = Vᵀ w, λᵢ by Maciejewski's rule: zero
    # for σᵢ ≥ 1/B, so only the weak tail calls it; 1/(2B) for σ = 0. Directions without
    # gain (σ = 0 or at the rounding floor) are free for the levels below: the QP only needs
    # them strictly convex, not penalized against this level's residual.
    curvature = np.zeros(dimension)
    curvature[:used] = sigma[:used] ** 2
    weak = _prefix(singular_values[:used], lambda s: s >= 1.0 / gain_bound)
    for i in range(weak, used):
        curvature[i] += damping_for_gain_bound(singular_values[i], gain_bound) ** 2
    damping = damping_for_gain_bound(singular_values[used - 1], gain_bound) if used else 0.0
    linear = sigma[:used] * (b_bar @ U[:, :used])  # −(gradient at z = 0)
    w = V[:, :used] @ (linear / curvature[:used])  # damped least squares, eq. 15–16
    w_unseen = None
    D_V = None
    used_qp = False
    if D_seen.shape[0]:
        D_C_bar_w = D_seen @ w
        new_slack = slack + D_C_bar_w
        if not new_slack.min() >= -feasibility_tolerance:  # violated, or NaN
            used_qp = True
            magnitude = max(float(np.abs(slack).max()), float(np.abs(D_C_bar_w).max()))
            limit = feasibility_tolerance / _EPSILON  # qp_data_limit
            if not magnitude <= limit:  # also NaN
                detail = (
                    f"no QP: inequality terms |D x + f| reach {magnitude:.3g}, beyond {limit:.3g} "
                    f"where rounding exceeds the feasibility tolerance {feasibility_tolerance:g}"
                )
                return _LevelStep(None, None, slack, [], rank, damping, tolerance, used_qp, detail)
            refusals = clock.refusals
            D_V = D_seen @ V
            D_C_bar_V = np.hstack([D_V, D_unseen]) if D_unseen.shape[1] else D_V
            # Violations already accepted (≤ tolerance, by a level above) may stay but not
            # grow: w = 0 is then exactly feasible, which degenerate vertices (more active
            # rows than unknowns, common in low levels) need for proxqp and quadprog.
            bound = np.where(slack >= -feasibility_tolerance, np.maximum(slack, 0.0), slack)
            # The top level, where a failure ends the solve, tries every solver and both
            # curvatures; below it a failure only skips the level, so one solver is enough.
            curvatures = _NULL_CURVATURES if persist else _NULL_CURVATURES[:1]
            for index, null_curvature in enumerate(curvatures):
                curvature[used:] = max((null_curvature * sigma_max) ** 2, _TINY)
                z_qp = solve_qp_chain(
                    curvature,
                    linear,
                    D_C_bar_V,
                    bound,
                    qp_solver,
                    rank,
                    feasibility_tolerance,
                    fallbacks=persist,
                    clock=clock,
                    first=index == 0,
                )
                if z_qp is None:
                    continue
                new_slack = slack + D_C_bar_V @ z_qp
                if new_slack.min() >= -feasibility_tolerance:  # also rejects NaN
                    w = V @ z_qp[:k]
                    w_unseen = z_qp[k:] if dimension > k else None
                    break
            else:
                detail = (
                    f"QP time budget of {clock.budget_s * 1e3:g} ms spent"
                    if clock.refusals > refusals
                    else f"no QP solver found a solution (chosen: {qp_solver})"
                )
                return _LevelStep(None, None, slack, [], rank, damping, tolerance, used_qp, detail)
        slack = new_slack
    # null(Ā) in the seen coordinates: V's columns from `rank` on, the given part apart.
    split = k - given
    null_parts: list[tuple[np.ndarray, np.ndarray | None]] = [
        (V[:, rank:split], None if D_V is None else D_V[:, rank:split])
    ]
    if given:
        null_parts.append((V[:, split:], None if D_V is None else D_V[:, split:]))
    return _LevelStep(w, w_unseen, slack, null_parts, rank, damping, tolerance, used_qp)


def _norm(vector: np.ndarray) -> float:
    """Euclidean norm of a finite vector (``np.linalg.norm`` without its dispatch)."""
    return math.sqrt(float(vector @ vector))


def _prefix(values: list[float], holds: Any) -> int:
    """Length of the prefix of ``values`` (sorted descending) on which ``holds`` is true."""
    count = len(values)
    while count and not holds(values[count - 1]):
        count -= 1
    return count
