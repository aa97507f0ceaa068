"""Solvers for the controllers' optimization problems."""

from controller_server.solvers.damped import damped_solve_psd, damping_for_gain_bound
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
    "damped_solve_psd",
    "damping_for_gain_bound",
    "solve_prioritized",
    "solve_weighted_kkt",
]
