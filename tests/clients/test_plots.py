"""A run's PNG plot fits what it shows (issue 40), checked on the figure itself.

Short synthetic series (a walk of 3.5 m, a symmetric stand, pushes close
together) are drawn by :func:`~clients.sim.plots.draw_series` and the laid-out
figure is measured: the top view's aspect and limits against every point it
plots, where its legend lies, the torque traces' line styles, and the push
labels' boxes against each other, the title and the CM height panel.
"""

from itertools import combinations
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from clients.physics.backend import PushSpec
from clients.sim.plots import PlotSeries, _side, draw_series, draw_walk_paths

TOP_VIEW = "Ground reference points (top view)"
TICKS = 600
DOFS = ["left_ankle y", "right_ankle y", "left_knee y", "right_knee y", "torso x", "neck"]


def series_of(com, cop, cmp_, torque, pushes=()) -> PlotSeries:
    """A series of commands (duck-typed: only what the plot reads) with diagnostics each tick."""
    polygon = np.array([[-0.1, -0.15], [0.15, -0.15], [0.15, 0.15], [-0.1, 0.15]])
    commands = [
        SimpleNamespace(
            joint_torque=torque[tick],
            diagnostics=SimpleNamespace(
                position_com_in_world=com[tick],
                center_of_pressure=cop[tick],
                centroidal_moment_pivot=cmp_[tick],
                support_polygon_xy=polygon.ravel(),
                linear_momentum=np.zeros(3),
                angular_momentum=np.zeros(3),
            ),
        )
        for tick in range(len(com))
    ]
    time_s = np.arange(len(com)) * 0.01
    return PlotSeries("synthetic", time_s, commands, DOFS, pushes=tuple(pushes))


def walking_series(outliers: int = 0) -> PlotSeries:
    """3.5 m along x, swaying ±0.1 m; the COP on alternating feet 0.12 m either side."""
    t = np.linspace(0.0, 1.0, TICKS)
    com = np.column_stack([3.5 * t, 0.1 * np.sin(20 * t), np.full(TICKS, 0.9)])
    foot = np.where(np.sin(20 * t) > 0, 0.22, -0.12)
    cop = np.column_stack([np.round(3.5 * t * 4) / 4, foot, np.zeros(TICKS)])
    cmp_ = cop + np.array([0.03, 0.02, 0.0])
    cmp_[10 : 10 + outliers] = [40.0, -25.0, 0.0]  # a nearly unloaded foot: far off
    cop[20:25] = np.nan  # no ground force
    torque = np.random.default_rng(0).normal(size=(TICKS, len(DOFS)))
    return series_of(com, cop, cmp_, torque)


def standing_series(pushes=()) -> PlotSeries:
    """Quiet standing, the left and right joints carrying the very same torques."""
    t = np.linspace(0.0, 1.0, TICKS)
    com = np.column_stack([0.02 * t, np.zeros(TICKS), 0.9 - 0.01 * t])
    cop = np.column_stack([0.03 * np.sin(9 * t), np.zeros(TICKS), np.zeros(TICKS)])
    ankle, knee = 13 * np.tanh(5 * t), 8 * np.tanh(5 * t)
    small = 0.1 * np.sin(7 * t)
    torque = np.column_stack([ankle, ankle, knee, knee, small, small])
    return series_of(com, cop, cop.copy(), torque, pushes=pushes)


@pytest.fixture
def drawn():
    """``drawn(series)``: the laid-out figure and its axes by title; closed after the test."""
    figures = []

    def draw(series):
        figure = draw_series(series)
        figures.append(figure)
        figure.canvas.draw()
        return figure, {ax.get_title(): ax for ax in figure.axes}

    yield draw
    for figure in figures:
        plt.close(figure)


def overlap(a, b) -> bool:
    """Whether two display boxes share any area (touching edges do not count)."""
    return a.x0 < b.x1 - 0.5 and b.x0 < a.x1 - 0.5 and a.y0 < b.y1 - 0.5 and b.y0 < a.y1 - 0.5


def assert_top_view_holds_its_points(ax) -> None:
    """Equal aspect on screen, and every plotted point (lines, polygons) within the limits."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    box = ax.get_window_extent()
    metres_per_px = ((x1 - x0) / box.width, (y1 - y0) / box.height)
    assert metres_per_px[0] == pytest.approx(metres_per_px[1], rel=0.01)
    plotted = [line.get_xydata() for line in ax.get_lines()]
    plotted += [patch.get_path().vertices for patch in ax.patches]
    points = np.vstack([p[np.isfinite(p).all(axis=1)] for p in plotted])
    assert points[:, 0].min() >= x0 and points[:, 0].max() <= x1
    assert points[:, 1].min() >= y0 and points[:, 1].max() <= y1


def test_a_walks_top_view_follows_it_at_equal_aspect_across_the_figure(drawn):
    figure, axes = drawn(walking_series())
    ax = axes[TOP_VIEW]
    assert_top_view_holds_its_points(ax)
    assert ax.get_xlim()[0] < 0.0 and ax.get_xlim()[1] > 3.5  # the whole walk
    cop = next(line for line in ax.get_lines() if line.get_label() == "COP")
    assert len(cop.get_xydata()) == TICKS - 5  # every COP with a ground force, none clipped
    # Far wider than tall: it spans the figure rather than a quarter of it.
    assert ax.get_window_extent().width > 0.6 * figure.bbox.width
    assert not any("outlier" in line.get_label() for line in ax.get_lines())


def test_far_outliers_are_drawn_on_the_views_edge_and_counted(drawn):
    _, axes = drawn(walking_series(outliers=3))
    ax = axes[TOP_VIEW]
    assert_top_view_holds_its_points(ax)
    assert ax.get_xlim()[1] < 10.0  # not stretched to 40 m for three points
    (edge,) = [line for line in ax.get_lines() if "outlier" in line.get_label()]
    assert edge.get_label().startswith("CMP: 3 outliers")
    assert len(edge.get_xydata()) == 3
    legend_labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert edge.get_label() in legend_labels


@pytest.mark.parametrize("series", [walking_series, standing_series])
def test_the_top_views_legend_lies_outside_its_axes_and_labels(drawn, series):
    _, axes = drawn(series())
    ax = axes[TOP_VIEW]
    legend = ax.get_legend().get_window_extent()
    assert not overlap(legend, ax.get_window_extent())
    assert not overlap(legend, ax.xaxis.label.get_window_extent())
    assert not overlap(legend, ax.yaxis.label.get_window_extent())
    assert_top_view_holds_its_points(ax)


def test_mirrored_torque_traces_differ_in_style_and_say_they_are_equal(drawn):
    _, axes = drawn(standing_series())
    ax = axes["Joint torques (4 highest peaks)"]
    lines = {line.get_label(): line for line in ax.get_lines()}
    left, right = lines["τ left_ankle y"], lines["τ right_ankle y (= left_ankle y)"]
    assert left.get_linestyle() == "-" and right.get_linestyle() == "--"
    assert left.get_linewidth() > right.get_linewidth()  # the wide one shows past the dashes
    assert left.get_color() != right.get_color()
    drawn_order = ax.get_lines()
    assert drawn_order.index(left) < drawn_order.index(right)  # the dashes on top
    knees = [lines["τ left_knee y"], lines["τ right_knee y (= left_knee y)"]]
    assert [line.get_linestyle() for line in knees] == ["-", "--"]


@pytest.mark.parametrize(
    ("name", "side"),
    [
        ("left_ankle y", "left"),
        ("r_hip_pitch", "right"),
        ("RightKnee", "right"),
        ("hip_l", "left"),
        ("torso x", None),
        ("lumbar", None),
    ],
)
def test_a_joints_side_is_read_from_its_name(name, side):
    assert _side(name) == side


def test_push_labels_sit_above_the_cm_height_curve_without_overlapping(drawn):
    pushes = [
        PushSpec(body="chest", force_in_world_N=(150.0, 0.0, 0.0), start_s=0.5, duration_s=0.1),
        PushSpec(body="abdomen", force_in_world_N=(0.0, -150.0, 0.0), start_s=0.6, duration_s=0.1),
        PushSpec(body="chest", force_in_world_N=(106.0, 106.0, 0.0), start_s=0.7, duration_s=0.1),
        PushSpec(body="pelvis", force_in_world_N=(-100.0, 0.0, 0.0), start_s=2.5, duration_s=0.1),
        PushSpec(body="chest", force_in_world_N=(80.0, 30.0, 20.0), start_s=5.85, duration_s=0.1),
    ]
    _, axes = drawn(standing_series(pushes))
    ax = next(ax for title, ax in axes.items() if title == "CM height")
    labels = ax.texts
    assert len(labels) == len(pushes)
    boxes = [label.get_window_extent() for label in labels]
    data_area = ax.get_window_extent()
    for box in boxes:
        assert box.y0 >= data_area.y1  # above the curve's area, never on it
        assert data_area.x0 - 0.5 <= box.x0 and box.x1 <= data_area.x1 + 0.5
        assert not overlap(box, ax.title.get_window_extent())
    for a, b in combinations(boxes, 2):
        assert not overlap(a, b)
    assert len({round(box.y0) for box in boxes}) >= 2  # the three close ones took rows


@pytest.mark.e2e
def test_a_walks_paths_are_drawn_at_equal_aspect_with_the_legend_outside(server):
    from clients.sim.runner import run_scenario
    from clients.sim.scenario import load_scenario

    record = run_scenario(load_scenario("walk", duration_s=1.5), server.endpoint)
    figure = draw_walk_paths(record)
    try:
        figure.canvas.draw()
        (ax,) = figure.axes
        assert_top_view_holds_its_points(ax)
        assert not overlap(ax.get_legend().get_window_extent(), ax.get_window_extent())
    finally:
        plt.close(figure)
