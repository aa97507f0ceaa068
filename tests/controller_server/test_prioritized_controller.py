"""The prioritized controller (de Lasa 2010) on seeded states of every built-in model."""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controller_server.controllers import ControlInput, create_controller
from controller_server.controllers.prioritized import friction_cone_basis
from controller_server.controllers.prioritized_layout import (
    LIMIT_ACCELERATION_ACTIVE,
    LayoutIndex,
    PrioritizedLayout,
)
from controller_server.dynamics import compute_dynamics_terms
from controller_server.errors import InvalidParams
from controller_server.features.setpoint import target_acceleration
from controller_server.models import BUILTIN_MODELS, load_robot_model

MODEL_NAMES = tuple(BUILTIN_MODELS)
TABLE_1 = {
    "priority_com_height": 2,
    "priority_angular_momentum": 3,
    "priority_pose": 3,
    "weight_com": 1.0,
    "weight_angular_momentum": 1.0,
}
"""de Lasa's Table 1 order (the default puts the momentum and pose in one level)."""
CONFIGURATIONS = {
    "pose below the momentum": (
        {"priority_pose": 3},
        ("dynamics", "contact", "com", "angular_momentum", "trunk"),
        [
            {"weight_pose": 25.0},
            {"weight_com_height": 25.0},
            {"com_height": 0.8},
            {"torque_selection": "ones", "weight_torque": 3.0},
        ],
    ),
    "table 1": (
        TABLE_1,
        ("dynamics", "contact", "com", "com_height", "trunk"),
        [
            {"weight_pose": 25.0},
            {"weight_angular_momentum": 0.0},
            {"reference_angular_momentum": [5.0, -3.0, 1.0]},
            {"torque_selection": "ones", "weight_torque": 3.0},
        ],
    ),
}
"""Configuration → (parameters, objectives above the lowest level, changes to that level)."""


def near_standing_state(robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Standing pose with every joint turned by up to 0.2 rad, small random velocities."""
    rng = np.random.default_rng(seed)
    model = robot.model
    q = pin.neutral(model)
    q[:3] = robot.standing_position_base_in_world
    q = pin.integrate(model, q, np.concatenate([np.zeros(6), rng.uniform(-0.2, 0.2, model.nv - 6)]))
    return q, rng.normal(0.0, 0.3, model.nv)


def compute(robot, q, v, params=None, flags=None):
    controller = create_controller(
        "prioritized", robot, {"contact_distance": 1.0, **(params or {})}
    )
    flags = flags or (True,) * len(robot.contacts)
    return controller.compute(ControlInput(0.0, q, v, flags))


@pytest.fixture(scope="module", params=MODEL_NAMES)
def robot(request):
    return load_robot_model(request.param)


def check_physics(robot, output):
    """Dynamics residual, λ ≥ 0 / non-penetration, friction pyramid and torque limits."""
    diagnostics = output.diagnostics
    assert diagnostics["objective_residuals"]["dynamics"] < 1e-6
    assert diagnostics["prioritized"]["inequality_violation"] < 1e-7
    forces = output.contact_force_in_world
    assert np.all(forces[:, 2] >= -1e-7)
    mus = np.concatenate(
        [[c.friction_coefficient] * len(c.points_in_frame) for c in robot.contacts]
    )
    grip = mus / math.sqrt(2.0) * forces[:, 2] + 1e-6
    assert np.all(np.abs(forces[:, 0]) <= grip) and np.all(np.abs(forces[:, 1]) <= grip)
    assert np.all(np.abs(output.joint_torque) <= robot.torque_limit * (1 + 1e-9))
    # The returned q̈ is what τ and the contact forces produce (eq. 22).
    data = robot.model.createData()
    return data


@settings(
    max_examples=5,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(seed=st.integers(0, 2**31 - 1), configuration=st.sampled_from(sorted(CONFIGURATIONS)))
def test_lower_objectives_never_raise_higher_residuals(robot, seed, configuration):
    """Priority property: adding or re-weighting a level-3 objective leaves levels 0–2 alone."""
    params, higher, variants = CONFIGURATIONS[configuration]
    q, v = near_standing_state(robot, seed)
    base = compute(robot, q, v, params)
    check_physics(robot, base)
    before = base.diagnostics["objective_residuals"]
    for change in variants:
        if change.get("torque_selection") == "ones":
            change = {**change, "torque_selection": [1.0] * robot.nv_joints}
        output = compute(robot, q, v, {**params, **change})
        check_physics(robot, output)
        after = output.diagnostics["objective_residuals"]
        for name in higher:
            scale = max(1.0, before[name])
            assert abs(after[name] - before[name]) <= 1e-8 * scale, (name, change)


def test_returned_acceleration_is_what_the_torques_and_forces_produce(robot):
    q, v = near_standing_state(robot, 7)
    output = compute(robot, q, v)
    model, data = robot.model, robot.model.createData()
    counts = [len(c.points_in_frame) for c in robot.contacts]
    generalized = np.concatenate([np.zeros(6), output.joint_torque])
    pin.computeJointJacobians(model, data, q)
    pin.framesForwardKinematics(model, data, q)
    start = 0
    for contact, count in zip(robot.contacts, counts, strict=True):
        J = pin.getFrameJacobian(
            model, data, contact.frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        rotation = data.oMf[contact.frame_id].rotation
        for point, force in zip(
            contact.points_in_frame,
            output.contact_force_in_world[start : start + count],
            strict=True,
        ):
            offset = rotation @ point
            J_point = J[:3] - pin.skew(offset) @ J[3:]
            generalized += J_point.T @ force
        start += count
    # Pinocchio's own forward dynamics (ABA) with those generalized forces.
    expected = pin.aba(model, data, q, v, generalized)
    np.testing.assert_allclose(
        output.acceleration, expected, atol=1e-6 * (1 + np.abs(expected).max())
    )


def test_a_fighting_objective_degrades_only_itself_when_prioritized():
    """de Lasa §3.2: weighted objectives fight; prioritized, the lower one gives way.

    A rest pose bending the hips forward moves the CM off the feet, against
    `com`. With `pose` below `com` (Table 1), the CM objective is met as
    without the bad pose; with both in one level (a weighted combination,
    eq. 16) the CM objective is given up in part.
    """
    robot = load_robot_model("revolute_humanoid")
    q, v = near_standing_state(robot, 3)
    leaning = pin.neutral(robot.model)[7:]
    names = [j.name for j in robot.joints]
    for i, name in enumerate(names):
        if name.endswith("hip_pitch"):
            leaning[i] = -0.8
    assert np.any(leaning != 0.0), names
    reference = compute(robot, q, v, {"priority_pose": 3})
    prioritized = compute(
        robot,
        q,
        v,
        {"reference_joint_position": list(leaning), "weight_pose": 50.0, "priority_pose": 3},
    )
    weighted = compute(
        robot,
        q,
        v,
        {"reference_joint_position": list(leaning), "weight_pose": 50.0, "priority_pose": 2},
    )
    com = {
        key: out.diagnostics["objective_residuals"]["com"]
        for key, out in (
            ("reference", reference),
            ("prioritized", prioritized),
            ("weighted", weighted),
        )
    }
    pose = {
        key: out.diagnostics["objective_residuals"]["pose"]
        for key, out in (
            ("reference", reference),
            ("prioritized", prioritized),
            ("weighted", weighted),
        )
    }
    # Weighted, the CM gives way; prioritized, it moves only within the weak directions the
    # CM level passes down (σ < σ_max / B, damped), a hundred times less.
    assert abs(com["weighted"] - com["reference"]) > 1e-3
    assert abs(com["prioritized"] - com["reference"]) < 1e-2 * abs(
        com["weighted"] - com["reference"]
    )
    assert pose["prioritized"] > pose["reference"]  # the fighting objective pays


def test_levels_are_reported_every_tick(robot):
    q, v = near_standing_state(robot, 11)
    levels = compute(robot, q, v).diagnostics["prioritized"]["priority_levels"]
    assert levels[0]["objectives"] == ["dynamics"]
    assert levels[-1]["objectives"] == ["forces"]
    assert [level["objectives"] for level in levels[1:-1]] == [
        ["contact"],
        ["com", "angular_momentum", "pose", "trunk"],
        ["com_height"],
    ]
    assert all(level["status"] in ("solved", "not reached") for level in levels)
    assert levels[0]["rank"] == robot.model.nv  # the equations of motion: full row rank


def test_priorities_and_weights_change_at_run_time():
    robot = load_robot_model("thesis_humanoid")
    controller = create_controller("prioritized", robot)
    controller.set_params({"priority_angular_momentum": 3, "weight_pose": 0.0})
    q, v = near_standing_state(robot, 5)
    output = controller.compute(ControlInput(0.0, q, v, (True, True)))
    levels = output.diagnostics["prioritized"]["priority_levels"]
    assert {"com_height", "angular_momentum"} in [set(lv["objectives"]) for lv in levels]
    assert not any("pose" in lv["objectives"] for lv in levels)
    for bad in ({"priority_pose": 0}, {"priority_pose": 1.5}, {"weight_com": -1.0}):
        with pytest.raises(InvalidParams):
            controller.set_params(bad)


def test_friction_cone_basis_spans_the_inscribed_pyramid():
    mu = 0.6
    V = friction_cone_basis(mu)
    np.testing.assert_allclose(np.linalg.norm(V, axis=0), 1.0)
    # Every edge is on Coulomb's cone; every non-negative combination is in the pyramid.
    np.testing.assert_allclose(np.hypot(V[0], V[1]), mu * V[2])
    rng = np.random.default_rng(0)
    forces = V @ rng.uniform(0, 1, (4, 200))
    assert np.all(np.abs(forces[:2]) <= mu / math.sqrt(2) * forces[2] + 1e-12)


@pytest.mark.parametrize("duration_s", [0.3, 1.0, 2.5])
def test_target_objective_reaches_the_target(duration_s):
    """Integrating eq. 6 with a, b from eq. 7 lands on (y_T, ẏ_T) at T."""
    y0, v0, yT, vT = 0.9, 0.2, 0.7, -0.1
    steps = 20000
    dt = duration_s / steps
    y, rate = y0, v0
    for i in range(steps):
        remaining = duration_s - i * dt
        acceleration = target_acceleration(y, rate, yT, vT, remaining, gain_bound=1e9)
        rate += acceleration * dt
        y += rate * dt
    assert y == pytest.approx(yT, abs=2e-3)
    assert rate == pytest.approx(vT, abs=2e-2)


def test_target_objective_is_bounded_as_the_time_runs_out():
    accelerations = [
        abs(float(target_acceleration(0.0, 0.0, 0.1, 0.0, T, gain_bound=100.0)))
        for T in np.geomspace(1.0, 1e-6, 200)
    ]
    assert max(accelerations) <= 100.0 * math.hypot(0.1, 0.0) * (1 + 1e-9)
    assert accelerations[-1] < 1e-3  # σ → 0: the damped solution goes to zero (eq. 19)


def test_a_new_cm_height_moves_the_cm_when_ranked_with_the_momentum():
    robot = load_robot_model("thesis_humanoid")
    q, v = near_standing_state(robot, 9)
    params = {"priority_com_height": 2, "priority_pose": 3}
    default = compute(robot, q, v, params)
    lowered = compute(robot, q, v, {**params, "com_height": 0.7})
    rate = "linear_momentum_rate_achieved"
    # Lower the CM: the ground pushes less than before (L̇_z smaller).
    assert lowered.diagnostics[rate][2] < default.diagnostics[rate][2] - 1.0


def layout_at(robot, seed: int):
    """The controller's layout at a near-standing state, every contact planted and loaded."""
    q, v = near_standing_state(robot, seed)
    data = robot.model.createData()
    terms = compute_dynamics_terms(robot, data, q, v)
    contacts = (True,) * len(robot.contacts)
    mus = tuple(c.friction_coefficient for c in robot.contacts)
    return q, terms, PrioritizedLayout(LayoutIndex(robot), terms, contacts, contacts, mus, 0.0, 1.0)


def test_motionless_forces_move_nothing(robot):
    """(τ, 0, λ) with Sᵀ τ + J_cᵀ V λ = 0: orthonormal, exactly zero on q̈, no generalized force."""
    _, terms, layout = layout_at(robot, 3)
    basis = layout.motionless_forces()
    assert basis.shape == (layout.size, layout.nl - 6)
    np.testing.assert_allclose(basis.T @ basis, np.eye(basis.shape[1]), atol=1e-12)
    assert not basis[layout.acceleration].any()
    dynamics = layout.equations_of_motion(terms).A
    np.testing.assert_allclose(dynamics @ basis, 0.0, atol=1e-10 * np.abs(dynamics).max())


def test_joint_limit_rows_bound_the_position_reached_within_the_horizon(robot):
    """Vectorized rows against the definition, joint by joint: ``q + q̇ T + ½ q̈ T² ≤ q_max``
    (and ``≥ q_min``) for every ``q̈`` the rows allow, with the rows of joints that cannot
    bind left out (eq. 27, velocity-aware); ball joints (all of the thesis humanoid's and the
    dino's) have none."""
    model = robot.model
    rng = np.random.default_rng(1)
    q = pin.neutral(model)
    v = np.zeros(model.nv)
    horizon = 0.1
    scalar = [joint for joint in model.joints[2:] if joint.nq == 1]
    for joint in scalar:  # below, above, near and inside, moving either way
        lower, upper = (
            model.lowerPositionLimit[joint.idx_q],
            model.upperPositionLimit[joint.idx_q],
        )
        q[joint.idx_q] = rng.choice(
            [lower - 0.1, upper + 0.1, lower + 0.05, upper - 0.05, 0.5 * (lower + upper)]
        )
        v[joint.idx_v] = rng.choice([-2.0, 0.0, 2.0])
    index = LayoutIndex(robot)
    columns, signs, offsets = index.joint_limit_bounds(q, v, horizon)
    rows = {(int(c), float(s)): float(f) for c, s, f in zip(columns, signs, offsets, strict=True)}
    assert len(rows) == columns.size
    expected = 0
    for joint in scalar:
        value, velocity = q[joint.idx_q], v[joint.idx_v]
        predicted = value + velocity * horizon
        for sign, limit in (
            (1.0, model.lowerPositionLimit[joint.idx_q]),
            (-1.0, model.upperPositionLimit[joint.idx_q]),
        ):
            # The acceleration that reaches the limit exactly at T, as `sign · q̈ ≥ −room`.
            room = sign * (predicted - limit) * 2.0 / horizon**2
            key = (joint.idx_v, sign)
            if room >= LIMIT_ACCELERATION_ACTIVE:
                assert key not in rows
                continue
            expected += 1
            assert rows[key] == pytest.approx(np.clip(room, -1000.0, 1000.0), rel=1e-12)
            # At the bound's acceleration the joint arrives at the limit at T (uncapped rows).
            if abs(room) < 1000.0:
                acceleration = -sign * rows[key]
                reached = value + velocity * horizon + 0.5 * acceleration * horizon**2
                assert reached == pytest.approx(limit, abs=1e-12)
    assert columns.size == expected
    assert bool(expected) == bool(scalar)


def test_a_tick_without_diagnostics_commands_the_same(robot):
    """Ticks that send no diagnostics skip them, and nothing else."""
    q, v = near_standing_state(robot, 4)
    controller = create_controller("prioritized", robot, {"contact_distance": 1.0})
    flags = (True,) * len(robot.contacts)
    full = controller.compute(ControlInput(0.0, q, v, flags))
    bare = controller.compute(ControlInput(0.0, q, v, flags, want_diagnostics=False))
    assert full.diagnostics is not None and bare.diagnostics is None
    for name in (
        "acceleration",
        "joint_torque",
        "contact_force_in_world",
        "contact_wrench_in_world",
    ):
        np.testing.assert_array_equal(getattr(bare, name), getattr(full, name))


def test_the_contact_rows_lie_in_the_soles_row_basis(robot):
    """6 orthonormal directions per sole hold its points' Jacobian rows (App. C)."""
    _, _, layout = layout_at(robot, 6)
    basis = layout.contact_row_basis()
    jacobian = layout.point_jacobian
    assert basis.shape == (jacobian.shape[0], 6 * len(robot.contacts))
    np.testing.assert_allclose(basis.T @ basis, np.eye(basis.shape[1]), atol=1e-14)
    np.testing.assert_allclose(basis @ (basis.T @ jacobian), jacobian, atol=1e-12)


def test_parameter_changes_reach_what_is_kept_between_ticks():
    """Support mask, friction and torque selection are cached per parameter set, not per tick."""
    robot = load_robot_model("thesis_humanoid")
    q, v = near_standing_state(robot, 8)
    controller = create_controller("prioritized", robot, {"contact_distance": 1.0})
    tick = ControlInput(0.0, q, v, (True, True))
    both = controller.compute(tick)
    counts = [len(c.points_in_frame) for c in robot.contacts]
    left = slice(0, counts[0])
    assert np.abs(both.contact_force_in_world[left]).max() > 1.0
    controller.set_params({"support_mask": [0.0, 1.0]})
    right_only = controller.compute(tick)
    assert not right_only.contact_force_in_world[left].any()
    controller.set_params({"support_mask": [1.0, 1.0], "friction_coefficients": [0.05, 0.05]})
    forces = controller.compute(tick).contact_force_in_world
    grip = 0.05 / math.sqrt(2.0) * forces[:, 2] + 1e-6
    assert np.all(np.abs(forces[:, :2]) <= grip[:, None])
    controller.set_params({"torque_selection": [1.0] * robot.nv_joints, "priority_torque": 2})
    levels = controller.compute(tick).diagnostics["prioritized"]["priority_levels"]
    assert any("torque" in level["objectives"] for level in levels)


def test_the_qp_time_budget_reaches_the_solver(monkeypatch):
    """`qp_time_budget_s` is the solver's wall-time budget for second tries (default 20 ms)."""
    import controller_server.controllers.prioritized as prioritized
    from controller_server.solvers.prioritized import QP_TIME_BUDGET_S

    budgets = []
    solve = prioritized.solve_prioritized

    def spy(*args, **kwargs):
        budgets.append(kwargs["qp_time_budget_s"])
        return solve(*args, **kwargs)

    monkeypatch.setattr(prioritized, "solve_prioritized", spy)
    robot = load_robot_model("thesis_humanoid")
    q, v = near_standing_state(robot, seed=0)
    compute(robot, q, v)
    compute(robot, q, v, {"qp_time_budget_s": 2.5})
    assert budgets == [QP_TIME_BUDGET_S, 2.5]
    with pytest.raises(InvalidParams):
        create_controller("prioritized", robot, {"qp_time_budget_s": -1.0})
