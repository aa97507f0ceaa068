"""The live 3-D view: a browser page (viser, three.js) that shows a run as it happens.

:class:`LiveView` serves the page (``http://HOST:PORT``) from a thread of
this process; :meth:`LiveView.start` shows a new run's robot, and
:meth:`LiveView.show` poses it at a tick, with the same overlays as the
video (:mod:`clients.visual.overlays`): the push arrow, the COP, the CMP,
the support polygon and the caption. Two live plots of the diagnostics
follow the last ``PLOT_WINDOW_S`` seconds: the CM, COP and CMP fore and aft
(x, m), and the momenta's magnitudes. The robot's geoms are MuJoCo's
(:class:`~clients.visual.scene.RobotScene`), one mesh each, hung from one
node per body: a tick sends each body's pose (world frame, quaternion
``w x y z`` as viser takes it). Updates are sent at most ``VIEW_HZ`` times a
wall-clock second, so a 1 kHz run costs the loop little.
"""

from __future__ import annotations

import bisect
import contextlib
import io
import logging
import time
from typing import Any

import mujoco
import numpy as np

from clients.track import Track
from clients.visual.overlays import TickOverlays, overlays_at
from clients.visual.scene import RobotScene

__all__ = ["PLOT_WINDOW_S", "ROBOT_RGB", "VIEW_HZ", "LiveView"]

VIEW_HZ = 30.0
"""Most scene updates per wall-clock second."""
PLOT_HZ = 5.0
"""Most plot updates per wall-clock second (each sends the window's data)."""
PLOT_WINDOW_S = 5.0
"""Seconds of simulated time the live plots show."""
PLOT_POINTS = 500
"""Most points a plot shows (the diagnostics in its window, evenly thinned)."""
ROBOT_RGB = (60, 100, 190)
"""Colour of the robot's grey geoms (three.js lights a light grey to near white on white)."""
ARROW_RGB = (230, 30, 20)
COP_RGB = (30, 200, 60)
CMP_RGB = (40, 110, 250)
POLYGON_RGB = (240, 200, 20)

_MESHES = {
    int(mujoco.mjtGeom.mjGEOM_BOX),
    int(mujoco.mjtGeom.mjGEOM_SPHERE),
    int(mujoco.mjtGeom.mjGEOM_CAPSULE),
    int(mujoco.mjtGeom.mjGEOM_CYLINDER),
    int(mujoco.mjtGeom.mjGEOM_ELLIPSOID),
    int(mujoco.mjtGeom.mjGEOM_MESH),
}


def _geom_mesh(model: mujoco.MjModel, geom: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (in the geom's frame, m) and triangles of a MuJoCo geom."""
    import trimesh

    kind, size = int(model.geom_type[geom]), model.geom_size[geom]
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        shape = trimesh.creation.box(extents=2 * size)
    elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        shape = trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        shape = trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=[12, 12])
    elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        shape = trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=16)
    elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        shape = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        shape.apply_scale(size)
    else:  # a mesh: MuJoCo keeps its vertices in the geom's frame
        mesh = int(model.geom_dataid[geom])
        first, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        face, faces = int(model.mesh_faceadr[mesh]), int(model.mesh_facenum[mesh])
        return (
            np.array(model.mesh_vert[first : first + count]),
            np.array(model.mesh_face[face : face + faces]),
        )
    return np.asarray(shape.vertices), np.asarray(shape.faces)


def _rgb(rgba: np.ndarray) -> tuple[int, int, int]:
    """A geom's colour: its own, or ``ROBOT_RGB`` for a light grey (shaded as dark as it is)."""
    red, green, blue = rgba[:3]
    if max(red, green, blue) - min(red, green, blue) < 0.1 and red > 0.4:
        return ROBOT_RGB
    return (int(255 * red), int(255 * green), int(255 * blue))


class LiveView:
    """``view = LiveView(port)``, then ``view.observe(track)`` every tick; ``view.close()``.

    Args:
        host: Interface to serve on (default loopback only).
        port: TCP port of the page and its WebSocket.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8080):
        import viser

        logging.getLogger("websockets").setLevel(logging.WARNING)
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: `url` says it
            self._server = viser.ViserServer(host=host, port=port, verbose=False)
        self._server.scene.set_up_direction("+z")
        self._server.scene.add_grid("/floor", width=20.0, height=20.0, cell_size=0.25)
        self._caption = self._server.gui.add_markdown("waiting for a run …")
        self._plots: list[Any] = []
        self._bodies: list[Any] = []
        # COP and CMP markers move (created once); the polygon and the push arrows are
        # made anew when their number of segments changes.
        self._markers = [
            self._server.scene.add_icosphere(
                f"/overlays/{name}", radius=0.03, color=rgb, visible=False
            )
            for name, rgb in (("cop", COP_RGB), ("cmp", CMP_RGB))
        ]
        self._polygon: Any = None
        self._arrows: Any = None
        self._scene: RobotScene | None = None
        self._track: Track | None = None
        self._last_show_s = self._last_plot_s = -np.inf

    @property
    def url(self) -> str:
        """Where the page is served."""
        return f"http://{self._server.get_host()}:{self._server.get_port()}"

    def close(self) -> None:
        """Stop serving."""
        with contextlib.redirect_stdout(io.StringIO()):  # viser's "Server stopped"
            self._server.stop()

    def start(self, track: Track) -> None:
        """Show a new run: its robot (in its first state), plots emptied.

        Raises:
            UnsupportedModel: MuJoCo cannot load the run's model.
        """
        scene = RobotScene(track)
        model = scene.model
        server = self._server
        for node in self._bodies:
            node.remove()
        self._bodies = []
        for body in range(1, model.nbody):
            node = server.scene.add_frame(f"/robot/body{body}", show_axes=False)
            self._bodies.append(node)
            for geom in np.flatnonzero(model.geom_bodyid == body):
                if int(model.geom_type[geom]) not in _MESHES or model.geom_rgba[geom, 3] == 0:
                    continue
                vertices, faces = _geom_mesh(model, int(geom))
                server.scene.add_mesh_simple(
                    f"/robot/body{body}/geom{geom}",
                    vertices,
                    faces,
                    color=_rgb(model.geom_rgba[geom]),
                    position=model.geom_pos[geom],
                    wxyz=model.geom_quat[geom],
                    flat_shading=True,
                )
        for plot in self._plots:
            plot.remove()
        self._plots = [self._add_plot("CM, COP, CMP x (m)", ("CM", "COP", "CMP"))]
        self._plots.append(self._add_plot("momenta", ("|L| kg·m/s", "|H| kg·m²/s")))
        self._scene = scene
        standing = np.asarray(track.welcome.standing_position_base_in_world)
        server.initial_camera.look_at = (standing[0], standing[1], 0.8 * standing[2])
        server.initial_camera.position = (standing[0] + 0.7, standing[1] - 2.7, 1.4 * standing[2])
        self._last_show_s = self._last_plot_s = -np.inf
        if len(track.states):
            self.show(track, len(track.states) - 1, force=True)

    def observe(self, track: Track) -> None:
        """A run's observer (:data:`~clients.track.RunObserver`): shows its last tick.

        A new track object is a new run, started; a growing one is shown at
        most ``VIEW_HZ`` times a second (the ticks between are not drawn).
        """
        if not track.states:
            return
        if track is not self._track:
            self._track = track
            self.start(track)
        elif time.monotonic() - self._last_show_s >= 1.0 / VIEW_HZ:
            self.show(track, len(track.states) - 1)

    def _add_plot(self, title: str, labels: tuple[str, ...]) -> Any:
        """A uPlot chart of ``labels`` over simulated time (the x axis is not a date)."""
        colours = ("#444444", "#1ec83c", "#286efa")
        series: list[Any] = [{"label": "t (s)"}] + [
            {"label": label, "stroke": colour, "width": 2}
            for label, colour in zip(labels, colours, strict=False)
        ]
        empty = tuple(np.zeros(1) for _ in range(len(labels) + 1))
        return self._server.gui.add_uplot(
            data=empty,
            series=tuple(series),
            title=title,
            aspect=1.6,
            scales={"x": {"time": False}},
        )

    def show(self, track: Track, tick: int, force: bool = False) -> None:
        """Pose the robot at ``tick`` of ``track``, with its overlays and plots.

        Drops the update (returns at once) if the last was under ``1 / VIEW_HZ``
        s ago, unless ``force``.
        """
        now = time.monotonic()
        if self._scene is None or (not force and now - self._last_show_s < 1.0 / VIEW_HZ):
            return
        self._last_show_s = now
        scene, server = self._scene, self._server
        scene.pose(track.states[tick])
        overlays = overlays_at(track, tick, scene.point_in_world)
        with server.atomic():
            for body, node in enumerate(self._bodies, start=1):
                node.position = scene.data.xpos[body].copy()
                node.wxyz = scene.data.xquat[body].copy()
            self._draw_overlays(overlays)
            self._caption.content = f"**{overlays.caption}**"
        if force or now - self._last_plot_s >= 1.0 / PLOT_HZ:
            self._last_plot_s = now
            self._update_plots(track, tick)

    def _draw_overlays(self, overlays: TickOverlays) -> None:
        """Pushes, support polygon, COP and CMP of one tick (within ``server.atomic()``)."""
        scene = self._server.scene
        if self._arrows is not None:
            self._arrows.remove()
            self._arrows = None
        if overlays.pushes:
            self._arrows = scene.add_arrows(
                "/overlays/pushes",
                np.array([[a.tail_in_world, a.head_in_world] for a in overlays.pushes]),
                ARROW_RGB,
                shaft_radius=0.012,
                head_radius=0.03,
                head_length=0.06,
            )
        polygon = overlays.support_polygon
        segments = np.stack([polygon, np.roll(polygon, -1, axis=0)], axis=1)
        if self._polygon is not None and len(self._polygon.points) != len(segments):
            self._polygon.remove()
            self._polygon = None
        if self._polygon is not None:
            self._polygon.points = segments
        elif len(segments):
            self._polygon = scene.add_line_segments(
                "/overlays/support_polygon", segments, POLYGON_RGB, thickness=0.008
            )
        points = (overlays.center_of_pressure, overlays.centroidal_moment_pivot)
        for marker, point in zip(self._markers, points, strict=True):
            marker.visible = point is not None
            if point is not None:
                marker.position = point

    def _update_plots(self, track: Track, tick: int) -> None:
        """The plots over the last ``PLOT_WINDOW_S`` s, at most ``PLOT_POINTS`` points each."""
        first = bisect.bisect_left(track.time_s, float(track.time_s[tick]) - PLOT_WINDOW_S)
        diagnosed = [i for i in range(first, tick + 1) if track.commands[i].diagnostics is not None]
        if not diagnosed:
            return
        diagnosed = diagnosed[:: -(-len(diagnosed) // PLOT_POINTS)]
        times = np.array([track.time_s[i] for i in diagnosed], dtype=float)
        rows = [d for i in diagnosed if (d := track.commands[i].diagnostics) is not None]
        ground = np.array(
            [
                (d.position_com_in_world[0], d.center_of_pressure[0], d.centroidal_moment_pivot[0])
                for d in rows
            ]
        )
        linear = np.array([d.linear_momentum for d in rows], dtype=float)
        angular = np.array([d.angular_momentum for d in rows], dtype=float)
        ground_plot, momenta_plot = self._plots
        ground_plot.data = (times, *ground.T)
        momenta_plot.data = (
            times,
            np.linalg.norm(linear, axis=1),
            np.linalg.norm(angular, axis=1),
        )
