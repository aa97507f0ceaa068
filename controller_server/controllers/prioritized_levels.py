"""The prioritized controller's objectives over ``x = [τ, q̈, λ]``, stacked into levels.

Each objective covers one block of ``x`` (:class:`Term`); a level stacks its objectives'
rows, weighted (de Lasa 2010, eq. 16, 37) and scaled to unit norm
(:func:`normalized_level`), for :func:`~controller_server.solvers.solve_prioritized`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from controller_server.features import Objective
from controller_server.solvers.prioritized import Level

__all__ = ["Term", "normalized_level", "term_residual"]


class Term(NamedTuple):
    """An objective over one block of ``x = [τ, q̈, λ]`` (its ``A`` has the block's columns).

    ``weight`` is the objective's weight when every row has it (``None`` otherwise),
    ``active`` whether any row has a positive one, and ``row_basis`` orthonormal columns
    holding those of ``A`` when its rows span fewer dimensions than they are
    (:attr:`~controller_server.solvers.prioritized.Level.row_basis`).
    """

    objective: Objective
    columns: slice
    weight: float | None
    active: bool
    row_basis: np.ndarray | None = None


def term_residual(term: Term, x: np.ndarray) -> float:
    """``‖W^½ (A x − b)‖`` of the objective on its block of ``x``."""
    objective = term.objective
    error = objective.A @ x[term.columns] - objective.b
    if term.weight is None:
        return math.sqrt(float((objective.weight * error) @ error))
    return math.sqrt(term.weight) * math.sqrt(float(error @ error))


def normalized_level(
    terms: Sequence[Term],
    size: int,
    well_conditioned: bool = False,
    null_space_part: np.ndarray | None = None,
) -> Level:
    """The level's rows ``√w A`` over ``x`` scaled to ``‖W^½ A‖_F = 1`` (de Lasa 2010, eq. 16, 37).

    Same minimizers. The levels come in their own units (N for the equations of motion, m/s²
    for features, kg·m²/s² per kg for momentum); scaled alike, one gain bound
    ``B`` is a bound on each level's condition (σ < σ_max / B, within
    ``√rank``, is singular) rather than on singular values in mixed units.
    """
    squared = 0.0
    for objective, _, weight, *_ in terms:
        A = objective.A
        if weight is None:
            squared += float(objective.weight @ (A * A).sum(axis=1))
        else:
            squared += weight * float(np.vdot(A, A))
    scale = math.sqrt(squared)
    rows = sum(term.objective.b.size for term in terms)
    A_level = np.zeros((rows, size))
    b_level = np.empty(rows)
    start = 0
    for objective, columns, weight, *_ in terms:
        end = start + objective.b.size
        if weight is None:
            root_weight = np.sqrt(objective.weight / scale**2 if scale > 0.0 else objective.weight)
            A_level[start:end, columns] = root_weight[:, None] * objective.A
            b_level[start:end] = root_weight * objective.b
        else:
            root = math.sqrt(weight / scale**2 if scale > 0.0 else weight)
            np.multiply(objective.A, root, out=A_level[start:end, columns])
            np.multiply(objective.b, root, out=b_level[start:end])
        start = end
    return Level(
        tuple(term.objective.name for term in terms),
        A_level,
        b_level,
        well_conditioned,
        null_space_part,
        row_basis_of(terms, rows),
    )


def row_basis_of(terms: Sequence[Term], rows: int) -> np.ndarray | None:
    """The level's row basis: block diagonal of its objectives' (all rows for those without)."""
    if all(term.row_basis is None for term in terms):
        return None
    if len(terms) == 1:
        return terms[0].row_basis
    bases = [
        np.eye(term.objective.b.size) if term.row_basis is None else term.row_basis
        for term in terms
    ]
    basis = np.zeros((rows, sum(part.shape[1] for part in bases)))
    row = column = 0
    for part in bases:
        basis[row : row + part.shape[0], column : column + part.shape[1]] = part
        row, column = row + part.shape[0], column + part.shape[1]
    return basis
