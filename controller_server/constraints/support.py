"""Support constraint: supporting feet keep the ground's acceleration.

Macchietto 2008, eq. 5.1::

    J_sup q̈ + J̇_sup q̇ = â_sup

with six rows (linear and angular acceleration of the contact frame, world
axes) per supporting contact. The ground is static here, so ``â_sup = 0``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controller_server.dynamics import DynamicsTerms

__all__ = ["Equality", "compute_support_equalities"]


@dataclass(frozen=True)
class Equality:
    """Linear equality ``C x = d``."""

    C: np.ndarray
    d: np.ndarray


def compute_support_equalities(terms: DynamicsTerms, supports: Sequence[bool]) -> Equality:
    """Rows of eq. 5.1 for every contact whose flag is set.

    Args:
        terms: Dynamics at the current state.
        supports: One flag per contact (the state's ``contact_flags``).

    Returns:
        ``C = J_sup`` and ``d = −J̇_sup q̇`` (zero rows if nothing supports).
    """
    nv = terms.v.size
    rows = [J for J, on in zip(terms.support_jacobians, supports, strict=True) if on]
    drifts = [a for a, on in zip(terms.support_drifts, supports, strict=True) if on]
    if not rows:
        return Equality(np.zeros((0, nv)), np.zeros(0))
    return Equality(np.vstack(rows), -np.concatenate(drifts))
