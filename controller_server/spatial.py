"""Small 3-D vector helpers shared by the dynamics modules."""

from __future__ import annotations

import numpy as np

__all__ = ["cross", "skew"]


def skew(u: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[u]×`` (Macchietto 2008, eq. A.4)."""
    return np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcasting (``numpy.cross`` without its overhead)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)
