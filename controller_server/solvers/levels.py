"""Priority levels and what solving them reports (de Lasa, Mordatch & Hertzmann 2010, eq. 37).

A level is its objectives' rows stacked, each scaled by the square root of its weight
(:class:`Level`, :func:`stack_level`); :func:`~.prioritized.solve_prioritized` reports what
happened at each (:class:`LevelReport`) and returns a :class:`PrioritizedSolution`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from controller_server.features.objective import Objective

__all__ = ["Level", "LevelReport", "LevelStatus", "PrioritizedSolution", "stack_level"]

LevelStatus = Literal["solved", "infeasible", "solver failed", "not reached", "empty"]


@dataclass(frozen=True)
class Level:
    """One priority level as stacked rows ``√w A`` and ``√w b`` (de Lasa 2010, eq. 37).

    What :func:`solve_prioritized` makes of a sequence of :class:`Objective` s; a caller
    that has the rows already (the prioritized controller) passes them as they are.

    Attributes:
        names: Names of the level's objectives (for the report).
        A: ``(m, n)`` rows, each already scaled by the square root of its weight.
        b: ``(m,)`` right-hand side, scaled alike.
        well_conditioned: The caller knows the rows to be linearly independent and well
            conditioned (the equations of motion: ``M ≻ 0``). The level's SVD may then come
            from the eigendecomposition of ``Ā Āᵀ`` (see :func:`~.level_svd.gram_svd`); the
            solver checks the condition and falls back to the SVD of ``Ā`` when it is not small.
        null_space_part: ``(n, f)`` orthonormal columns in the null space of ``A``, for a
            ``well_conditioned`` first level: kept as a block of ``C̄`` of its own (see the
            module docstring, "Blocks"), so that the levels below whose rows are exactly
            zero on it leave it out of their SVD. Ignored when the level's SVD is taken.
        row_basis: ``(m, r)`` orthonormal columns whose span holds every column of ``A``
            (rows that combine fewer: the points of a rigid sole). The level is solved as
            ``Pᵀ A x ≈ Pᵀ b``, which has the same minimizers, singular values and right
            singular vectors, from ``r`` rows (by :func:`~.level_svd.gram_svd` when its condition
            allows); its rounding floor and reported residual are those of all ``m`` rows.
    """

    names: tuple[str, ...]
    A: np.ndarray
    b: np.ndarray
    well_conditioned: bool = False
    null_space_part: np.ndarray | None = None
    row_basis: np.ndarray | None = None


@dataclass(frozen=True)
class LevelReport:
    """What happened at one priority level.

    Attributes:
        names: Names of the level's objectives.
        status: ``"solved"``; ``"infeasible"`` (the QP had no solution: ``x`` is the
            solution of the levels above); ``"solver failed"`` (below a solved level, where
            ``w = 0`` is feasible, so the QP solver failed: the level is skipped, its
            freedom left to the levels below); ``"not reached"`` (after a level that used
            all remaining freedom, or after an infeasible level); ``"empty"`` (no
            objectives).
        residual: ``‖W^{½}(A x − b)‖`` at the returned ``x``.
        rank: Number of directions of ``Ā = A C̄`` kept by this level (σ ≥ tolerance);
            0 when not solved.
        null_space_dimension: Dimension of the freedom left to the lower levels after this
            level (columns of ``C̄``); 0 when not solved.
        damping: Largest λᵢ applied, ``damping_for_gain_bound(σ, B)`` for the smallest
            singular value σ above the rounding floor; 0 when no direction was damped.
        singular_value_tolerance: ``max(1/B, σ_max · max(m, k) · ε)``; 0 when not solved.
        used_qp: Whether the level needed a QP (the closed form violated an inequality).
        detail: Why the level's QP gave no solution (``""`` if it did, or needed none):
            every solver failed, the time budget was spent, or the data were out of range.
    """

    names: tuple[str, ...]
    status: LevelStatus
    residual: float
    rank: int
    null_space_dimension: int
    damping: float
    singular_value_tolerance: float
    used_qp: bool
    detail: str = ""


@dataclass(frozen=True)
class PrioritizedSolution:
    """Result of :func:`solve_prioritized`.

    Attributes:
        found: No level was infeasible or failed, and ``D x + f ≥ 0`` holds within the
            tolerance.
        x: The solution (``d̄`` of Algorithm 1 where the solver stopped).
        levels: One report per level, in priority order.
        inequality_violation: ``max(0, max(−(D x + f)))``.
        qp_solver: Name of the QP solver used for constrained levels.
        solve_time_s: Wall time of the solve (s).
        qp_attempts: Number of QP solver calls (every solver, retry and level).
        qp_time_s: Wall time of those calls (s).
    """

    found: bool
    x: np.ndarray
    levels: tuple[LevelReport, ...]
    inequality_violation: float
    qp_solver: str
    solve_time_s: float
    qp_attempts: int = 0
    qp_time_s: float = 0.0


def stack_level(
    level: Level | Sequence[Objective] | Objective, n: int, check_finite: bool = True
) -> Level:
    """The level's rows ``√w A``, ``√w b`` (de Lasa 2010, eq. 37), checked."""
    if isinstance(level, Level):
        A, b = level.A, level.b
        if not (isinstance(A, np.ndarray) and A.dtype == float):
            A = np.asarray(A, dtype=float)
        if not (isinstance(b, np.ndarray) and b.dtype == float):
            b = np.asarray(b, dtype=float)
        if A.ndim != 2 or A.shape[1] != n or b.shape != (A.shape[0],):
            raise ValueError(
                f"level {level.names} needs A (m, {n}) and b (m,), got {A.shape=}, {b.shape=}"
            )
        if check_finite and not (np.isfinite(A).all() and np.isfinite(b).all()):
            raise ValueError(f"level {level.names} has non-finite A or b")
        basis = level.row_basis
        if basis is not None and (basis.ndim != 2 or basis.shape[0] != A.shape[0]):
            raise ValueError(
                f"level {level.names} needs a row basis ({A.shape[0]}, r), got {basis.shape}"
            )
        return level if A is level.A and b is level.b else replace(level, A=A, b=b)
    objectives = (level,) if isinstance(level, Objective) else tuple(level)
    names = tuple(objective.name for objective in objectives)
    blocks_A: list[np.ndarray] = []
    blocks_b: list[np.ndarray] = []
    for objective in objectives:
        A = np.asarray(objective.A, dtype=float)
        b = np.asarray(objective.b, dtype=float)
        if A.ndim != 2 or A.shape[1] != n or b.shape != (A.shape[0],):
            raise ValueError(
                f"objective {objective.name!r} needs A (m, {n}) and b (m,), "
                f"got {A.shape=}, {b.shape=}"
            )
        weight = np.asarray(objective.weight, dtype=float)
        if weight.shape not in ((), b.shape):
            raise ValueError(
                f"objective {objective.name!r} needs weights () or {b.shape}, got {weight.shape}"
            )
        if not (np.all(np.isfinite(weight)) and np.all(weight >= 0.0)):
            raise ValueError(f"objective {objective.name!r} has weights {weight} (need ≥ 0)")
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):
            raise ValueError(f"objective {objective.name!r} has non-finite A or b")
        root_weight = np.broadcast_to(np.sqrt(weight), b.shape)
        blocks_A.append(root_weight[:, None] * A)
        blocks_b.append(root_weight * b)
    if not blocks_A:
        return Level(names, np.zeros((0, n)), np.zeros(0))
    if len(blocks_A) == 1:
        return Level(names, blocks_A[0], blocks_b[0])
    return Level(names, np.vstack(blocks_A), np.concatenate(blocks_b))
