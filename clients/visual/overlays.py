"""What is drawn over the robot at a tick: pushes, COP, CMP, support polygon, caption.

One computation for every picture of a run (the video and the live view):

* **Push arrows** while a push acts (``start_s ≤ t < start_s + duration_s``,
  as the simulators apply it): the head at the pushed point of the body, the
  tail ``ARROW_M_PER_N`` metres per newton back along the force.
* **Centre of pressure** and **centroidal moment pivot** (Macchietto 2008,
  eq. 3.3–3.10) and the **support polygon** (the convex hull of the
  supporting contact points) from the server's diagnostics, held from the
  last tick that carried them (``diagnostics_period_ticks``), on the ground.
* **Caption**: scenario, controller, backend and time.

Everything is in the world frame, in metres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from clients.track import Track

__all__ = ["ARROW_M_PER_N", "Arrow", "TickOverlays", "overlays_at"]

ARROW_M_PER_N = 0.002
"""Length of a push arrow per newton of force (m/N): 150 N draws 0.3 m."""
GROUND_LIFT_M = 0.002
"""How far above the floor the ground overlays are drawn (m), so the floor does not hide them."""

PointInWorld = Callable[[str, tuple[float, float, float]], np.ndarray]
"""``(body, point in body frame) → point in world`` at the tick's pose (m)."""


@dataclass(frozen=True)
class Arrow:
    """A push drawn as an arrow (world frame, m).

    Attributes:
        tail_in_world: Where the arrow starts.
        head_in_world: The pushed point (the arrow ends there).
        force_N: The force's magnitude.
    """

    tail_in_world: np.ndarray
    head_in_world: np.ndarray
    force_N: float


@dataclass(frozen=True)
class TickOverlays:
    """The overlays of one tick (world frame, m).

    Attributes:
        time_s: The tick's time (s).
        pushes: An arrow per push acting now.
        center_of_pressure: COP on the ground, ``None`` without ground force or diagnostics.
        centroidal_moment_pivot: CMP on the ground, ``None`` likewise.
        support_polygon: ``(vertices, 3)`` counter-clockwise on the ground (empty: no support).
        caption: One line: scenario, controller, backend, time.
    """

    time_s: float
    pushes: tuple[Arrow, ...]
    center_of_pressure: np.ndarray | None
    centroidal_moment_pivot: np.ndarray | None
    support_polygon: np.ndarray
    caption: str


def overlays_at(track: Track, tick: int, point_in_world: PointInWorld) -> TickOverlays:
    """The overlays of ``track`` at ``tick``.

    Args:
        track: The run.
        tick: Index of the tick.
        point_in_world: Kinematics of the robot posed at this tick
            (:meth:`~clients.visual.scene.RobotScene.point_in_world`).
    """
    time_s = float(track.time_s[tick])
    arrows = []
    for push in track.pushes:
        if not push.start_s <= time_s < push.start_s + push.duration_s:
            continue
        force = np.asarray(push.force_in_world_N, dtype=float)
        head = np.asarray(point_in_world(push.body, push.point_in_body_m), dtype=float)
        arrows.append(Arrow(head - ARROW_M_PER_N * force, head, float(np.linalg.norm(force))))
    diagnostics = next(
        (
            command.diagnostics
            for command in reversed(track.commands[: tick + 1])
            if command.diagnostics is not None
        ),
        None,
    )
    cop = cmp = None
    polygon = np.zeros((0, 3))
    if diagnostics is not None:
        cop = _on_ground(diagnostics.center_of_pressure)
        cmp = _on_ground(diagnostics.centroidal_moment_pivot)
        xy = np.asarray(diagnostics.support_polygon_xy, dtype=float).reshape(-1, 2)
        polygon = np.column_stack([xy, np.full(len(xy), GROUND_LIFT_M)])
    caption = f"{track.name} - {track.controller} controller, {track.backend} - t = {time_s:5.2f} s"
    return TickOverlays(time_s, tuple(arrows), cop, cmp, polygon, caption)


def _on_ground(point: np.ndarray) -> np.ndarray | None:
    """A ground point lifted just above the floor; ``None`` if it is not finite (no force)."""
    point = np.asarray(point, dtype=float)
    if not np.all(np.isfinite(point[:2])):
        return None
    return np.array([point[0], point[1], GROUND_LIFT_M])
