"""Solvers for the controllers' optimization problems."""

from controller_server.solvers.kkt import (
    KKTSolution,
    WeightedProblem,
    build_weighted_problem,
    solve_weighted_kkt,
)
from controller_server.solvers.prioritized import PrioritizedSolution, solve_prioritized

__all__ = [
    "KKTSolution",
    "PrioritizedSolution",
    "WeightedProblem",
    "build_weighted_problem",
    "solve_prioritized",
    "solve_weighted_kkt",
]
