"""The compiled soft joint limits against their specification, ``JointLimitSet.errors``.

``JointLimitSet.compiled()`` (``controller_server/core/joint_limits.cpp``) computes the limit
violation per DoF of Macchietto 2008, §6.2 in C++. Per built-in model, and for synthetic ball
limits with hand-built cones (irregular convex, reflex, none), on 1,200 seeded configurations
biased to the limits: inside, on, just past and far past each box; swings to a cone's boundary
± 1e-12 … 0.5 rad toward random directions, its edges and its face centres; twists at and past
their bounds and near half turns; the degenerate swing–twist cases (a half turn about an axis
⊥ the bone, and near one); swings near π; quaternions neither unit nor sign-normalised.

The two agree to 1e-12 (rad, or m), plus, on a ball joint, the rounding of a dot product
amplified by the two ill-conditioned steps of the specification (``rounding_allowance``: an
``acos`` near 1, and the twist near a half turn ⊥ the bone). That rounding depends on the BLAS
kernel numpy calls; the C++ sums in the order of this machine's (OpenBLAS on AVX-512), and
here they agree to ~1e-15 everywhere (``-s`` prints the worst); with plain sums they differ by
up to 1.5e-8, within the allowance. Bad values fail as in Python.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller_server.features.joint_limits import (
    BallJointLimit,
    JointLimitSet,
    RevoluteJointLimit,
    default_joint_limits,
)
from controller_server.features.swing_twist import SwingCone, compose, rotate
from controller_server.models import load_robot_model
from tests.controller_server.test_compiled_core import MODEL_NAMES, random_states
from tests.controller_server.test_joint_limits import (
    axis_angle,
    boundary_angle,
    perpendicular_basis,
)

CONFIGURATIONS = 1200
TOLERANCE = 1e-12  # rad (m for prismatic joints)
ROUNDING = 1e-15  # a few ulp of a dot product of unit vectors (rounding_allowance)
OFFSETS = (0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.05, 0.5)  # rad (m) past (or short of) a bound


def unit(vector) -> np.ndarray:
    vector = np.asarray(vector, dtype=float)
    return vector / np.linalg.norm(vector)


def signed_offset(rng: np.random.Generator) -> float:
    """Outward (> 0) or inward offset from a bound, mostly tiny or small."""
    return float(rng.choice((-1.0, 1.0)) * rng.choice(OFFSETS))


def box_coordinate(limit: RevoluteJointLimit, rng: np.random.Generator) -> float:
    """Inside, on a bound, or an offset in or out of it."""
    if rng.random() < 0.2:
        return float(rng.uniform(limit.lower, limit.upper))
    if rng.random() < 0.5:
        return limit.lower - signed_offset(rng)
    return limit.upper + signed_offset(rng)


def radial_directions(limit: BallJointLimit) -> list[np.ndarray]:
    """Unit vectors ⊥ the bone axis toward each edge ray and face centre of its cone."""
    a = limit.bone_axis_in_parent
    rays = [*limit.cone.edges_in_parent, *limit.cone.face_normals_in_parent]
    rays += [-n for n in limit.cone.face_normals_in_parent]
    radials = [r - (r @ a) * a for r in rays]
    return [unit(r) for r in radials if np.linalg.norm(r) > 1e-6]


def ball_quaternion(limit: BallJointLimit, rng: np.random.Generator) -> np.ndarray:
    """A quaternion ``[x, y, z, w]`` near the limit's boundaries and degenerate cases."""
    a = limit.bone_axis_in_parent
    e1, e2 = perpendicular_basis(a)
    low, high = limit.twist_lower_rad, limit.twist_upper_rad
    twist_choices = [
        rng.uniform(low, high),
        low - signed_offset(rng),
        high + signed_offset(rng),
        rng.uniform(-math.pi, math.pi),
        math.pi - float(rng.choice(OFFSETS)),
    ]
    twist_rad = float(twist_choices[rng.integers(len(twist_choices))])
    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    radial = math.cos(azimuth) * e1 + math.sin(azimuth) * e2
    kind = rng.integers(6)
    if kind == 0:  # any rotation
        quaternion = unit(rng.normal(size=4))
    elif kind in (1, 2):  # a swing to the cone's boundary ± an offset, toward a feature or not
        candidates = radial_directions(limit)
        if kind == 2 and candidates:
            radial = candidates[rng.integers(len(candidates))]
        if len(limit.cone.face_normals_in_parent):
            swing_rad = boundary_angle(limit.cone, a, radial) + signed_offset(rng)
        else:
            swing_rad = rng.uniform(0.0, math.pi)
        swing = axis_angle(np.cross(a, radial), swing_rad)
        quaternion = compose(swing, axis_angle(a, twist_rad))
    elif kind == 3:  # a pure twist
        quaternion = axis_angle(a, twist_rad)
    elif kind == 4:  # a half turn about an axis ⊥ a (degenerate swing), or near one
        quaternion = np.append(radial, 0.0)
        quaternion[3] = rng.choice((0.0, 1e-12, -1e-10, 1e-8, 1e-6))
        quaternion[:3] += rng.choice((0.0, 1e-12, 1e-10, 1e-8)) * a
    else:  # a swing near π (a' ≈ −a), then a twist
        swing = axis_angle(np.cross(a, radial), math.pi - float(rng.choice(OFFSETS)))
        quaternion = compose(swing, axis_angle(a, twist_rad))
    # Neither unit nor sign-normalised: both implementations normalise, q and −q agree.
    return quaternion * rng.choice((1.0, -1.0)) * rng.choice((1.0, 1.0, 0.5, 3.0))


def biased_configurations(robot_q: list[np.ndarray], limits, count: int, seed: int):
    """``count`` configurations: each limited coordinate redrawn near its limits."""
    rng = np.random.default_rng(seed)
    configurations = []
    for index in range(count):
        q = robot_q[index % len(robot_q)].copy()
        for limit in limits:
            if rng.random() < 0.3:
                continue  # keep the base configuration's value
            if isinstance(limit, RevoluteJointLimit):
                q[limit.idx_q] = box_coordinate(limit, rng)
            else:
                q[limit.idx_q : limit.idx_q + 4] = ball_quaternion(limit, rng)
        configurations.append(q)
    return configurations


def rounding_allowance(limit_set: JointLimitSet, q: np.ndarray, dof: int) -> float:
    """How much more than ``TOLERANCE`` the two may differ at ``dof`` (module docstring).

    Two steps of a ball joint's error are ill conditioned, so that a rounding ``δ`` of a dot
    product, which depends on the BLAS kernel, is amplified. The distance to a convex cone's
    edge ray, ``acos(e · d)``, moves by ``δ / e_axis``, and by at most ``√(2δ)`` (1.5e-8 rad
    for one ulp) as ``e_axis`` goes to 0. The twist, from ``(u · a, w) / ‖(u · a, w)‖``,
    moves by ``δ / ‖(u · a, w)‖`` near a half turn about an axis ⊥ ``a`` (eq. 6.4's
    singularity, where the swing–twist split is the identity below 1e-9).
    """
    limit = next(x for x in limit_set.limits if x.idx_v <= dof < x.idx_v + x.nv)
    if not isinstance(limit, BallJointLimit):
        return 0.0
    quaternion = unit(q[limit.idx_q : limit.idx_q + 4])
    axis_error = limit.cone.violation(rotate(quaternion, limit.bone_axis_in_parent))
    near_zero = math.sqrt(2.0 * ROUNDING)
    axis = min(ROUNDING / axis_error, near_zero) if axis_error > 0.0 else near_zero
    twist_norm = math.hypot(quaternion[:3] @ limit.bone_axis_in_parent, quaternion[3])
    return axis + ROUNDING / twist_norm


def assert_agreement(limit_set: JointLimitSet, configurations, label: str) -> None:
    """``errors(q)`` of both within the tolerance of the module docstring; prints the worst."""
    compiled = limit_set.compiled()
    worst, outside = 0.0, 0
    for q in configurations:
        expected = limit_set.errors(q)
        difference = np.abs(compiled.errors(q) - expected)
        worst = max(worst, float(difference.max(initial=0.0)))
        for dof in np.flatnonzero(difference > TOLERANCE).tolist():
            assert difference[dof] <= TOLERANCE + rounding_allowance(limit_set, q, dof), (
                label,
                q,
                dof,
            )
        outside += int(np.count_nonzero(expected))
    print(f"{label}: worst |compiled − python| {worst:.3g} over {len(configurations)} q")
    assert outside > len(configurations)  # many limits were past, not only inside


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_errors_match_the_python_on_1200_biased_configurations(name):
    robot = load_robot_model(name)
    limits = default_joint_limits(robot)
    bases = [q for q, _ in random_states(robot, 50)]  # root poses and other joints
    configurations = biased_configurations(bases, limits, CONFIGURATIONS, seed=11)
    assert_agreement(JointLimitSet(limits, robot.model.nv), configurations, name)


def cone(axis, azimuths_rad, tilts_rad, *, reflex: bool = False) -> SwingCone:
    """Faces ``n_i = −sin(t_i) a ± cos(t_i) r(ψ_i)``: a convex cone of half-angles ``t_i``
    about ``a``, or (reflex) the complement of one of half-angles ``t_i`` about ``−a``.
    """
    a = unit(axis)
    e1, e2 = perpendicular_basis(a)
    radial = np.outer(np.cos(azimuths_rad), e1) + np.outer(np.sin(azimuths_rad), e2)
    tilts = np.asarray(tilts_rad)[:, None]
    sign = -1.0 if reflex else 1.0
    return SwingCone(-np.sin(tilts) * a + sign * np.cos(tilts) * radial, reflex=reflex)


def synthetic_limits() -> list[BallJointLimit]:
    """Hand-built cones on tilted bone axes, with asymmetric twist intervals."""
    specifications = [  # bone axis, cone, twist interval (rad)
        ([0, 0, -1], cone([0, 0, -1], [0.3, 2.2, 4.4], [0.5, 0.9, 0.3]), (-0.2, 1.3)),
        ([1, 2, -3], cone([1, 2, -3], [0.0, 1.0, 2.9, 4.0], [1.2, 0.4, 1.0, 0.2]), (-1.0, 0.1)),
        (
            [0.3, -1, 0.1],
            cone([0.3, -1, 0.1], [0.1, 1.4, 2.6, 3.9, 5.2], [0.3, 0.8, 0.6, 1.1, 0.5]),
            (-3.0, 3.0),
        ),
        (
            [0, 1, 0],
            cone([0, 1, 0], [0.2, 1.9, 3.3, 5.0], [0.4, 1.0, 0.6, 0.3], reflex=True),
            (-0.5, 0.5),
        ),
        ([-1, 0.5, 0.5], cone([-1, 0.5, 0.5], [0, 2, 4], [1.4, 1.3, 1.5], reflex=True), (0.2, 2.5)),
        ([0.2, 0.2, 1], SwingCone(np.zeros((0, 3))), (-1.5, 0.7)),  # no swing limit
    ]
    return [
        BallJointLimit(
            name=f"synthetic_{index}",
            idx_q=1 + 4 * index,  # after one coordinate that no limit reads
            idx_v=3 * index,
            bone_axis_in_parent=np.array(axis, dtype=float),
            cone=swing_cone,
            twist_lower_rad=low,
            twist_upper_rad=high,
        )
        for index, (axis, swing_cone, (low, high)) in enumerate(specifications)
    ]


def test_errors_match_the_python_on_synthetic_cones():
    limits = synthetic_limits()
    nq, nv = 1 + 4 * len(limits), 3 * len(limits)
    bases = [np.append(0.0, np.tile([0.0, 0.0, 0.0, 1.0], len(limits)))]
    configurations = biased_configurations(bases, limits, CONFIGURATIONS, seed=5)
    assert all(q.shape == (nq,) for q in configurations)
    assert_agreement(JointLimitSet(limits, nv), configurations, "synthetic cones")


def thesis_humanoid_limits() -> tuple[JointLimitSet, BallJointLimit, np.ndarray]:
    """The thesis humanoid's limits, its first ball joint's limit, and its standing ``q``."""
    robot = load_robot_model("thesis_humanoid")
    limits = default_joint_limits(robot)
    ball = next(limit for limit in limits if isinstance(limit, BallJointLimit))
    return JointLimitSet(limits, robot.model.nv), ball, robot.standing_configuration.copy()


def test_the_compiled_limits_are_the_python_data():
    robot = load_robot_model("revolute_humanoid")
    limit_set = JointLimitSet([*default_joint_limits(robot)], robot.model.nv)
    compiled = limit_set.compiled()
    assert compiled.nv == robot.model.nv and compiled.min_nq <= robot.model.nq
    assert [(box.name, box.idx_q, box.idx_v, box.lower, box.upper) for box in compiled.boxes] == [
        (limit.name, limit.idx_q, limit.idx_v, limit.lower, limit.upper)
        for limit in limit_set.limits
    ]
    synthetic = JointLimitSet(synthetic_limits(), 18)
    for ball, limit in zip(synthetic.compiled().balls, synthetic.limits, strict=True):
        assert (ball.name, ball.idx_q, ball.idx_v, ball.reflex) == (
            limit.name,
            limit.idx_q,
            limit.idx_v,
            limit.cone.reflex,
        )
        np.testing.assert_array_equal(ball.bone_axis_in_parent, limit.bone_axis_in_parent)
        np.testing.assert_array_equal(
            ball.face_normals_in_parent, limit.cone.face_normals_in_parent
        )
        np.testing.assert_array_equal(ball.edges_in_parent, limit.cone.edges_in_parent)
        assert (ball.twist_lower_rad, ball.twist_upper_rad) == (
            limit.twist_lower_rad,
            limit.twist_upper_rad,
        )


def test_errors_are_a_fresh_array_of_nv():
    limit_set, ball, q = thesis_humanoid_limits()
    compiled = limit_set.compiled()
    q[ball.idx_q : ball.idx_q + 4] = axis_angle(ball.bone_axis_in_parent, 3.0)  # a twist past
    first = compiled.errors(q)
    assert first.shape == (limit_set.nv,) and first.dtype == np.float64
    assert first.flags.c_contiguous and first.flags.writeable
    kept = first.copy()
    second = compiled.errors(q.copy())
    assert not np.shares_memory(first, second)
    np.testing.assert_array_equal(first, kept)
    np.testing.assert_array_equal(second, limit_set.errors(q))
    assert np.count_nonzero(second) == 3


def test_bad_values_fail_as_in_python():
    """NaN in a box coordinate is NaN on its DoF; a ball quaternion that is not finite or is 0
    raises (Python: ``ValueError``, and ``ZeroDivisionError`` for 0 from ``_within``'s
    division; compiled: ``ValueError`` naming the joint); one too large to square is a
    direction like any other; the root's coordinates are not read.
    """
    limit_set, ball, standing = thesis_humanoid_limits()
    compiled = limit_set.compiled()
    boxes = JointLimitSet(default_joint_limits(load_robot_model("revolute_humanoid")), 28)
    q = load_robot_model("revolute_humanoid").standing_configuration.copy()
    knee = next(limit for limit in boxes.limits if limit.name == "right_knee")
    q[knee.idx_q] = np.nan
    np.testing.assert_array_equal(boxes.compiled().errors(q), boxes.errors(q))
    assert np.isnan(boxes.errors(q)[knee.idx_v])
    for value, python_error in (
        (np.nan, ValueError),
        (np.inf, ValueError),
        (0.0, (ZeroDivisionError, ValueError)),
    ):
        q = standing.copy()
        q[ball.idx_q : ball.idx_q + 4] = value
        with pytest.raises(python_error), np.errstate(invalid="ignore", over="ignore"):
            limit_set.errors(q)
        with pytest.raises(ValueError, match=f"joint '{ball.name}'"):
            compiled.errors(q)
    for quaternion in ([0.0, 0.0, 0.0, 1e200], [0.0, 0.0, 0.0, 1e-13]):
        q = standing.copy()
        q[ball.idx_q : ball.idx_q + 4] = quaternion
        with np.errstate(over="ignore"):
            np.testing.assert_array_equal(compiled.errors(q), limit_set.errors(q))
    q = standing.copy()
    q[:7] = np.nan
    np.testing.assert_array_equal(compiled.errors(q), limit_set.errors(q))
    with pytest.raises(IndexError):
        limit_set.errors(standing[:-1])
    with pytest.raises(IndexError):
        compiled.errors(standing[:-1])


def test_malformed_limits_are_refused_naming_the_joint():
    from controller_server.compiled import load_core

    core = load_core()
    good = synthetic_limits()[0]

    def ball(**changes):
        fields = {
            "name": "elbow",
            "idx_q": 0,
            "idx_v": 0,
            "bone_axis_in_parent": good.bone_axis_in_parent,
            "face_normals_in_parent": good.cone.face_normals_in_parent,
            "edges_in_parent": good.cone.edges_in_parent,
            "reflex": False,
            "twist_lower_rad": -1.0,
            "twist_upper_rad": 1.0,
        }
        return core.BallLimit(**(fields | changes))

    core.JointLimits(3, [], [ball()])
    for changes in (
        {"idx_v": 1},
        {"idx_q": -1},
        {"bone_axis_in_parent": np.zeros(3)},
        {"face_normals_in_parent": good.cone.face_normals_in_parent[:2]},
        {"edges_in_parent": np.zeros((0, 3))},
        {"reflex": True},  # a reflex cone has no edges
        {"twist_lower_rad": 1.0},
        {"twist_upper_rad": np.nan},
    ):
        with pytest.raises(ValueError, match="joint 'elbow'"):
            core.JointLimits(3, [], [ball(**changes)])
    box = core.BoxLimit(name="knee", idx_q=3, idx_v=3, lower=-1.0, upper=1.0)
    with pytest.raises(ValueError, match="joint 'knee'"):
        core.JointLimits(3, [box], [])
