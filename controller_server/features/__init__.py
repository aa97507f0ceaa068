"""Objectives: each returns weighted rows ``(A, b)`` of a least-squares term."""

from controller_server.features.objective import Objective
from controller_server.features.tracking import compute_tracking_objective

__all__ = ["Objective", "compute_tracking_objective"]
