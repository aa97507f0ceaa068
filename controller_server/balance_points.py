"""Ground reference points: centre of pressure, centroidal moment pivot, support polygon.

Flat ground at height ``h`` with normal +z (gravity −z), as in the thesis.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "center_of_pressure",
    "centroidal_moment_pivot",
    "closest_point_in_polygon",
    "shrink_polygon",
    "support_polygon",
]

MIN_NORMAL_FORCE_N = 1e-6
"""Below this total normal force the COP and CMP are undefined (NaN)."""
COLLINEAR_SINE = 1e-9
"""Hull vertices whose edges turn by less than this (sine of the angle) are dropped."""


def center_of_pressure(
    force: np.ndarray, torque: np.ndarray, reference_point: np.ndarray, ground_height: float
) -> np.ndarray:
    """COP from the aggregate ground wrench (Macchietto 2008, eq. 3.3–3.6).

    Args:
        force: Total ground force ``f`` (N), world axes.
        torque: Total ground torque ``τ`` about ``reference_point`` (N·m).
        reference_point: ``c_sp``, e.g. the centre of the supports (m).
        ground_height: Height of the contact surface (m).

    Returns:
        ``p = c_sp + r`` with ``r_x = −(τ_y + h f_x)/f_z``, ``r_y = (τ_x − h f_y)/f_z``,
        ``r_z = −h`` where ``h`` is the reference point's height above the ground;
        NaN if ``f_z`` is too small.
    """
    if force[2] < MIN_NORMAL_FORCE_N:
        return np.full(3, np.nan)
    height = reference_point[2] - ground_height
    offset = np.array(
        [
            -(torque[1] + height * force[0]) / force[2],
            (torque[0] - height * force[1]) / force[2],
            -height,
        ]
    )
    return reference_point + offset


def centroidal_moment_pivot(
    position_com_in_world: np.ndarray, force: np.ndarray, ground_height: float
) -> np.ndarray:
    """CMP: where the ground force's line through the CM meets the ground (eq. 3.9–3.10)."""
    if force[2] < MIN_NORMAL_FORCE_N:
        return np.full(3, np.nan)
    drop = position_com_in_world[2] - ground_height
    return np.array(
        [
            position_com_in_world[0] - force[0] / force[2] * drop,
            position_com_in_world[1] - force[1] / force[2] * drop,
            ground_height,
        ]
    )


def support_polygon(points_in_world: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise ``(m, 2)`` x–y vertices) of the support points.

    Andrew's monotone chain: a handful of points per tick, no Qhull call.
    Collinear points give the segment's two ends; one point gives itself;
    no points give an empty array.
    """
    xy = np.asarray(points_in_world, dtype=float).reshape(-1, 3)[:, :2]
    points = sorted({(float(x), float(y)) for x, y in xy})
    if len(points) <= 2:
        return np.array(points).reshape(-1, 2)

    def left_turn(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> bool:
        """Strictly left, relative to the edge lengths: collinear up to round-off is not."""
        ax, ay, bx, by = a[0] - o[0], a[1] - o[1], b[0] - o[0], b[1] - o[1]
        return ax * by - ay * bx > COLLINEAR_SINE * math.hypot(ax, ay) * math.hypot(bx, by)

    def chain(ordered: list[tuple[float, float]]) -> list[tuple[float, float]]:
        hull: list[tuple[float, float]] = []
        for point in ordered:
            while len(hull) >= 2 and not left_turn(hull[-2], hull[-1], point):
                hull.pop()
            hull.append(point)
        return hull

    lower, upper = chain(points), chain(points[::-1])
    return np.array(lower[:-1] + upper[:-1])


def shrink_polygon(polygon_xy: np.ndarray, margin: float) -> np.ndarray:
    """Move every edge of a convex counter-clockwise polygon inward by ``margin`` (m).

    Each new vertex is where the two offset edges around an old vertex meet.
    Vertices where the boundary does not turn (repeated or collinear up to
    round-off) are dropped first, since their offset edges are parallel. A
    polygon with fewer than three vertices left, or too small for the
    margin, collapses to its vertex mean, a single point.
    """
    polygon_xy = np.asarray(polygon_xy, dtype=float).reshape(-1, 2)
    if not len(polygon_xy):
        return np.zeros((1, 2))
    centre = polygon_xy.mean(axis=0, keepdims=True)
    polygon_xy = _turning_vertices(polygon_xy)
    if len(polygon_xy) < 3:
        return centre
    if margin <= 0.0:
        return polygon_xy
    edges = np.roll(polygon_xy, -1, axis=0) - polygon_xy
    normals = np.column_stack([edges[:, 1], -edges[:, 0]])  # outward for counter-clockwise
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = np.einsum("ij,ij->i", normals, polygon_xy) - margin
    # Vertex i: where the offset edges i − 1 and i meet, n_j · p = o_j (Cramer's rule).
    n_prev, o_prev = np.roll(normals, 1, axis=0), np.roll(offsets, 1)
    determinant = n_prev[:, 0] * normals[:, 1] - n_prev[:, 1] * normals[:, 0]
    shrunk = np.column_stack(
        [
            (o_prev * normals[:, 1] - n_prev[:, 1] * offsets) / determinant,
            (n_prev[:, 0] * offsets - o_prev * normals[:, 0]) / determinant,
        ]
    )
    # Too much margin turns the offset polygon inside out: some vertex is then
    # closer than `margin` to (or beyond) an original edge.
    clearance = offsets[None, :] + margin - shrunk @ normals.T  # distance inside each edge
    if not np.all(np.isfinite(shrunk)) or clearance.min() < margin * (1.0 - 1e-9):
        return centre
    return shrunk


def _turning_vertices(polygon_xy: np.ndarray) -> np.ndarray:
    """The vertices where a closed polygon turns by more than round-off."""
    while len(polygon_xy) >= 3:
        before = polygon_xy - np.roll(polygon_xy, 1, axis=0)
        after = np.roll(polygon_xy, -1, axis=0) - polygon_xy
        sine = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
        scale = np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1)
        flat = ~(sine > COLLINEAR_SINE * scale)
        if not flat.any():
            break
        polygon_xy = np.delete(polygon_xy, int(np.argmax(flat)), axis=0)
    return polygon_xy


def closest_point_in_polygon(point_xy: np.ndarray, polygon_xy: np.ndarray) -> np.ndarray:
    """The point of a convex counter-clockwise polygon (segment, point) nearest ``point_xy``."""
    point_xy = np.asarray(point_xy, dtype=float)
    polygon_xy = np.asarray(polygon_xy, dtype=float).reshape(-1, 2)
    if len(polygon_xy) >= 3:
        edges = np.roll(polygon_xy, -1, axis=0) - polygon_xy
        outward = edges[:, 1] * (point_xy[0] - polygon_xy[:, 0]) - edges[:, 0] * (
            point_xy[1] - polygon_xy[:, 1]
        )
        if np.all(outward <= 0.0):
            return point_xy.copy()
    starts = polygon_xy
    ends = np.roll(polygon_xy, -1, axis=0)
    segments = ends - starts
    lengths_squared = np.maximum(np.einsum("ij,ij->i", segments, segments), 1e-300)
    fractions = np.clip(np.einsum("ij,ij->i", point_xy - starts, segments) / lengths_squared, 0, 1)
    candidates = starts + fractions[:, None] * segments
    return candidates[np.argmin(np.linalg.norm(candidates - point_xy, axis=1))]
