"""A run as an MP4: MuJoCo renders the robot offscreen, overlays drawn into the scene.

Each frame poses the robot at the last tick at or before the frame's time
(``fps`` frames per second of simulated time: the 1 kHz ticks subsampled),
adds the tick's overlays (:mod:`clients.visual.overlays`) to MuJoCo's scene
as user geoms — the push as a red arrow, the support polygon in yellow, a
floor grid every ``GRID_SPACING_M`` on a brown floor (the rendered scene's
only: the grey robot stands out) so that motion shows — then draws the COP
(a green disc) and the CMP (a blue ring around it, as the two often
coincide) over the image where they lie on the ground, outlined in white:
on top, since the feet would hide them, and sized to the robot
(``MARKER_RADIUS_PER_HEIGHT`` of its standing height, seen at their
distance). The caption is burnt into the top of the image. The camera looks
at the base from the robot's right, a little behind, following it over the
floor (its height stays put), from a distance that fits the robot's height.
Frames are encoded to H.264 (yuv420p) by PyAV, which ships its own FFmpeg.

Rendering needs headless OpenGL: call :func:`~clients.visual.gl.choose_headless_gl`
before anything imports ``mujoco``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from clients.track import Track
from clients.visual.gl import open_renderer
from clients.visual.overlays import TickOverlays, overlays_at
from clients.visual.scene import RobotScene

__all__ = [
    "ARROW_RGBA",
    "CMP_RGBA",
    "COP_RGBA",
    "FLOOR_RGBA",
    "VIDEO_FPS",
    "FrameRenderer",
    "frame_ticks",
    "project_to_pixels",
    "write_video",
]

VIDEO_FPS = 30
"""Frames per second of simulated time."""
WIDTH_PX, HEIGHT_PX = 640, 480
ARROW_RGBA = (1.0, 0.1, 0.05, 1.0)
"""Push arrows: red."""
COP_RGBA = (0.1, 0.85, 0.2, 1.0)
"""Centre of pressure: green."""
CMP_RGBA = (0.15, 0.45, 1.0, 1.0)
"""Centroidal moment pivot: blue."""
MARKER_OUTLINE_RGB = (255, 255, 255)
"""Around the COP and CMP markers, so they show on the floor and on the robot alike."""
POLYGON_RGBA = (1.0, 0.85, 0.1, 1.0)
FLOOR_RGBA = (0.42, 0.29, 0.18, 1.0)
"""The rendered floor: brown, against the light grey robot (the model's own is unchanged)."""
GRID_RGBA = (0.74, 0.62, 0.48, 1.0)
GRID_SPACING_M = 0.5
GRID_HALF_LINES = 8
CAMERA_DISTANCE_PER_HEIGHT = 1.7
"""Camera distance per metre of the robot's standing height: the whole robot in view."""
CAMERA_AZIMUTH_DEG = 75.0
"""From the robot's right, a little behind: pushes along x cross the picture."""
CAMERA_ELEVATION_DEG = -20.0
MARKER_RADIUS_PER_HEIGHT = 0.03
"""COP disc radius per metre of the robot's standing height (the CMP ring is 1.6 times it)."""
CMP_RING_RADIUS = 1.6
"""The CMP ring's radius per COP disc radius."""


def frame_ticks(track: Track, fps: float = VIDEO_FPS) -> list[int]:
    """The tick drawn in each frame: the last at or before ``k / fps`` s, for every frame.

    ``round(duration × fps)`` frames (at least one).
    """
    frames = max(1, round(track.duration_s * fps))
    return [track.tick_at(k / fps) for k in range(frames)]


class FrameRenderer:
    """``renderer.frame(tick)`` → an RGB image ``(height, width, 3)`` of the track at a tick.

    Args:
        track: The run to draw.
        width: Image width (pixels, even).
        height: Image height (pixels, even).

    Raises:
        UnsupportedModel: MuJoCo cannot load the track's model.
        RenderingUnavailable: No OpenGL context could be made.
    """

    def __init__(self, track: Track, width: int = WIDTH_PX, height: int = HEIGHT_PX):
        self.track = track
        self.scene = RobotScene(track)
        model = self.scene.model
        model.vis.global_.offwidth = max(width, int(model.vis.global_.offwidth))
        model.vis.global_.offheight = max(height, int(model.vis.global_.offheight))
        model.vis.quality.offsamples = 0  # no multisampling: a third of the time per frame
        model.geom_rgba[model.geom_bodyid == 0] = FLOOR_RGBA
        model.vis.headlight.ambient[:] = 0.35
        model.vis.headlight.diffuse[:] = 0.6
        self._renderer = open_renderer(model, height, width)
        self._options = mujoco.MjvOption()
        robot_height_m = self._standing_height_m()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self._camera.distance = CAMERA_DISTANCE_PER_HEIGHT * robot_height_m
        self._camera.azimuth = CAMERA_AZIMUTH_DEG
        self._camera.elevation = CAMERA_ELEVATION_DEG
        self._look_height_m = 0.5 * robot_height_m
        self.marker_radius_m = MARKER_RADIUS_PER_HEIGHT * robot_height_m

    def _standing_height_m(self) -> float:
        """The top of the robot's geoms (their bounding spheres) in its first state (m)."""
        self.scene.pose(self.track.states[0])
        model, data = self.scene.model, self.scene.data
        robot = model.geom_bodyid != 0
        if not robot.any():
            return float(self.track.welcome.standing_position_base_in_world[2])
        return float(np.max(data.geom_xpos[robot, 2] + model.geom_rbound[robot]))

    def close(self) -> None:
        """Free the OpenGL context."""
        self._renderer.close()

    def __enter__(self) -> FrameRenderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def frame(self, tick: int) -> np.ndarray:
        """The image of ``tick``: robot, overlays, caption."""
        state = self.track.states[tick]
        self.scene.pose(state)
        overlays = overlays_at(self.track, tick, self.scene.point_in_world)
        base = state.position_base_in_world
        self._camera.lookat[:] = (base[0], base[1], self._look_height_m)
        self._renderer.update_scene(self.scene.data, self._camera, self._options)
        scene = self._renderer.scene
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        _add_grid(scene, base[:2])
        _add_overlays(scene, overlays)
        image = self._renderer.render()
        image = _with_markers(image, scene, overlays, self.marker_radius_m)
        return _with_caption(image, overlays.caption)


def write_video(
    track: Track,
    path: str | os.PathLike[str],
    fps: int = VIDEO_FPS,
    progress: Callable[[float], None] | None = None,
) -> Path:
    """Render ``track`` to an MP4 at ``path`` (:func:`frame_ticks` frames); return the path.

    Args:
        track: The run.
        path: The file to write (replaced if it exists).
        fps: Frames per second of simulated time.
        progress: Called with the fraction of frames done.

    Raises:
        UnsupportedModel: MuJoCo cannot load the track's model.
        RenderingUnavailable: No OpenGL context could be made.
    """
    import av

    ticks = frame_ticks(track, fps)
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    with FrameRenderer(track) as renderer, av.open(str(partial), "w", format="mp4") as container:
        stream = container.add_stream("libx264", rate=fps)
        stream.width, stream.height, stream.pix_fmt = WIDTH_PX, HEIGHT_PX, "yuv420p"
        stream.options = {"crf": "23", "preset": "veryfast"}
        for index, tick in enumerate(ticks):
            frame = av.VideoFrame.from_ndarray(renderer.frame(tick), format="rgb24")
            container.mux(stream.encode(frame))
            if progress is not None:
                progress((index + 1) / len(ticks))
        container.mux(stream.encode(None))
    os.replace(partial, path)
    return path


def _add_geom(
    scene: mujoco.MjvScene,
    kind: mujoco.mjtGeom,
    rgba: tuple[float, float, float, float],
    *,
    size: tuple[float, float, float] = (0.0, 0.0, 0.0),
    position: np.ndarray | None = None,
    connect: tuple[np.ndarray, np.ndarray, float] | None = None,
    emission: float = 0.4,
) -> None:
    """Append a user geom to ``scene``: placed at ``position``, or ``connect`` (from, to, width)."""
    if scene.ngeom >= scene.maxgeom:
        return  # a full scene draws the robot and drops the extras
    geom = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(
        geom,
        kind,
        np.asarray(size, dtype=float),
        np.zeros(3) if position is None else np.asarray(position, dtype=float),
        np.eye(3).reshape(-1),
        np.asarray(rgba, dtype=np.float32),
    )
    if connect is not None:
        start, end, width = connect
        mujoco.mjv_connector(geom, kind, width, np.asarray(start), np.asarray(end))
    geom.emission = emission
    scene.ngeom += 1


def _add_grid(scene: mujoco.MjvScene, center_xy: np.ndarray) -> None:
    """Floor lines every ``GRID_SPACING_M`` around ``center_xy`` (snapped to the grid)."""
    snapped = np.round(np.asarray(center_xy) / GRID_SPACING_M) * GRID_SPACING_M
    reach = GRID_HALF_LINES * GRID_SPACING_M
    for offset in np.arange(-GRID_HALF_LINES, GRID_HALF_LINES + 1) * GRID_SPACING_M:
        for axis in (0, 1):
            start = np.array([*snapped, 0.001])
            end = start.copy()
            start[axis] += offset
            end[axis] += offset
            start[1 - axis] -= reach
            end[1 - axis] += reach
            _add_geom(
                scene, mujoco.mjtGeom.mjGEOM_LINE, GRID_RGBA, connect=(start, end, 1.5), emission=0
            )


def _add_overlays(scene: mujoco.MjvScene, overlays: TickOverlays) -> None:
    for arrow in overlays.pushes:
        _add_geom(
            scene,
            mujoco.mjtGeom.mjGEOM_ARROW,
            ARROW_RGBA,
            connect=(arrow.tail_in_world, arrow.head_in_world, 0.025),
        )
    polygon = overlays.support_polygon
    for start, end in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        _add_geom(scene, mujoco.mjtGeom.mjGEOM_CAPSULE, POLYGON_RGBA, connect=(start, end, 0.008))


def project_to_pixels(
    scene: mujoco.MjvScene, points_in_world: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, np.ndarray]:
    """Where world points fall in the rendered image, and their depth along the view.

    The pinhole of MuJoCo's OpenGL camera (``scene.camera``, both eyes averaged, as
    ``mjr_render`` sets it up: the frustum's height from the scene, its width from the
    image's aspect).

    Args:
        scene: The scene as last updated (its camera).
        points_in_world: ``(n, 3)`` points (m).
        width: Image width (pixels).
        height: Image height (pixels).

    Returns:
        ``(n, 2)`` pixel coordinates (column, row; from the top left corner) and ``(n,)``
        depths in front of the camera (m; not positive: behind it).
    """
    camera = mujoco.mjv_averageCamera(scene.camera[0], scene.camera[1])
    forward, up = np.asarray(camera.forward, dtype=float), np.asarray(camera.up, dtype=float)
    right = np.cross(forward, up)
    relative = np.atleast_2d(np.asarray(points_in_world, dtype=float)) - camera.pos
    depth = relative @ forward
    near = camera.frustum_near
    safe = np.where(depth > 1e-9, depth, np.nan)
    x_near, y_near = near * (relative @ right) / safe, near * (relative @ up) / safe
    bottom, top = camera.frustum_bottom, camera.frustum_top
    half_width = 0.5 * width / height * (top - bottom)
    column = (x_near - camera.frustum_center + half_width) / (2 * half_width) * width
    row = (top - y_near) / (top - bottom) * height
    return np.column_stack([column, row]), depth


def _with_markers(
    image: np.ndarray, scene: mujoco.MjvScene, overlays: TickOverlays, radius_m: float
) -> np.ndarray:
    """``image`` with the COP (a disc) and the CMP (a ring) drawn over it, outlined in white.

    A marker of ``radius_m`` on the ground, as large as a sphere of that radius would
    look there (not foreshortened into a sliver by the camera's slant).
    """
    height, width = image.shape[:2]
    markers = [
        (point, ring)
        for point, ring in (
            (overlays.centroidal_moment_pivot, True),
            (overlays.center_of_pressure, False),
        )
        if point is not None
    ]  # the ring first: a COP inside it stays whole
    if not markers:
        return image
    from PIL import Image, ImageDraw

    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    camera = scene.camera[0]
    pixels_per_m_at_1_m = (
        height * camera.frustum_near / (camera.frustum_top - camera.frustum_bottom)
    )
    centers, depths = project_to_pixels(scene, np.array([p for p, _ in markers]), width, height)
    for (_, ring), center, depth in zip(markers, centers, depths, strict=True):
        if not depth > 0:
            continue
        radius = pixels_per_m_at_1_m * radius_m / depth
        if ring:
            radius *= CMP_RING_RADIUS
            thickness = max(2, round(0.35 * radius))
            _circle(draw, center, radius + 1.5, outline=MARKER_OUTLINE_RGB, width=thickness + 3)
            _circle(draw, center, radius, outline=_rgb(CMP_RGBA), width=thickness)
        else:
            _circle(draw, center, radius + 1.5, fill=MARKER_OUTLINE_RGB)
            _circle(draw, center, radius, fill=_rgb(COP_RGBA))
    return np.asarray(picture)


def _circle(draw: Any, center: np.ndarray, radius: float, **style: Any) -> None:
    """A circle of ``radius`` pixels about ``center`` (PIL's ``ellipse`` styles)."""
    column, row = center
    draw.ellipse((column - radius, row - radius, column + radius, row + radius), **style)


def _rgb(rgba: tuple[float, float, float, float]) -> tuple[int, int, int]:
    return tuple(round(255 * channel) for channel in rgba[:3])  # type: ignore[return-value]


def _with_caption(image: np.ndarray, caption: str) -> np.ndarray:
    """``image`` with ``caption`` in white on a dark band across its top."""
    from PIL import Image, ImageDraw, ImageFont

    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    font = ImageFont.load_default(size=16)
    draw.rectangle((0, 0, picture.width, 26), fill=(20, 20, 28))
    draw.text((8, 4), caption, fill=(255, 255, 255), font=font)
    return np.asarray(picture)
