"""Ground reference points: centre of pressure, centroidal moment pivot, support polygon.

Flat ground at height ``h`` with normal +z (gravity −z), as in the thesis.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "MAX_MARGIN_FRACTION",
    "admissible_cop_polygon",
    "center_of_pressure",
    "centroidal_moment_pivot",
    "closest_point_in_polygon",
    "ground_reference_points",
    "polygon_width",
    "shrink_polygon",
    "support_polygon",
]

MIN_NORMAL_FORCE_N = 1e-6
"""Below this total normal force the COP and CMP are undefined (NaN)."""
COLLINEAR_SINE = 1e-9
"""Hull vertices whose edges turn by less than this (sine of the angle) are dropped."""
MAX_MARGIN_FRACTION = 0.25
"""A COP margin takes at most this fraction of the support polygon's width from each side."""


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


def ground_reference_points(
    position_contact_frames_in_world: np.ndarray,
    position_com_in_world: np.ndarray,
    contact_wrench_in_world: np.ndarray | None,
    supports: Sequence[bool],
    ground_height: float,
) -> tuple[np.ndarray, np.ndarray]:
    """COP and CMP of the contacts' ground wrenches (NaN without ground force).

    Args:
        position_contact_frames_in_world: ``(contacts, 3)`` contact frame origins (m).
        position_com_in_world: Centre of mass (m).
        contact_wrench_in_world: ``(contacts, 6)`` force and torque about each
            contact frame origin, or ``None``.
        supports: One flag per contact; the wrenches are summed about the
            mean of the supporting frames' origins (all origins if none).
        ground_height: Ground plane height (m).
    """
    if contact_wrench_in_world is None:
        nan = np.full(3, np.nan)
        return nan, nan
    # A handful of contacts: scalar arithmetic beats numpy's per-call overhead here.
    wrenches = np.asarray(contact_wrench_in_world).reshape(-1, 6).tolist()
    origins = np.asarray(position_contact_frames_in_world).tolist()
    chosen = [o for o, on in zip(origins, supports, strict=True) if on] or origins
    cx, cy, cz = (sum(axis) / len(chosen) for axis in zip(*chosen, strict=True))
    force, torque = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    for (fx, fy, fz, tx, ty, tz), (ox, oy, oz) in zip(wrenches, origins, strict=True):
        rx, ry, rz = ox - cx, oy - cy, oz - cz  # torque about the reference: τ + r × f
        force[0], force[1], force[2] = force[0] + fx, force[1] + fy, force[2] + fz
        torque[0] += tx + ry * fz - rz * fy
        torque[1] += ty + rz * fx - rx * fz
        torque[2] += tz + rx * fy - ry * fx
    total_force = np.array(force)
    return (
        center_of_pressure(total_force, np.array(torque), np.array([cx, cy, cz]), ground_height),
        centroidal_moment_pivot(position_com_in_world, total_force, ground_height),
    )


def support_polygon(points_in_world: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise ``(m, 2)`` x–y vertices) of the support points.

    Andrew's monotone chain: a handful of points per tick, no Qhull call.
    Collinear points give the segment's two ends; one point gives itself;
    no points give an empty array.

    The chain keeps a vertex on any strictly left turn, however small, and only then
    are the vertices where the boundary does not turn (collinear up to
    :data:`COLLINEAR_SINE`) dropped, each one lying between its neighbours
    (:func:`_corners`). The chain's own order along a line is the lexicographic
    one, which along an edge parallel to y is set by the round-off of x: the heels
    of two feet side by side (four points on one line, their x equal up to 1e-17) come in
    any order there. Dropped during the chain, a point collinear with the last two was
    the middle one only if they came in order along the line; out of order, a
    heel's outer corner went, and the hull lost a triangle of a foot (24 × 11 cm on
    the revolute humanoid), so the COP allowed to ``com`` jumped between ticks with
    the rounding of the kinematics.
    """
    xy = np.asarray(points_in_world, dtype=float).reshape(-1, 3)[:, :2]
    points = sorted(set(map(tuple, xy.tolist())))
    if len(points) <= 2:
        return np.array(points).reshape(-1, 2)

    def chain(ordered: list[tuple[float, float]]) -> list[tuple[float, float]]:
        hull: list[tuple[float, float]] = []
        for bx, by in ordered:
            while len(hull) >= 2:
                (ox, oy), (ax, ay) = hull[-2], hull[-1]
                if (ax - ox) * (by - oy) - (ay - oy) * (bx - ox) > 0.0:  # strictly left
                    break
                hull.pop()
            hull.append((bx, by))
        return hull

    lower, upper = chain(points), chain(points[::-1])
    return np.array(_corners(lower[:-1] + upper[:-1])).reshape(-1, 2)


def _corners(vertices: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """A convex polygon's vertices without those on the segment between their neighbours.

    A vertex goes when its edges turn by less than :data:`COLLINEAR_SINE` (sine of the
    angle) and it lies between its neighbours: what it adds to the polygon is a sliver
    of that relative width. A vertex where the boundary turns back (the ends of a
    polygon of collinear points) stays, so collinear points give the segment's ends.
    """
    removed = True
    while removed and len(vertices) >= 3:
        removed = False
        for i, (x, y) in enumerate(vertices):
            px, py = vertices[i - 1]
            nx, ny = vertices[(i + 1) % len(vertices)]
            bx, by, ax, ay = x - px, y - py, nx - x, ny - y
            forward = bx * ax + by * ay > 0.0
            if forward and abs(bx * ay - by * ax) <= COLLINEAR_SINE * math.hypot(
                bx, by
            ) * math.hypot(ax, ay):
                del vertices[i]
                removed = True
                break
    return vertices


def shrink_polygon(polygon_xy: np.ndarray, margin: float) -> np.ndarray:
    """Move every edge of a convex counter-clockwise polygon inward by ``margin`` (m).

    Each new vertex is where the two offset edges around an old vertex meet.
    Vertices where the boundary does not turn (repeated or collinear up to
    round-off) are dropped first, since their offset edges are parallel. A
    polygon with fewer than three vertices left, or too small for the
    margin, collapses to its vertex mean, a single point.

    A handful of vertices per tick: scalar arithmetic, no array temporaries.
    """
    polygon_xy = np.asarray(polygon_xy, dtype=float).reshape(-1, 2)
    if not len(polygon_xy):
        return np.zeros((1, 2))
    listed = [(x, y) for x, y in polygon_xy.tolist()]
    centre = np.array(
        [[sum(x for x, _ in listed) / len(listed), sum(y for _, y in listed) / len(listed)]]
    )
    vertices = _turning_vertices(list(listed))
    if len(vertices) < 3:
        return centre
    if margin <= 0.0:
        return np.array(vertices)
    # Offset edge i (from vertex i to i + 1): n_i · p = o_i, n_i its outward unit normal.
    lines = []
    for (x0, y0), (x1, y1) in zip(vertices, vertices[1:] + vertices[:1], strict=True):
        length = math.hypot(x1 - x0, y1 - y0)
        nx, ny = (y1 - y0) / length, (x0 - x1) / length
        lines.append((nx, ny, nx * x0 + ny * y0 - margin))
    # Vertex i: where the offset edges i − 1 and i meet (Cramer's rule).
    shrunk = []
    for (ax, ay, ao), (bx, by, bo) in zip(lines[-1:] + lines[:-1], lines, strict=True):
        determinant = ax * by - ay * bx
        shrunk.append(((ao * by - ay * bo) / determinant, (ax * bo - ao * bx) / determinant))
    # Too much margin turns the offset polygon inside out: some vertex is then
    # closer than `margin` to (or beyond) an original edge.
    limit = margin * (1.0 - 1e-9)
    for x, y in shrunk:
        if not (math.isfinite(x) and math.isfinite(y)):
            return centre
        if any(o + margin - (nx * x + ny * y) < limit for nx, ny, o in lines):
            return centre
    return np.array(shrunk)


def polygon_width(polygon_xy: np.ndarray) -> float:
    """Width of a convex counter-clockwise polygon: its smallest extent across an edge (m).

    The distance between the closest pair of parallel lines that hold it, which
    for a convex polygon rests on one of its edges. A segment or a point has
    width 0.
    """
    points = np.asarray(polygon_xy, dtype=float).reshape(-1, 2).tolist()
    vertices = _turning_vertices([(x, y) for x, y in points])
    if len(vertices) < 3:
        return 0.0
    width = math.inf
    for (x0, y0), (x1, y1) in zip(vertices, vertices[1:] + vertices[:1], strict=True):
        length = math.hypot(x1 - x0, y1 - y0)
        nx, ny = (y0 - y1) / length, (x1 - x0) / length  # inward normal (counter-clockwise)
        width = min(width, max(nx * (x - x0) + ny * (y - y0) for x, y in vertices))
    return width


def admissible_cop_polygon(
    polygon_xy: np.ndarray, margin: float, max_margin_fraction: float = MAX_MARGIN_FRACTION
) -> np.ndarray:
    """Where a balance objective may ask for the COP: the support polygon shrunk by a margin.

    The margin (m) is at most ``max_margin_fraction`` of the polygon's width
    (:func:`polygon_width`), so a narrow support keeps a strip of its own shape
    instead of collapsing to its centre. A fixed 2 cm margin suits a 9 cm-wide
    sole, but on one 3 cm-wide sole it leaves only the centre point: a CM
    beyond it would be driven further out (the COP asked at the centre),
    whatever the push.
    """
    polygon_xy = np.asarray(polygon_xy, dtype=float).reshape(-1, 2)
    margin = min(margin, max_margin_fraction * polygon_width(polygon_xy))
    return shrink_polygon(polygon_xy, margin)


def _turning_vertices(vertices: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The vertices where a closed polygon turns by more than round-off."""
    while len(vertices) >= 3:
        for i, (x, y) in enumerate(vertices):
            px, py = vertices[i - 1]
            nx, ny = vertices[(i + 1) % len(vertices)]
            bx, by, ax, ay = x - px, y - py, nx - x, ny - y
            if not bx * ay - by * ax > COLLINEAR_SINE * math.hypot(bx, by) * math.hypot(ax, ay):
                del vertices[i]
                break
        else:
            break
    return vertices


def closest_point_in_polygon(point_xy: np.ndarray, polygon_xy: np.ndarray) -> np.ndarray:
    """The point of a convex counter-clockwise polygon (segment, point) nearest ``point_xy``.

    A handful of vertices per tick: scalar arithmetic, no array temporaries.
    """
    px, py = point_xy[:2].tolist() if isinstance(point_xy, np.ndarray) else map(float, point_xy[:2])
    vertices = np.asarray(polygon_xy, dtype=float).reshape(-1, 2).tolist()
    if not vertices or not all(math.isfinite(x) and math.isfinite(y) for x, y in vertices):
        return np.full(2, np.nan)  # no polygon: nothing is inside it
    edges = list(zip(vertices, vertices[1:] + vertices[:1], strict=True))
    if len(vertices) >= 3 and all(
        (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0) >= 0.0 for (x0, y0), (x1, y1) in edges
    ):
        return np.array([px, py])
    best, best_distance = (px, py), math.inf
    for (x0, y0), (x1, y1) in edges:
        sx, sy = x1 - x0, y1 - y0
        fraction = ((px - x0) * sx + (py - y0) * sy) / max(sx * sx + sy * sy, 1e-300)
        fraction = min(max(fraction, 0.0), 1.0)
        cx, cy = x0 + fraction * sx, y0 + fraction * sy
        distance = math.hypot(cx - px, cy - py)
        if distance < best_distance:
            best, best_distance = (cx, cy), distance
    return np.array(best)
