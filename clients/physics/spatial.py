"""The cross product and its matrix for the simulators (numpy's ``cross`` costs tens of µs).

The server has its own (:mod:`controller_server.math.spatial`): a client imports no server
module (docs/architecture.md), and these two functions are all the simulators need.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cross", "skew"]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` over the last axis, broadcasting (two 3-vectors or ``(n, 3)`` arrays)."""
    if a.ndim == 1 and b.ndim == 1:  # the common 3-vector case, in scalar arithmetic
        x0, x1, x2 = a.tolist()
        y0, y1, y2 = b.tolist()
        return np.array([x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0])
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def skew(vector: np.ndarray) -> np.ndarray:
    """``[v]×``, the matrix with ``[v]× u = v × u``."""
    x, y, z = vector
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
