"""Support polygon geometry and the COP-admissible linear momentum rate."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from controller_server.balance_points import (
    MAX_MARGIN_FRACTION,
    admissible_cop_polygon,
    closest_point_in_polygon,
    polygon_width,
    shrink_polygon,
    support_polygon,
)
from controller_server.features import admissible_linear_momentum_rate

SQUARE = np.array([[0.1, -0.1], [0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1]])  # counter-clockwise
GRAVITY = 9.81


def distance_to_boundary(point: np.ndarray, polygon: np.ndarray) -> float:
    starts, ends = polygon, np.roll(polygon, -1, axis=0)
    segments = ends - starts
    t = np.clip(np.einsum("ij,ij->i", point - starts, segments) / (segments**2).sum(1), 0, 1)
    return float(np.linalg.norm(starts + t[:, None] * segments - point, axis=1).min())


def inside(point: np.ndarray, polygon: np.ndarray, tolerance: float = 1e-12) -> bool:
    edges = np.roll(polygon, -1, axis=0) - polygon
    cross = edges[:, 0] * (point[1] - polygon[:, 1]) - edges[:, 1] * (point[0] - polygon[:, 0])
    return bool(np.all(cross >= -tolerance))


def test_shrinking_a_square_moves_every_edge_in_by_the_margin():
    shrunk = shrink_polygon(SQUARE, 0.02)
    np.testing.assert_allclose(shrunk, SQUARE * 0.8, atol=1e-15)


def test_a_margin_larger_than_the_polygon_collapses_it_to_its_centre():
    np.testing.assert_allclose(shrink_polygon(SQUARE + 1.0, 0.2), [[1.0, 1.0]])


polygons = st.lists(
    st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)), min_size=3, max_size=12
).map(lambda points: support_polygon(np.column_stack([np.array(points), np.zeros(len(points))])))


@settings(max_examples=200, deadline=None)
@given(polygons, st.floats(0.0, 0.05), st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)))
def test_shrunk_polygon_and_closest_point_properties(polygon, margin, point):
    area = 0.5 * np.sum(
        polygon[:, 0] * np.roll(polygon[:, 1], -1) - np.roll(polygon[:, 0], -1) * polygon[:, 1]
    )
    assume(len(polygon) >= 3 and area > 1e-4)  # real feet, not slivers
    point = np.array(point)
    shrunk = shrink_polygon(polygon, margin)
    if len(shrunk) >= 3:
        # Every shrunk vertex is inside the original, exactly `margin` from its nearest edge.
        for vertex in shrunk:
            assert inside(vertex, polygon, 1e-12)
            assert distance_to_boundary(vertex, polygon) >= margin - 1e-9
    closest = closest_point_in_polygon(point, polygon)
    if inside(point, polygon, 0.0):
        np.testing.assert_array_equal(closest, point)
    else:
        # On the boundary, and no boundary point is nearer.
        assert distance_to_boundary(closest, polygon) < 1e-12
        assert np.linalg.norm(closest - point) <= distance_to_boundary(point, polygon) + 1e-12


@pytest.mark.parametrize(
    ("desired_xy", "expected_cop_xy"),
    [
        ((-5.0, 0.0), (0.06 + 0.94 * 5.0 / (65.0 * GRAVITY), 0.0)),  # admissible: unchanged
        ((-2000.0, 0.0), (0.08, 0.0)),  # COP would leave the front edge: held at the margin
        ((3000.0, -3000.0), (-0.08, 0.08)),  # and at a corner
    ],
)
def test_admissible_rate_keeps_the_cop_it_needs_inside_the_shrunk_polygon(
    desired_xy, expected_cop_xy
):
    """p = c − (c_z − h) L̇ / (m g) (angular momentum held) must lie in the polygon."""
    mass, com = 65.0, np.array([0.06, 0.0, 0.94])
    desired = np.array([*desired_xy, np.nan])
    admissible = admissible_linear_momentum_rate(
        desired, mass, com, shrink_polygon(SQUARE, 0.02), 0.0, GRAVITY
    )
    cop = com[:2] - com[2] * admissible[:2] / (mass * GRAVITY)
    np.testing.assert_allclose(cop, expected_cop_xy, atol=1e-12)
    assert np.isnan(admissible[2])


def test_turned_feet_side_by_side_shrink_to_a_finite_polygon_inside_the_feet():
    """Toe and heel lines of two aligned feet are collinear up to round-off at any yaw."""
    foot = np.array([[0.189, 0.047], [0.189, -0.047], [-0.063, 0.047], [-0.063, -0.047]])
    for yaw in np.linspace(0.0, 2.0 * np.pi, 2001):
        rotation = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
        offset = np.array([0.0, 0.0875])
        points = np.vstack([foot + offset, foot - offset]) @ rotation.T
        polygon = support_polygon(np.column_stack([points, np.zeros(8)]))
        assert len(polygon) == 4, (yaw, polygon)
        shrunk = shrink_polygon(polygon, 0.02)
        assert shrunk.shape == (4, 2) and np.all(np.isfinite(shrunk)), (yaw, shrunk)
        for vertex in shrunk:
            assert inside(vertex, polygon, 1e-12)
            assert distance_to_boundary(vertex, polygon) == pytest.approx(0.02, abs=1e-9)


HEELS_AND_TOES_UP_TO_ROUNDING = np.array(
    [
        [-0.06999706209641562, 0.045000000000000075],
        [-0.0699970620964156, -0.15500000000000003],
        [-0.0699970620964156, -0.04500000000000002],
        [-0.0699970620964156, 0.15500000000000008],
        [0.1700029216864892, 0.04499999999999999],
        [0.17000292168648923, -0.15500000000000003],
        [0.17000292168648923, -0.04500000000000002],
        [0.17000292168648923, 0.155],
    ]
)
"""The sole corners of the revolute humanoid standing (its kinematics at 26 ms of the walk):
heels and toes on lines parallel to y, their x equal up to 2e-17."""


def polygon_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_the_hull_keeps_every_corner_when_heels_are_collinear_up_to_rounding():
    """Sorted by x, the heels come in the order their rounding gives, not along the heel line:
    a chain that dropped nearly collinear points as it went lost the outer corner of a heel
    (a triangle of 24 × 11 cm), on half the ticks of a standing robot."""
    polygon = support_polygon(np.column_stack([HEELS_AND_TOES_UP_TO_ROUNDING, np.zeros(8)]))
    assert len(polygon) == 4, polygon
    np.testing.assert_allclose(polygon_area(polygon), 0.24 * 0.31, rtol=1e-6)
    for point in HEELS_AND_TOES_UP_TO_ROUNDING:
        assert inside(point, polygon, 1e-15), point


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.integers(-4, 4), min_size=16, max_size=16),
    st.floats(0.0, 2.0 * np.pi),
    st.permutations(range(8)),
)
def test_the_hull_of_two_feet_holds_them_whatever_their_rounding(ulps, yaw, order):
    """Two soles side by side, turned by any yaw, every coordinate a few ulps off: the hull
    holds every point and has the two soles' outline (area) and four corners."""
    foot = np.array([[0.17, 0.045], [0.17, 0.155], [-0.07, 0.045], [-0.07, 0.155]])
    points = np.vstack([foot, foot * [1.0, -1.0]])
    rotation = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    points = points @ rotation.T
    points += np.spacing(np.abs(points) + 1e-300) * np.reshape(ulps, (8, 2))
    points = points[list(order)]
    polygon = support_polygon(np.column_stack([points, np.zeros(8)]))
    assert len(polygon) == 4, polygon
    np.testing.assert_allclose(polygon_area(polygon), 0.24 * 0.31, rtol=1e-9)
    for point in points:
        assert inside(point, polygon, 1e-12), point


def test_collinear_points_in_any_order_give_the_segments_ends():
    line = np.array([[0.0, 0.1], [1e-17, -0.2], [0.0, 0.3], [-1e-17, 0.0]])
    polygon = support_polygon(np.column_stack([line, np.zeros(4)]))
    assert len(polygon) == 2, polygon
    assert sorted(polygon[:, 1].tolist()) == [-0.2, 0.3]


def test_degenerate_polygons_collapse_to_a_point():
    np.testing.assert_allclose(shrink_polygon(np.array([[0.1, 0.2]]), 0.0), [[0.1, 0.2]])
    segment = np.array([[0.0, 0.0], [0.2, 0.0]])
    np.testing.assert_allclose(shrink_polygon(segment, 0.02), [[0.1, 0.0]])


def test_zero_gravity_leaves_the_rate_alone():
    desired = np.array([10.0, -5.0, np.nan])
    out = admissible_linear_momentum_rate(
        desired, 65.0, np.array([0.0, 0.0, 0.9]), SQUARE, 0.0, gravity=0.0
    )
    np.testing.assert_array_equal(out, desired)


def test_the_rate_stays_within_the_inscribed_friction_pyramid():
    mu, mass = 0.03, 65.0
    out = admissible_linear_momentum_rate(
        np.array([-400.0, 300.0, np.nan]),
        mass,
        np.array([0.0, 0.0, 0.9]),
        SQUARE,
        0.0,
        GRAVITY,
        friction_coefficient=mu,
    )
    grip = mu / np.sqrt(2.0) * mass * GRAVITY
    np.testing.assert_allclose(out[:2], [-grip, grip])


NARROW_SOLE = np.array([[-0.07, 0.085], [0.13, 0.085], [0.13, 0.115], [-0.07, 0.115]])
"""One 20 cm × 3 cm sole, its centre line 10 cm left of the origin (counter-clockwise)."""


def test_a_polygon_width_is_its_smallest_extent_across():
    assert polygon_width(NARROW_SOLE) == pytest.approx(0.03)
    assert polygon_width(SQUARE) == pytest.approx(0.2)
    triangle = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert polygon_width(triangle) == pytest.approx(np.sqrt(0.5))
    assert polygon_width(np.array([[0.0, 0.0], [1.0, 0.0]])) == 0.0


def test_a_wide_support_is_shrunk_by_the_whole_margin():
    np.testing.assert_allclose(admissible_cop_polygon(SQUARE, 0.02), shrink_polygon(SQUARE, 0.02))


def test_a_narrow_sole_keeps_a_strip_where_a_fixed_margin_would_leave_its_centre():
    """A 2 cm margin on a 3 cm sole: shrink_polygon collapses it to one point (issue 31)."""
    assert len(shrink_polygon(NARROW_SOLE, 0.02)) == 1
    admissible = admissible_cop_polygon(NARROW_SOLE, 0.02)
    margin = MAX_MARGIN_FRACTION * 0.03
    np.testing.assert_allclose(admissible, shrink_polygon(NARROW_SOLE, margin), atol=1e-15)
    assert admissible[:, 1].min() == pytest.approx(0.085 + margin)
    assert admissible[:, 1].max() == pytest.approx(0.115 - margin)


def test_on_a_narrow_sole_the_admissible_rate_still_pulls_the_cm_back_toward_the_sole():
    """The CM 5 mm beyond the sole's centre line, drifting out: the rate asked pulls it back
    (the COP beyond the CM), where the collapsed polygon asked the COP at the centre line,
    that is a rate pushing the CM further out."""
    mass, com = 52.0, np.array([0.03, 0.105, 0.93])
    desired = np.array([0.0, -300.0, np.nan])  # toward the sole's centre, hard
    collapsed = admissible_linear_momentum_rate(
        desired, mass, com, shrink_polygon(NARROW_SOLE, 0.02), 0.0, GRAVITY
    )
    assert collapsed[1] > 0.0  # the COP at y = 0.1: the CM is pushed further out
    rate = admissible_linear_momentum_rate(
        desired, mass, com, admissible_cop_polygon(NARROW_SOLE, 0.02), 0.0, GRAVITY
    )
    lever = com[2] / (mass * GRAVITY)
    assert rate[1] == pytest.approx((com[1] - (0.115 - MAX_MARGIN_FRACTION * 0.03)) / lever)
    assert rate[1] < 0.0
