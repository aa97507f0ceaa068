"""The common form of every objective: weighted rows of a least-squares term."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Objective"]


@dataclass(frozen=True)
class Objective:
    """Rows of ``Σᵢ wᵢ (Aᵢ x − bᵢ)²`` (Macchietto 2008, eq. 4.1 with ``W² = diag(w)``).

    Attributes:
        name: Objective name, for diagnostics.
        A: ``(m, n)`` matrix mapping the unknowns ``x`` to the objective space.
        b: ``(m,)`` desired values.
        weight: ``(m,)`` non-negative weight per row (the objective's β folded in).
    """

    name: str
    A: np.ndarray
    b: np.ndarray
    weight: np.ndarray

    def residual(self, x: np.ndarray) -> float:
        """Weighted residual ``‖W (A x − b)‖``."""
        return float(np.linalg.norm(np.sqrt(self.weight) * (self.A @ x - self.b)))
