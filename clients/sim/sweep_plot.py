"""The picture of a push sweep: survived/fell over push direction × force, per controller.

One polar panel per controller, seen from above: the angle is the push's
direction in the horizontal plane (x forward at the top, y left: a push
"from behind", +x, points up), the radius its force (N). Every trial of the
bisection is a point, a filled green circle if the robot stayed up and a
red cross if it fell; the largest force survived per direction is joined by
a line. The radius ends a little beyond the largest answer: the first
trials (2000 N, 1000 N, …) all fell and would squeeze the answers into the
centre, so trials beyond the edge are drawn on it as open markers.

A sweep still running or stopped is drawn as far as it got: every trial that
ran, the answer only of the finished bisections, and the titles say how many
are finished.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from clients.sim.sweep import Sweep

__all__ = ["plot_sweep", "push_azimuth_rad", "pyplot"]

EDGE_MARGIN = 1.5
"""The radius ends at this multiple of the largest force survived (rounded up to 50 N)."""


def push_azimuth_rad(direction: tuple[float, float, float]) -> float:
    """Angle of a push direction in the horizontal plane (rad, 0 along +x, +π/2 along +y).

    A vertical push (no horizontal part) is drawn at 0.
    """
    return math.atan2(direction[1], direction[0])


def pyplot() -> ModuleType:
    """``matplotlib.pyplot`` on the Agg backend, imported on first use (a second or so).

    A sweep imports it before its first trial: a Ctrl-C in the middle of an import
    leaves the module half made, and the sweep could not draw what it ran.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_sweep(sweep: Sweep, path: Path) -> None:
    """Plot ``sweep`` to ``path`` (PNG, whatever its suffix): a polar panel per controller.

    See the module docstring.
    """
    plt = pyplot()
    pairs = [b for row in sweep.bisections.values() for b in row.values()]
    answers = [b.largest_survived_N for b in pairs if b.done]
    edge_N = 50.0 * math.ceil(max(50.0, EDGE_MARGIN * max(answers, default=0.0)) / 50.0)
    count = len(sweep.bisections)
    columns = min(count, 2)
    rows = math.ceil(count / columns)
    figure, axes = plt.subplots(
        rows,
        columns,
        figsize=(5.2 * columns, 5.4 * rows + 0.4),
        subplot_kw={"projection": "polar"},
        squeeze=False,
        constrained_layout=True,
    )
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    azimuths = {name: push_azimuth_rad(xyz) for name, xyz in sweep.directions.items()}
    for ax, (label, row) in zip(axes.flat, sweep.bisections.items(), strict=False):
        ax.set_theta_zero_location("N")  # +x (forward) up, +y (left) to the left
        ax.set_rlim(0.0, edge_N)
        ax.set_rlabel_position(-67.5)  # the force scale between the swept directions
        ax.tick_params(axis="y", labelsize=7)
        for survived, style in ((True, {"marker": "o", "color": "tab:green"}), (False, {})):
            inside: list[tuple[float, float]] = []  # (azimuth rad, force N)
            beyond: list[tuple[float, float]] = []
            for name, bisection in row.items():
                for force_N, ok in bisection.trials:
                    if ok == survived:
                        point = (azimuths[name], min(force_N, edge_N))
                        (inside if force_N <= edge_N else beyond).append(point)
            style = style or {"marker": "x", "color": "tab:red"}
            name = "survived" if survived else "fell"
            if inside:
                ax.scatter(*zip(*inside, strict=True), s=28, label=name, zorder=3, **style)
            if beyond:
                ax.scatter(
                    *zip(*beyond, strict=True),
                    s=36,
                    marker="o",
                    facecolors="none",
                    edgecolors=style["color"],
                    label=f"{name} beyond {edge_N:.0f} N ({len(beyond)})",
                    zorder=3,
                )
        order = sorted((n for n in row if row[n].done), key=lambda name: azimuths[name])
        angles = [azimuths[name] for name in order]
        forces = [row[name].largest_survived_N for name in order]
        if len(order) > 2 and len(order) == len(row):  # a closed outline around the robot
            angles, forces = [*angles, angles[0]], [*forces, forces[0]]
        if order:
            ax.plot(angles, forces, color="tab:green", linewidth=1.2, label="largest survived")
        for name in order:
            ax.annotate(
                f"{row[name].largest_survived_N:.0f} N",
                (azimuths[name], row[name].largest_survived_N),
                textcoords="offset points",
                xytext=(4, 4),
                fontsize=8,
            )
        ticks = sorted(set(azimuths.values()))
        names = ["\n".join(n for n in sweep.directions if azimuths[n] == a) for a in ticks]
        ax.set_xticks(ticks, names, fontsize=8)
        for angle, text in zip(ticks, ax.get_xticklabels(), strict=True):
            across = -math.sin(angle)  # screen x of the direction: +x is up, +y to the left
            text.set_horizontalalignment(
                "right" if across < -0.3 else "left" if across > 0.3 else "center"
            )
        title = label
        if len(order) < len(row):
            title += f"\n({len(order)} of {len(row)} directions finished)"
        ax.set_title(title, fontsize=10, pad=18)
        if ax.get_legend_handles_labels()[0]:  # a controller not begun has nothing to name
            ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), fontsize=7, ncol=2)
    push = sweep.push
    incomplete = ""
    if not sweep.complete:
        finished = sum(b.done for b in pairs)
        incomplete = f"; incomplete: {finished} of {len(pairs)} bisections finished"
    figure.suptitle(
        f"push sweep: {sweep.scenario}, {push.duration_s:g} s on the {push.body} at "
        f"{push.start_s:g} s{incomplete}\nforce (N) by direction, seen from above (x forward, up)"
    )
    try:
        figure.savefig(path, dpi=100, format="png")
    finally:
        plt.close(figure)
