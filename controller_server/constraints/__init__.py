"""Constraints on the unknowns: equalities ``C x = d``."""

from controller_server.constraints.support import Equality, compute_support_equalities

__all__ = ["Equality", "compute_support_equalities"]
