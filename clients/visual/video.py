"""A run as an MP4: MuJoCo renders the robot offscreen, overlays drawn into the scene.

Each frame poses the robot at the last tick at or before the frame's time
(``fps`` frames per second of simulated time: the 1 kHz ticks subsampled),
adds the tick's overlays (:mod:`clients.visual.overlays`) to MuJoCo's scene
as user geoms — the push as a red arrow, the COP as a green and the CMP as
a blue disc on the ground, the support polygon in yellow, a floor grid every
``GRID_SPACING_M`` so that motion shows — and burns the caption into the
top of the image. The camera looks at the base from the robot's left,
following it over the floor (its height stays put). Frames are encoded to
H.264 (yuv420p) by PyAV, which ships its own FFmpeg.

Rendering needs headless OpenGL: call :func:`~clients.visual.gl.choose_headless_gl`
before anything imports ``mujoco``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

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
    "VIDEO_FPS",
    "FrameRenderer",
    "frame_ticks",
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
POLYGON_RGBA = (1.0, 0.85, 0.1, 1.0)
GRID_RGBA = (0.55, 0.57, 0.62, 1.0)
GRID_SPACING_M = 0.5
GRID_HALF_LINES = 8
CAMERA_DISTANCE_M = 2.8
CAMERA_AZIMUTH_DEG = 75.0
"""From the robot's right, a little behind: pushes along x cross the picture."""
CAMERA_ELEVATION_DEG = -20.0
FLOOR_RGBA = (0.78, 0.8, 0.84, 1.0)
MARKER_RADIUS_M = 0.04


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
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self._camera.distance = CAMERA_DISTANCE_M
        self._camera.azimuth = CAMERA_AZIMUTH_DEG
        self._camera.elevation = CAMERA_ELEVATION_DEG
        self._look_height_m = 0.8 * float(track.welcome.standing_position_base_in_world[2])

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
    for point, rgba in (
        (overlays.center_of_pressure, COP_RGBA),
        (overlays.centroidal_moment_pivot, CMP_RGBA),
    ):
        if point is not None:
            _add_geom(
                scene,
                mujoco.mjtGeom.mjGEOM_CYLINDER,
                rgba,
                size=(MARKER_RADIUS_M, 0.004, 0.0),
                position=point,
            )


def _with_caption(image: np.ndarray, caption: str) -> np.ndarray:
    """``image`` with ``caption`` in white on a dark band across its top."""
    from PIL import Image, ImageDraw, ImageFont

    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    font = ImageFont.load_default(size=16)
    draw.rectangle((0, 0, picture.width, 26), fill=(20, 20, 28))
    draw.text((8, 4), caption, fill=(255, 255, 255), font=font)
    return np.asarray(picture)
