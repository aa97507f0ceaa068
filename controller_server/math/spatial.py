"""Small 3-D vector helpers: the cross product, its matrix and the point-to-origin wrench map."""

from __future__ import annotations

import numpy as np

__all__ = ["cross", "skew", "wrench_map"]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcasting (``numpy.cross`` without its overhead)."""
    if a.ndim == 1 and b.ndim == 1:  # the common 3-vector case, in scalar arithmetic
        x0, x1, x2 = a.tolist()
        y0, y1, y2 = b.tolist()
        return np.array([x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0])
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def skew(vector: np.ndarray) -> np.ndarray:
    """The matrix ``[v]×`` with ``[v]× w = v × w``."""
    x, y, z = vector
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def wrench_map(offsets: np.ndarray) -> np.ndarray:
    """``(6, 3k)`` ``W = [I … I; [r₁]× … [r_k]×]`` for ``k`` points at offsets ``r`` from an origin.

    Forces ``f`` at the points (stacked) make the wrench ``W f = [Σ f; Σ r × f]``
    about the origin; by duality the points' velocity Jacobian is ``Wᵀ`` times
    the origin's ``[v; ω]`` Jacobian.
    """
    r = np.asarray(offsets, dtype=float).reshape(-1, 3)
    count = len(r)
    matrix = np.empty((6, count, 3))
    matrix[:3] = _IDENTITY_ROWS  # [I … I]
    # [r]×_ab = −ε_abc r_c
    np.einsum("abc,ic->aib", _NEGATIVE_LEVI_CIVITA, r, out=matrix[3:])
    return matrix.reshape(6, 3 * count)


_IDENTITY_ROWS = np.eye(3)[:, None, :]
"""``(3, 1, 3)``: row ``a`` of the identity, broadcast over the points."""
_NEGATIVE_LEVI_CIVITA = np.zeros((3, 3, 3))
for _a, _b, _c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _NEGATIVE_LEVI_CIVITA[_a, _b, _c], _NEGATIVE_LEVI_CIVITA[_a, _c, _b] = -1.0, 1.0
