"""Ground reference points: centre of pressure, centroidal moment pivot, support polygon.

Flat ground at height ``h`` with normal +z (gravity −z), as in the thesis.
"""

from __future__ import annotations

import numpy as np

__all__ = ["center_of_pressure", "centroidal_moment_pivot", "support_polygon"]

MIN_NORMAL_FORCE_N = 1e-6
"""Below this total normal force the COP and CMP are undefined (NaN)."""


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

    def turn(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def chain(ordered: list[tuple[float, float]]) -> list[tuple[float, float]]:
        hull: list[tuple[float, float]] = []
        for point in ordered:
            while len(hull) >= 2 and turn(hull[-2], hull[-1], point) <= 0.0:
                hull.pop()
            hull.append(point)
        return hull

    lower, upper = chain(points), chain(points[::-1])
    return np.array(lower[:-1] + upper[:-1])
