"""Soft joint limits (Macchietto 2008, §6.2): swing–twist, swing cones, gains, built-in models."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller_server.features.joint_limits import (
    BallJointLimit,
    JointLimitSet,
    RevoluteJointLimit,
    default_joint_limits,
    joint_limit_errors,
    soft_limit_gains,
)
from controller_server.features.swing_twist import (
    SwingCone,
    compose,
    rotate,
    swing_twist,
    twist_angle,
)
from controller_server.models import load_robot_model

PROPERTY = settings(deadline=None, max_examples=300)
FEW = settings(deadline=None, max_examples=100)
HALF_ANGLES_RAD = [0.2, 0.6, 1.0, 1.4, 1.55, math.pi / 2, 1.8, 2.4, 2.6, 3.0]

unit = st.floats(-1.0, 1.0, allow_nan=False)


def unit_vectors(size: int) -> st.SearchStrategy[np.ndarray]:
    return (
        st.tuples(*[unit] * size)
        .map(lambda xs: np.array(xs))
        .filter(lambda x: np.linalg.norm(x) > 0.1)
        .map(lambda x: x / np.linalg.norm(x))
    )


def perpendicular_basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Any right-handed ``(e1, e2)`` ⊥ ``axis``, built independently of the module's choice."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = helper - (helper @ axis) * axis
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def axis_angle(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    return np.append(math.sin(angle_rad / 2) * axis, math.cos(angle_rad / 2))


def same_rotation(p: np.ndarray, q: np.ndarray, tol: float = 1e-9) -> bool:
    return min(np.linalg.norm(p - q), np.linalg.norm(p + q)) < tol


def meridian(axis: np.ndarray, radial: np.ndarray, theta_rad: float) -> np.ndarray:
    """Direction at polar angle ``theta`` from ``axis`` toward the unit ``radial`` ⊥ ``axis``."""
    return math.cos(theta_rad) * axis + math.sin(theta_rad) * radial


def boundary_angle(cone: SwingCone, axis: np.ndarray, radial: np.ndarray) -> float:
    """Polar angle where the meridian toward ``radial`` leaves the cone, from the normals alone.

    Face ``i`` is crossed where ``cos θ (a·n) + sin θ (u·n) = 0``; a convex cone is left at
    the first crossing, a reflex one (a union of half-spaces) at the last.
    """
    normals = cone.face_normals_in_parent
    crossings = np.arctan2(-(normals @ axis), normals @ radial)
    return float(crossings.max() if cone.reflex else crossings.min())


# Swing–twist decomposition (eq. 6.4)


@PROPERTY
@given(quaternion=unit_vectors(4), axis=unit_vectors(3), scale=st.floats(0.1, 10.0))
def test_swing_twist_round_trips_and_has_the_thesis_properties(quaternion, axis, scale):
    swing, twist = swing_twist(scale * quaternion, axis)
    assert same_rotation(compose(swing, twist), quaternion)
    assert np.linalg.norm(np.cross(twist[:3], axis)) < 1e-9  # twist about a
    assert abs(swing[:3] @ axis) < 1e-9  # swing axis ⊥ a: the shortest arc
    moved_axis = rotate(quaternion, axis)
    np.testing.assert_allclose(rotate(swing, axis), moved_axis, atol=1e-9)
    swing_angle_rad = 2 * math.atan2(np.linalg.norm(swing[:3]), swing[3])
    assert swing_angle_rad == pytest.approx(math.acos(np.clip(axis @ moved_axis, -1, 1)), abs=1e-6)
    swing_of_negated, twist_of_negated = swing_twist(-quaternion, axis)
    assert same_rotation(swing_of_negated, swing)
    assert same_rotation(twist_of_negated, twist)


@PROPERTY
@given(
    axis=unit_vectors(3),
    swing_direction_rad=st.floats(-math.pi, math.pi),
    swing_rad=st.floats(0.0, math.pi - 1e-6) | st.sampled_from([0.0, 1e-12, math.pi - 1e-6]),
    twist_rad=st.floats(-math.pi + 1e-6, math.pi) | st.sampled_from([0.0, math.pi]),
)
def test_swing_twist_recovers_its_factors(axis, swing_direction_rad, swing_rad, twist_rad):
    e1, e2 = perpendicular_basis(axis)
    swing_axis = math.cos(swing_direction_rad) * e1 + math.sin(swing_direction_rad) * e2
    swing = axis_angle(swing_axis, swing_rad)
    twist = axis_angle(axis, twist_rad)
    swing_found, twist_found = swing_twist(compose(swing, twist), axis)
    assert same_rotation(swing_found, swing, 1e-6)
    difference_rad = twist_angle(twist_found, axis) - twist_rad
    assert abs(math.remainder(difference_rad, 2 * math.pi)) < 1e-6  # ±π are the same twist


@pytest.mark.parametrize("twist_rad", [0.0, 0.7, -2.0])
def test_swing_twist_degenerate_cases(twist_rad):
    axis = np.array([0.0, 0.0, 1.0])
    # a' = a: identity swing.
    swing, twist = swing_twist(axis_angle(axis, twist_rad), axis)
    assert same_rotation(swing, np.array([0.0, 0.0, 0.0, 1.0]))
    assert twist_angle(twist, axis) == pytest.approx(twist_rad)
    # a' = −a: a half-turn swing about an axis ⊥ a, same answer every time.
    quaternion = compose(
        axis_angle(np.array([1.0, 1.0, 0.0]), math.pi), axis_angle(axis, twist_rad)
    )
    swing, twist = swing_twist(quaternion, axis)
    assert same_rotation(compose(swing, twist), quaternion)
    assert abs(swing[:3] @ axis) < 1e-9 and abs(swing[3]) < 1e-9
    np.testing.assert_allclose(rotate(swing, axis), -axis, atol=1e-9)
    np.testing.assert_array_equal(swing_twist(quaternion, axis)[0], swing)


def test_twist_angle_range_and_bad_inputs():
    axis = np.array([0.0, 1.0, 0.0])
    assert twist_angle(axis_angle(axis, math.pi), axis) == math.pi
    assert twist_angle(-axis_angle(axis, math.pi), axis) == math.pi
    assert twist_angle(axis_angle(-axis, 0.5), axis) == pytest.approx(-0.5)
    with pytest.raises(ValueError, match="quaternion"):
        swing_twist(np.zeros(4), axis)
    with pytest.raises(ValueError, match="axis"):
        swing_twist(np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3))


# Swing cone and e_axis


@FEW
@given(
    axis=unit_vectors(3),
    half_angle_rad=st.sampled_from(HALF_ANGLES_RAD),
    sides=st.integers(3, 12),
    azimuth_rad=st.floats(-math.pi, math.pi),
)
def test_violation_is_zero_inside_and_strictly_increasing_outside(
    axis, half_angle_rad, sides, azimuth_rad
):
    cone = SwingCone.regular(axis, half_angle_rad, sides)
    e1, e2 = perpendicular_basis(axis)
    radial = math.cos(azimuth_rad) * e1 + math.sin(azimuth_rad) * e2
    limit_rad = boundary_angle(cone, axis, radial)
    assert limit_rad <= half_angle_rad + 1e-9  # inscribed: never looser than the circle
    thetas = np.linspace(0.0, math.pi - 1e-3, 121)
    inside = thetas < limit_rad - 1e-9
    outside = thetas > limit_rad + 1e-9
    errors = np.array([cone.violation(meridian(axis, radial, t)) for t in thetas])
    contained = np.array([cone.contains(meridian(axis, radial, t)) for t in thetas])
    assert np.all(errors[inside] == 0.0) and np.all(contained[inside])
    assert not np.any(contained[outside])
    assert np.all(errors[outside] > 0.0)
    assert np.all(np.diff(errors[outside]) > 0.0)
    # The crossing point is in the cone, so the distance to the cone is at most θ − θ_b.
    assert np.all(errors[outside] <= thetas[outside] - limit_rad + 1e-9)


@FEW
@given(
    axis=unit_vectors(3),
    half_angle_rad=st.sampled_from(HALF_ANGLES_RAD),
    sides=st.integers(3, 12),
    offset_rad=st.floats(1e-6, math.pi),
)
def test_violation_equals_angle_past_boundary_at_edges_and_face_centres(
    axis, half_angle_rad, sides, offset_rad
):
    cone = SwingCone.regular(axis, half_angle_rad, sides)
    if half_angle_rad == math.pi / 2:  # a half-space: the same at every azimuth
        radials = [perpendicular_basis(axis)[0]]
        cases = [(r, half_angle_rad) for r in radials]
    elif cone.reflex:  # faces tangent to the circle: the boundary is the circle at face centres
        perpendicular = cone.face_normals_in_parent - np.outer(
            cone.face_normals_in_parent @ axis, axis
        )
        cases = [(-p / np.linalg.norm(p), half_angle_rad) for p in perpendicular]
    else:  # edges on the circle; face centres inside it
        face_rad = math.atan(math.tan(half_angle_rad) * math.cos(math.pi / sides))
        edges = cone.edges_in_parent - np.outer(cone.edges_in_parent @ axis, axis)
        faces = cone.face_normals_in_parent - np.outer(cone.face_normals_in_parent @ axis, axis)
        cases = [(e / np.linalg.norm(e), half_angle_rad) for e in edges]
        if offset_rad <= math.pi / 2:
            cases += [(f / np.linalg.norm(f), face_rad) for f in faces]
    for radial, limit_rad in cases:
        theta_rad = min(limit_rad + offset_rad, math.pi)
        assert cone.violation(meridian(axis, radial, theta_rad)) == pytest.approx(
            theta_rad - limit_rad, abs=1e-9
        )


def boundary_samples(cone: SwingCone, axis: np.ndarray, per_face: int) -> np.ndarray:
    """Points along the cone's boundary arcs, from corners found by brute force."""
    normals = cone.face_normals_in_parent
    corners = np.cross(normals, np.roll(normals, -1, axis=0))
    corners /= np.linalg.norm(corners, axis=1)[:, None]
    # Convex cone: corners on the axis side; reflex: corners of the forbidden cone around −a.
    corners *= np.sign(corners @ axis)[:, None] * (-1 if cone.reflex else 1)
    samples = []
    t = np.linspace(0.0, 1.0, per_face)[:, None]
    for start, end in zip(np.roll(corners, 1, axis=0), corners, strict=True):
        arc_rad = math.acos(np.clip(start @ end, -1, 1))
        slerp = np.sin((1 - t) * arc_rad) * start + np.sin(t * arc_rad) * end
        samples.append(slerp / math.sin(arc_rad))
    return np.concatenate(samples)


@FEW
@given(
    axis=unit_vectors(3),
    direction=unit_vectors(3),
    half_angle_rad=st.sampled_from([a for a in HALF_ANGLES_RAD if a != math.pi / 2]),
    sides=st.integers(3, 12),
)
def test_violation_is_the_angle_to_the_nearest_boundary_point(
    axis, direction, half_angle_rad, sides
):
    cone = SwingCone.regular(axis, half_angle_rad, sides)
    error_rad = cone.violation(direction)
    if cone.contains(direction):
        assert error_rad == 0.0
        return
    samples = boundary_samples(cone, axis, per_face=2001)
    angles_rad = np.arccos(np.clip(samples @ direction, -1, 1))
    # Samples are ≤ π / 2000 apart, so the nearest one is at most half that further.
    assert 0.0 < error_rad <= angles_rad.min() + 1e-9
    assert error_rad == pytest.approx(angles_rad.min(), abs=math.pi / 4000)


def test_cone_with_no_limit_and_bad_arguments():
    axis = np.array([0.0, 0.0, 1.0])
    unlimited = SwingCone.regular(axis, math.pi)
    assert unlimited.contains(-axis) and unlimited.violation(-axis) == 0.0
    with pytest.raises(ValueError, match="half_angle_rad"):
        SwingCone.regular(axis, 0.0)
    with pytest.raises(ValueError, match="sides"):
        SwingCone.regular(axis, 1.0, sides=2)
    with pytest.raises(ValueError, match="cyclic"):
        SwingCone(SwingCone.regular(axis, 1.0).face_normals_in_parent[[0, 2, 1, 3, 4, 5, 6, 7]])


# Twist and box errors, gains (eq. 6.5–6.6)


@PROPERTY
@given(
    twist_rad=st.floats(-math.pi + 1e-9, math.pi),
    lower_rad=st.floats(-3.0, 0.0),
    width_rad=st.floats(0.01, 3.0),
    axis=unit_vectors(3),
)
def test_twist_error_is_the_distance_outside_the_interval(twist_rad, lower_rad, width_rad, axis):
    upper_rad = lower_rad + width_rad
    limit = BallJointLimit("j", 0, 0, axis, SwingCone.regular(axis, math.pi), lower_rad, upper_rad)
    expected = max(lower_rad - twist_rad, 0.0, twist_rad - upper_rad)
    assert limit.error(axis_angle(axis, twist_rad)) == pytest.approx(expected, abs=1e-9)
    if lower_rad <= twist_rad <= upper_rad:
        assert limit.error(axis_angle(axis, twist_rad)) <= 1e-12
    further_rad = twist_rad + 0.01 if twist_rad > upper_rad else twist_rad - 0.01
    if not lower_rad <= twist_rad <= upper_rad and abs(further_rad) < math.pi:
        assert limit.error(axis_angle(axis, further_rad)) > limit.error(axis_angle(axis, twist_rad))


def test_revolute_box_errors_and_error_vector():
    limits = (
        RevoluteJointLimit("knee", 7, 6, 0.0, 2.4),
        RevoluteJointLimit("slide", 8, 7, -0.1, 0.1),
    )
    assert limits[0].error(np.array([0.0] * 7 + [1.0, 0.0])) == 0.0
    errors = joint_limit_errors(limits, np.array([0.0] * 7 + [-0.3, 0.25]), nv=8)
    np.testing.assert_allclose(errors, [0, 0, 0, 0, 0, 0, 0.3, 0.15])


@PROPERTY
@given(seed=st.integers(0, 2**32 - 1), nv=st.integers(1, 50))
def test_soft_limit_gains_are_eq_6_5_and_6_6(seed, nv):
    rng = np.random.default_rng(seed)
    errors = rng.uniform(0.0, 2.0, nv) * (rng.random(nv) < 0.5)
    k_s, k_d, l_s, l_d = rng.uniform(0.0, 100.0, 4)
    stiffness, damping = soft_limit_gains(k_s, k_d, l_s, l_d, errors)
    np.testing.assert_allclose(stiffness, k_s + l_s * errors)
    np.testing.assert_allclose(damping, k_d + l_d * errors)
    per_dof = rng.uniform(0.0, 100.0, nv)
    stiffness, _ = soft_limit_gains(per_dof, k_d, l_s, l_d, errors)
    np.testing.assert_allclose(stiffness, per_dof + l_s * errors)
    assert stiffness.shape == damping.shape == (nv,)


# Built-in models


@pytest.mark.parametrize("name", ["thesis_humanoid", "revolute_humanoid", "dino_biped"])
def test_default_limits_cover_every_joint_and_hold_at_neutral(name):
    robot = load_robot_model(name)
    limits = default_joint_limits(robot)
    assert [limit.name for limit in limits] == [joint.name for joint in robot.joints]
    covered = sorted(i for limit in limits for i in range(limit.idx_v, limit.idx_v + limit.nv))
    assert covered == list(range(6, robot.model.nv))
    errors = joint_limit_errors(limits, pin.neutral(robot.model), robot.model.nv)
    np.testing.assert_array_equal(errors, np.zeros(robot.model.nv))


@pytest.mark.parametrize(
    ("name", "joint"),
    [
        ("thesis_humanoid", "left_knee"),
        ("thesis_humanoid", "right_elbow"),
        ("dino_biped", "left_knee"),
    ],
)
def test_ball_joint_beyond_its_limit_raises_the_error_on_its_dofs(name, joint):
    robot = load_robot_model(name)
    limits = {limit.name: limit for limit in default_joint_limits(robot)}
    limit = limits[joint]
    swing_limit_rad = robot.ball_swing_limit[joint]
    perpendicular = np.cross(limit.bone_axis_in_parent, [0.3, 1.0, 0.2])
    q = pin.neutral(robot.model)
    dofs = slice(limit.idx_v, limit.idx_v + 3)
    q[limit.idx_q : limit.idx_q + 4] = axis_angle(perpendicular, swing_limit_rad - 0.2)
    np.testing.assert_array_equal(joint_limit_errors(limits.values(), q, robot.model.nv), 0.0)
    q[limit.idx_q : limit.idx_q + 4] = axis_angle(perpendicular, swing_limit_rad + 0.3)
    errors = joint_limit_errors(limits.values(), q, robot.model.nv)
    moved_axis = rotate(q[limit.idx_q : limit.idx_q + 4], limit.bone_axis_in_parent)
    radial = moved_axis - (moved_axis @ limit.bone_axis_in_parent) * limit.bone_axis_in_parent
    radial /= np.linalg.norm(radial)
    past_boundary_rad = (
        swing_limit_rad + 0.3 - boundary_angle(limit.cone, limit.bone_axis_in_parent, radial)
    )
    assert np.all(errors[dofs] > 0.0) and np.all(errors[dofs] <= past_boundary_rad + 1e-9)
    assert np.count_nonzero(errors) == 3
    # A pure twist past ±min(swing, π/2) is an error of exactly the excess.
    q[limit.idx_q : limit.idx_q + 4] = axis_angle(limit.bone_axis_in_parent, -2.0)
    errors = joint_limit_errors(limits.values(), q, robot.model.nv)
    np.testing.assert_allclose(errors[dofs], 2.0 - min(swing_limit_rad, math.pi / 2))


def test_revolute_knee_beyond_its_limit():
    robot = load_robot_model("revolute_humanoid")
    limits = default_joint_limits(robot)
    knee = next(limit for limit in limits if limit.name == "right_knee")
    q = pin.neutral(robot.model)
    q[knee.idx_q] = knee.upper + 0.25
    errors = joint_limit_errors(limits, q, robot.model.nv)
    assert errors[knee.idx_v] == pytest.approx(0.25)
    assert np.count_nonzero(errors) == 1


@pytest.mark.parametrize("name", ["thesis_humanoid", "revolute_humanoid", "dino_biped"])
def test_the_vectorized_screen_agrees_with_each_joints_own_error(name):
    """JointLimitSet screens all joints at once; per joint, the error must be the joint's own."""
    robot = load_robot_model(name)
    limits = default_joint_limits(robot)
    limit_set = JointLimitSet(limits, robot.model.nv)
    rng = np.random.default_rng(7)
    outside = 0
    for _ in range(300):  # random configurations (seeded), many of them past some limit
        q = pin.neutral(robot.model)
        for limit in limits:
            if isinstance(limit, BallJointLimit):
                quaternion = rng.normal(size=4)
                q[limit.idx_q : limit.idx_q + 4] = quaternion / np.linalg.norm(quaternion)
            else:
                q[limit.idx_q] = rng.uniform(-2.5, 2.5)
        expected = np.zeros(robot.model.nv)
        for limit in limits:
            expected[limit.idx_v : limit.idx_v + limit.nv] = limit.error(q)
        np.testing.assert_array_equal(limit_set.errors(q), expected)
        outside += int(np.count_nonzero(expected) > 0)
    assert outside > 100  # the screen was exercised on both sides
