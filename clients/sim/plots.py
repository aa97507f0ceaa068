"""PNG plots of a run, simulated or recorded (matplotlib, no display needed).

One figure, four panels: the ground reference points (CM, COP, CMP) over the
support polygon seen from above, the CM height, the momenta, and the joint
torques (the peak and RMS over all joints, and each of the joints that peaked
highest). A simulated run whose base the server estimated from an IMU
(``base_state = "imu"``) gets a fifth: the estimate's tilt, height and yaw
errors against the simulator's truth. Pushes are shaded and labelled with
body, direction and force.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from clients.sim.metrics import base_estimate_error_series
from clients.sim.runner import RunRecord
from clients.sim.scenario import PushSpec
from protocol.messages import Command, JointInfo

__all__ = [
    "PlotSeries",
    "dof_names",
    "plot_run",
    "plot_series",
    "plot_walk_paths",
    "series_of_run",
]

WORST_JOINTS = 4
"""Joints drawn one by one in the torque panel: those of highest peak |τ|."""
VIEW_MARGIN_M = 0.1
"""Room around the support polygon and the CM path in the top view; COP and CMP
points beyond it are drawn on the view's edge as open markers and counted."""


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
    """Plot ``series`` to ``path`` (PNG): the four panels of the module docstring."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    errors = series.estimate_errors
    estimated = errors is not None and errors["time_s"].size > 0
    figure = plt.figure(figsize=(13, 12 if estimated else 8.5), constrained_layout=True)
    grid = figure.add_gridspec(
        3 if estimated else 2, 2, height_ratios=[1, 1, 0.6][: 3 if estimated else 2]
    )
    axes = np.array(
        [[figure.add_subplot(grid[row, column]) for column in range(2)] for row in range(2)]
    )
    if estimated and errors is not None:
        estimate_axes = figure.add_subplot(grid[2, :])
        _estimate_errors(estimate_axes, errors)
        _shade_pushes(estimate_axes, series.pushes)
    diagnosed = [i for i, command in enumerate(series.commands) if command.diagnostics is not None]
    if diagnosed:
        _ground_points(axes[0, 0], series, diagnosed)
        _com_height_and_momenta(axes[0, 1], axes[1, 0], series, diagnosed)
    else:
        for ax in (axes[0, 0], axes[0, 1], axes[1, 0]):
            ax.text(0.5, 0.5, "no diagnostics recorded", ha="center", transform=ax.transAxes)
    _torques(axes[1, 1], series)
    for ax in (axes[0, 1], axes[1, 0], axes[1, 1]):
        _shade_pushes(ax, series.pushes)
    figure.suptitle(series.title)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _ground_points(ax: Any, series: PlotSeries, diagnosed: list[int]) -> None:
    diagnostics = [series.commands[i].diagnostics for i in diagnosed]
    com = np.array([d.position_com_in_world for d in diagnostics if d is not None])
    cop = np.array([d.center_of_pressure for d in diagnostics if d is not None])
    cmp_ = np.array([d.centroidal_moment_pivot for d in diagnostics if d is not None])
    first = diagnostics[0]
    polygon = first.support_polygon_xy.reshape(-1, 2) if first is not None else np.zeros((0, 2))
    if len(polygon) >= 3:
        closed = np.vstack([polygon, polygon[:1]])
        ax.fill(closed[:, 0], closed[:, 1], alpha=0.15, color="grey", label="support (t = 0)")
    corners = np.vstack([polygon, com[:, :2]]) if len(polygon) else com[:, :2]
    low, high = corners.min(axis=0) - VIEW_MARGIN_M, corners.max(axis=0) + VIEW_MARGIN_M
    for points, label, color in ((cop, "COP", "C0"), (cmp_, "CMP", "C1")):
        finite = points[np.isfinite(points[:, :2]).all(axis=1), :2]
        inside = np.all((finite >= low) & (finite <= high), axis=1)
        ax.plot(*finite[inside].T, ".", ms=1.5, color=color, label=label)
        if not inside.all():
            edge = np.clip(finite[~inside], low, high)
            beyond = f"{label}: {int((~inside).sum())} beyond the view (on its edge)"
            ax.plot(*edge.T, "o", mfc="none", ms=4, color=color, label=beyond)
    ax.plot(com[:, 0], com[:, 1], "k-", lw=1.5, label="CM (ground projection)")
    ax.set(
        title="Ground reference points (top view)",
        xlabel="x (m)",
        ylabel="y (m)",
        xlim=(low[0], high[0]),
        ylim=(low[1], high[1]),
        aspect="equal",
    )
    ax.legend(loc="best", fontsize=7)


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
    worst = np.argsort(np.abs(torque).max(axis=0))[::-1][:WORST_JOINTS]
    for dof in worst:
        ax.plot(series.time_s, torque[:, dof], lw=0.8, label=f"τ {names[dof]}")
    ax.set(title=f"Joint torques ({len(worst)} highest peaks)", xlabel="time (s)", ylabel="N·m")
    ax.legend(fontsize=7)


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
    if ax.get_subplotspec().is_first_row() and ax.get_subplotspec().is_last_col():
        for push in pushes:  # labelled once, on the CM height panel
            force = np.asarray(push.force_in_world_N)
            ax.annotate(
                f"{push.body} {_direction(force)} {np.linalg.norm(force):.0f} N",
                xy=(push.start_s, 1.0),
                xycoords=("data", "axes fraction"),
                rotation=90,
                va="top",
                ha="right",
                fontsize=7,
                color="darkred",
            )


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
    """Plot a walk seen from above to ``path`` (PNG), issue 19.

    The CM's ground projection, each sole frame's path, and the sole's outline at every
    touch-down (:func:`~clients.sim.metrics.touchdowns`), by forward kinematics
    (Pinocchio, the scenario's model) of the simulated states.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pinocchio as pin

    from clients.sim.metrics import touchdowns, walking_metrics
    from clients.sim.model_file import describe_model

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
    figure, ax = plt.subplots(figsize=(12, 4.5), constrained_layout=True)
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
        aspect="equal",
    )
    ax.legend(loc="best", fontsize=7)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _outline(points_xy: np.ndarray) -> np.ndarray:
    """The closed convex outline of a few sole points (counter-clockwise)."""
    center = points_xy.mean(axis=0)
    order = np.argsort(np.arctan2(*(points_xy - center).T[::-1]))
    ordered = points_xy[order]
    return np.vstack([ordered, ordered[:1]])
