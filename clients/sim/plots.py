"""PNG plots of a run, simulated or recorded (matplotlib, no display needed).

One figure, four panels: the ground reference points (CM, COP, CMP) seen from
above, the CM height, the momenta, and the joint torques (the peak and RMS
over all joints, and each of the joints that peaked highest). A simulated run
whose base the server estimated from an IMU (``base_state = "imu"``) gets a
fifth: the estimate's tilt, height and yaw errors against the simulator's
truth. Pushes are shaded and labelled with body, direction and force.

What each panel guarantees (issue 40, the tests check it on the figure):

* The top view is drawn at equal aspect and holds every point it plots: its
  limits come from the CM path, the COP and CMP and the first support polygon,
  so a walk's view follows the path. A view much wider than tall (a walk)
  takes the figure's whole width. COP and CMP points implying a ground force
  leaning more than 45° (farther from the CM's ground projection than the CM
  is high: a nearly unloaded foot) are outliers: drawn on the view's edge as
  open markers and counted in the legend, which sits outside the axes.
* Push labels sit in a band above the CM height panel, in as many rows as
  they need not to overlap, never on the curve.
* Torque traces of a ``left`` joint are solid and wide, those of a ``right``
  one dashed and drawn over them, so mirrored joints that carry the same
  torque (quiet standing) both show; a trace equal to another one says so.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from clients.physics.backend import PushSpec
from clients.sim.metrics import base_estimate_error_series
from clients.sim.runner import RunRecord
from protocol.messages import Command, JointInfo

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "PlotSeries",
    "dof_names",
    "draw_series",
    "draw_walk_paths",
    "plot_run",
    "plot_series",
    "plot_walk_paths",
    "series_of_run",
]

WORST_JOINTS = 4
"""Joints drawn one by one in the torque panel: those of highest peak |τ|."""
VIEW_MARGIN_M = 0.05
"""Room around everything the top view shows."""
WIDE_VIEW_RATIO = 2.5
"""A top view this many times wider than tall (a walk) spans the figure's width."""
FIGURE_WIDTH_IN = 13.0
WIDE_VIEW_AXES_WIDTH_IN = 10.5
"""About the width of a full-width top view's axes, its legend beside it (inches)."""
PUSH_LABEL_GAP_PT = 3.0
"""Between the CM height panel's top and the first row of push labels (points)."""
PUSH_LABEL_ROW_PT = 11.0
"""Height of a row of push labels (points; the labels are 7 pt)."""
PUSH_LABEL_SPACE_PX = 6.0
"""Least room between two push labels on one row (pixels)."""
SAME_TRACE_TOLERANCE = 1e-3
"""Two torque traces closer than this fraction of the larger peak are called the same."""


@dataclass
class PlotSeries:
    """What the plot shows, from a simulator run or a recorded log.

    Attributes:
        title: The figure's title.
        time_s: Time of each command (s).
        commands: The commands, one per tick (some carry diagnostics).
        dof_names: A name per ``joint_torque`` entry (:func:`dof_names`).
        pushes: Pushes to shade (a log does not know them).
        estimate_errors: The base estimate's errors against the truth
            (:func:`~clients.sim.metrics.base_estimate_error_series`), when known.
    """

    title: str
    time_s: np.ndarray
    commands: Sequence[Command]
    dof_names: Sequence[str]
    pushes: Sequence[PushSpec] = field(default_factory=tuple)
    estimate_errors: dict[str, np.ndarray] | None = None


def series_of_run(record: RunRecord) -> PlotSeries:
    """The plot series of a simulator run."""
    scenario = record.scenario
    status = f"fell at {record.fall_time_s:.2f} s" if record.fell else "stayed up"
    return PlotSeries(
        title=f"{scenario.name} — {scenario.controller} controller, "
        f"{scenario.backend} backend: {status}",
        time_s=np.asarray(record.time_s),
        commands=record.commands,
        dof_names=dof_names(record.welcome.joints),
        pushes=scenario.pushes,
        estimate_errors=base_estimate_error_series(record) if record.commands else None,
    )


def plot_run(record: RunRecord, path: Path) -> None:
    """Plot a simulator run to ``path`` (PNG)."""
    plot_series(series_of_run(record), path)


def plot_series(series: PlotSeries, path: Path) -> None:
    """Plot ``series`` to ``path`` (PNG): the panels of the module docstring."""
    _save(draw_series(series), path)


def _save(figure: Figure, path: Path) -> None:
    import matplotlib.pyplot as plt

    try:
        figure.savefig(path, dpi=100)
    finally:
        plt.close(figure)


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_series(series: PlotSeries) -> Figure:
    """The figure :func:`plot_series` saves (the caller closes it: ``plt.close(figure)``)."""
    plt = _pyplot()
    errors = series.estimate_errors
    estimated = errors is not None and errors["time_s"].size > 0
    diagnosed = [i for i, command in enumerate(series.commands) if command.diagnostics is not None]
    view = _ground_view(series, diagnosed) if diagnosed else None
    span = view.high - view.low if view is not None else np.ones(2)
    wide = bool(span[0] > WIDE_VIEW_RATIO * span[1])
    if wide:  # a walk: the top view across the figure
        view_in = float(np.clip(WIDE_VIEW_AXES_WIDTH_IN * span[1] / span[0], 1.4, 5.0)) + 0.9
        heights = [view_in, 3.6, 3.6] + ([2.6] if estimated else [])
        figure = plt.figure(figsize=(FIGURE_WIDTH_IN, sum(heights)), constrained_layout=True)
        grid = figure.add_gridspec(len(heights), 2, height_ratios=heights)
        ground_ax = figure.add_subplot(grid[0, :])
        height_ax, momenta_ax = figure.add_subplot(grid[1, 0]), figure.add_subplot(grid[1, 1])
        torque_ax = figure.add_subplot(grid[2, :])
        estimate_at = grid[3, :] if estimated else None
    else:
        heights = [1.0, 1.0] + ([0.6] if estimated else [])
        figure = plt.figure(
            figsize=(FIGURE_WIDTH_IN, 12 if estimated else 8.5), constrained_layout=True
        )
        grid = figure.add_gridspec(len(heights), 2, height_ratios=heights)
        ground_ax, height_ax = figure.add_subplot(grid[0, 0]), figure.add_subplot(grid[0, 1])
        momenta_ax, torque_ax = figure.add_subplot(grid[1, 0]), figure.add_subplot(grid[1, 1])
        estimate_at = grid[2, :] if estimated else None
    if estimated and errors is not None:
        estimate_axes = figure.add_subplot(estimate_at)
        _estimate_errors(estimate_axes, errors)
        _shade_pushes(estimate_axes, series.pushes)
    if view is not None:
        _ground_points(ground_ax, view, legend_below=not wide)
        _com_height_and_momenta(height_ax, momenta_ax, series, diagnosed)
    else:
        for ax in (ground_ax, height_ax, momenta_ax):
            ax.text(0.5, 0.5, "no diagnostics recorded", ha="center", transform=ax.transAxes)
    _torques(torque_ax, series)
    for ax in (height_ax, momenta_ax, torque_ax):
        _shade_pushes(ax, series.pushes)
    figure.suptitle(series.title)
    _label_pushes(height_ax, series.pushes)
    return figure


@dataclass(frozen=True)
class _GroundView:
    """What the top view draws (world x, y in m) and its limits."""

    com: np.ndarray
    polygon: np.ndarray
    inside: dict[str, np.ndarray]
    outliers: dict[str, np.ndarray]
    low: np.ndarray
    high: np.ndarray


def _ground_view(series: PlotSeries, diagnosed: list[int]) -> _GroundView:
    diagnostics = [series.commands[i].diagnostics for i in diagnosed]
    com = np.array([d.position_com_in_world for d in diagnostics if d is not None], dtype=float)
    polygon = next(
        (
            np.asarray(d.support_polygon_xy, dtype=float).reshape(-1, 2)
            for d in diagnostics
            if d is not None and len(d.support_polygon_xy)
        ),
        np.zeros((0, 2)),
    )
    inside, outliers = {}, {}
    for label, name in (("COP", "center_of_pressure"), ("CMP", "centroidal_moment_pivot")):
        points = np.array([getattr(d, name) for d in diagnostics if d is not None], dtype=float)
        finite = np.isfinite(points[:, :2]).all(axis=1)  # NaN: no ground force
        # Farther from the CM's ground projection than the CM is high: the ground force
        # leans more than 45°, beyond any sole's friction — a nearly unloaded foot.
        reach = np.linalg.norm(points[:, :2] - com[:, :2], axis=1)
        far = finite & ~(reach <= np.maximum(com[:, 2], 0.0))
        inside[label] = points[finite & ~far, :2]
        outliers[label] = points[far, :2]
    shown = np.vstack([polygon, com[:, :2], *inside.values()])
    low = shown.min(axis=0) - VIEW_MARGIN_M
    high = shown.max(axis=0) + VIEW_MARGIN_M
    return _GroundView(com[:, :2], polygon, inside, outliers, low, high)


def _ground_points(ax: Any, view: _GroundView, legend_below: bool) -> None:
    if len(view.polygon) >= 3:
        closed = np.vstack([view.polygon, view.polygon[:1]])
        ax.fill(closed[:, 0], closed[:, 1], alpha=0.15, color="grey", label="first support")
    for label, color in (("COP", "C0"), ("CMP", "C1")):
        ax.plot(*view.inside[label].T, ".", ms=1.5, color=color, label=label)
        outliers = view.outliers[label]
        if len(outliers):
            edge = np.clip(outliers, view.low, view.high)
            note = f"{label}: {len(outliers)} outliers (force > 45°), on the edge"
            ax.plot(*edge.T, "o", mfc="none", ms=4, color=color, label=note)
    ax.plot(*view.com.T, "k-", lw=1.5, label="CM (ground projection)")
    ax.set(
        title="Ground reference points (top view)",
        xlabel="x (m)",
        ylabel="y (m)",
    )
    _equal_aspect_around(ax, view.low, view.high)
    _legend_outside(ax, below=legend_below)


def _equal_aspect_around(ax: Any, low: np.ndarray, high: np.ndarray) -> None:
    """Equal aspect, the limits at least ``low`` to ``high`` and widened to the panel's shape.

    Autoscaled (no margins) rather than fixed, so that matplotlib may widen them: a point
    plotted within ``low``…``high`` is never cut off.
    """
    ax.update_datalim(np.array([low, high]))
    ax.margins(0.0)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")


def _legend_outside(ax: Any, below: bool = False) -> None:
    """The legend outside ``ax``, at its right or below it, so it hides no data."""
    if below:
        ax.legend(
            loc="upper center", bbox_to_anchor=(0.5, -0.17), ncol=2, borderaxespad=0.0, fontsize=7
        )
    else:
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=7)


def _com_height_and_momenta(
    height_ax: Any, momenta_ax: Any, series: PlotSeries, diagnosed: list[int]
) -> None:
    time_s = series.time_s[diagnosed]
    diagnostics = [series.commands[i].diagnostics for i in diagnosed]
    com = np.array([d.position_com_in_world for d in diagnostics if d is not None])
    linear = np.array([d.linear_momentum for d in diagnostics if d is not None])
    angular = np.array([d.angular_momentum for d in diagnostics if d is not None])
    height_ax.plot(time_s, com[:, 2])
    height_ax.set(title="CM height", xlabel="time (s)", ylabel="m")
    for i, axis in enumerate("xyz"):
        momenta_ax.plot(time_s, linear[:, i], label=f"L{axis} (kg·m/s)")
        momenta_ax.plot(time_s, angular[:, i], "--", label=f"H{axis} (kg·m²/s)")
    momenta_ax.set(title="Momenta about the CM", xlabel="time (s)")
    momenta_ax.legend(fontsize=7, ncol=2)


def _torques(ax: Any, series: PlotSeries) -> None:
    torque = np.array([command.joint_torque for command in series.commands])
    ax.plot(series.time_s, np.abs(torque).max(axis=1), "k-", lw=1.2, label="max |τ| (all joints)")
    ax.plot(series.time_s, np.sqrt(np.mean(torque**2, axis=1)), "k:", label="RMS τ")
    names = list(series.dof_names)
    if len(names) != torque.shape[1]:
        names = [f"dof {i}" for i in range(torque.shape[1])]
    worst = [int(dof) for dof in np.argsort(np.abs(torque).max(axis=0))[::-1][:WORST_JOINTS]]
    # Left joints first, solid and wide; right ones dashed on top: a mirrored pair carrying
    # the same torque shows both colours.
    order = sorted(worst, key=lambda dof: {"left": 0, None: 1, "right": 2}[_side(names[dof])])
    for rank, dof in enumerate(order):
        side = _side(names[dof])
        label = f"τ {names[dof]}"
        same = [
            names[other]
            for other in order[:rank]
            if np.allclose(
                torque[:, dof],
                torque[:, other],
                rtol=0.0,
                atol=SAME_TRACE_TOLERANCE * max(np.abs(torque[:, [dof, other]]).max(), 1e-9),
            )
        ]
        if same:
            label += f" (= {same[0]})"
        ax.plot(
            series.time_s,
            torque[:, dof],
            "--" if side == "right" else "-",
            lw=1.8 if side == "left" else 1.0,
            color=f"C{worst.index(dof)}",
            label=label,
        )
    ax.set(title=f"Joint torques ({len(worst)} highest peaks)", xlabel="time (s)", ylabel="N·m")
    ax.legend(fontsize=7)


def _side(name: str) -> str | None:
    """``"left"``, ``"right"`` or ``None``: the side a name says (``left_knee``, ``l_hip``)."""
    words = [word for word in re.split(r"[^a-z]+", name.lower()) if word]
    for side in ("left", "right"):
        if any(word == side[0] or word.startswith(side) for word in words):
            return side
    return None


def dof_names(joints: Sequence[JointInfo]) -> list[str]:
    """A name per torque entry: the joint's, or ``name x/y/z`` for a ball joint's three."""
    names = []
    for joint in joints:
        if joint.nv == 1:
            names.append(joint.name)
        else:
            names += [f"{joint.name} {'xyz'[i] if joint.nv == 3 else i}" for i in range(joint.nv)]
    return names


def _shade_pushes(ax: Any, pushes: Sequence[PushSpec]) -> None:
    for push in pushes:
        ax.axvspan(push.start_s, push.start_s + push.duration_s, color="red", alpha=0.15)


def _label_pushes(ax: Any, pushes: Sequence[PushSpec]) -> None:
    """Label each push in a band above ``ax``, in rows so that no two labels overlap.

    The figure is laid out once to measure the labels (the rows change only the band's
    height, not where a time falls across the axes).
    """
    start_s, end_s = ax.get_xlim()
    shown = sorted(
        (push for push in pushes if start_s <= push.start_s <= end_s), key=lambda p: p.start_s
    )
    if not shown:
        return
    labels = []
    for push in shown:
        force = np.asarray(push.force_in_world_N)
        labels.append(
            ax.annotate(
                f"{push.body} {_direction(force)} {np.linalg.norm(force):.0f} N",
                xy=(push.start_s, 1.0),
                xycoords=("data", "axes fraction"),
                xytext=(0.0, PUSH_LABEL_GAP_PT),
                textcoords="offset points",
                va="bottom",
                ha="left",
                fontsize=7,
                color="darkred",
                annotation_clip=False,
            )
        )
    for label in labels:  # the title's pad makes their room; the layout must not move them
        label.set_in_layout(False)
    figure = ax.get_figure()
    figure.draw_without_rendering()
    renderer = figure.canvas.get_renderer()
    left_px, right_px = ax.get_window_extent(renderer).intervalx
    row_ends: list[float] = []  # the right end of each row's last label (pixels)
    for label in labels:
        box = label.get_window_extent(renderer)
        shift = max(min(right_px - box.x1, 0.0), left_px - box.x0)  # not past the axes' ends
        left, right = box.x0 + shift, box.x1 + shift
        row = next(
            (i for i, end in enumerate(row_ends) if end + PUSH_LABEL_SPACE_PX <= left),
            len(row_ends),
        )
        if row == len(row_ends):
            row_ends.append(right)
        row_ends[row] = right
        points_per_px = 72.0 / figure.dpi
        label.xyann = (shift * points_per_px, PUSH_LABEL_GAP_PT + row * PUSH_LABEL_ROW_PT)
    ax.set_title(ax.get_title(), pad=PUSH_LABEL_GAP_PT + len(row_ends) * PUSH_LABEL_ROW_PT + 3)


def _direction(force: np.ndarray) -> str:
    """``+x``, ``-y`` or ``(+0.71, +0.71, 0)`` for a push direction in world."""
    unit = force / max(float(np.linalg.norm(force)), 1e-12)
    axis = int(np.argmax(np.abs(unit)))
    if abs(unit[axis]) > 0.99:
        return f"{'+' if unit[axis] > 0 else '-'}{'xyz'[axis]}"
    return "(" + ", ".join(f"{value:+.2f}" for value in unit) + ")"


def _estimate_errors(ax: Any, errors: dict[str, np.ndarray]) -> None:
    time_s = errors["time_s"]
    ax.plot(time_s, errors["tilt_deg"], color="C0", lw=1, label="tilt (°)")
    ax.plot(time_s, errors["yaw_deg"], color="C2", lw=1, label="yaw (°, unobservable)")
    ax.set(title="Base estimate − truth", xlabel="time (s)", ylabel="angle (°)")
    height_axis = ax.twinx()
    height_axis.plot(time_s, 100 * errors["height_m"], color="C3", lw=1, label="height (cm)")
    height_axis.set_ylabel("height (cm)")
    lines = ax.get_legend_handles_labels()
    more = height_axis.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc="upper left", fontsize=7)


def plot_walk_paths(record: RunRecord, path: Path) -> None:
    """Plot a walk seen from above to ``path`` (PNG), issue 19: :func:`draw_walk_paths`."""
    _save(draw_walk_paths(record), path)


def draw_walk_paths(record: RunRecord) -> Figure:
    """The figure :func:`plot_walk_paths` saves (the caller closes it).

    The CM's ground projection, each sole frame's path, and the sole's outline at every
    touch-down (:func:`~clients.sim.metrics.touchdowns`), by forward kinematics
    (Pinocchio, the scenario's model) of the simulated states; at equal aspect, the
    figure shaped to the walk, the legend outside the axes.
    """
    plt = _pyplot()
    import pinocchio as pin

    from clients.physics.model_file import describe_model
    from clients.sim.metrics import touchdowns, walking_metrics

    model = describe_model(record.scenario.model).model
    data = model.createData()
    contacts = record.welcome.contacts
    frames = [model.getFrameId(contact.frame) for contact in contacts]
    com: list[np.ndarray] = []
    feet: list[list[np.ndarray]] = [[] for _ in contacts]
    outlines: list[tuple[int, np.ndarray]] = []
    landings: dict[int, list[int]] = {}
    for tick, foot in touchdowns(record):
        landings.setdefault(tick, []).append(foot)
    for tick, state in enumerate(record.states):
        q = np.concatenate(
            [
                state.position_base_in_world,
                state.orientation_base_in_world_xyzw,
                state.joint_position,
            ]
        )
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        com.append(pin.centerOfMass(model, data, q, False)[:2].copy())
        for index, frame in enumerate(frames):
            feet[index].append(data.oMf[frame].translation[:2].copy())
        for index in landings.get(tick, []):
            sole = contacts[index].points_in_frame
            corners = np.array(sole) if sole else np.zeros((1, 3))
            placement = data.oMf[frames[index]]
            points = (placement.rotation @ corners.T).T + placement.translation
            outlines.append((index, _outline(points[:, :2])))
    shown = np.vstack([np.array(com), *(np.array(f) for f in feet), *(o for _, o in outlines)])
    low, high = shown.min(axis=0) - VIEW_MARGIN_M, shown.max(axis=0) + VIEW_MARGIN_M
    span = high - low
    axes_height_in = float(np.clip(WIDE_VIEW_AXES_WIDTH_IN * span[1] / span[0], 1.5, 8.0))
    figure, ax = plt.subplots(
        figsize=(FIGURE_WIDTH_IN, axes_height_in + 1.1), constrained_layout=True
    )
    colors = ("C0", "C3", "C2", "C4")
    for index, contact in enumerate(contacts):
        path_xy = np.array(feet[index])
        ax.plot(*path_xy.T, "-", lw=0.8, color=colors[index % 4], label=f"{contact.name} path")
    for index, outline in outlines:
        ax.fill(*outline.T, alpha=0.25, color=colors[index % 4])
    ax.plot(*np.array(com).T, "k-", lw=1.5, label="CM (ground projection)")
    metrics = walking_metrics(record)
    status = f"fell at {record.fall_time_s:.2f} s" if record.fell else "stayed up"
    ax.set(
        title=f"{record.scenario.name} ({record.scenario.backend}), seen from above: "
        f"{metrics['distance_m']:.2f} m at {metrics.get('speed_m_per_s', 0.0):.2f} m/s, "
        f"{metrics['step_count']} steps, {status}",
        xlabel="x (m)",
        ylabel="y (m)",
    )
    _equal_aspect_around(ax, low, high)
    _legend_outside(ax)
    return figure


def _outline(points_xy: np.ndarray) -> np.ndarray:
    """The closed convex outline of a few sole points (counter-clockwise)."""
    center = points_xy.mean(axis=0)
    order = np.argsort(np.arctan2(*(points_xy - center).T[::-1]))
    ordered = points_xy[order]
    return np.vstack([ordered, ordered[:1]])
