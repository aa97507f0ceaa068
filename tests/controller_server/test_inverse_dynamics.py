"""Floating-base inverse dynamics (Macchietto 2008, eq. 4.2) and the tracking controller.

The residual ``rnea(q, v, q̈) − Sᵀτ − Σ J_pᵀ f`` uses point Jacobians built here
from Pinocchio's frame Jacobians, independently of ``compute_dynamics_terms``.
"""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest

from controller_server.controllers import ControlInput, ControlOutput, TrackingController
from controller_server.dynamics import compute_dynamics_terms
from controller_server.inverse_dynamics import InverseDynamicsResult, solve_inverse_dynamics
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model

MODEL_NAMES = tuple(BUILTIN_MODELS)
FLAG_SETS = ((True, True), (True, False), (False, True), (False, False))
WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
GRAVITY = 9.81


def random_state(robot: RobotModel, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded configuration (base within ±1 m, any orientation) and velocity."""
    model = robot.model
    lower = model.lowerPositionLimit.copy()
    upper = model.upperPositionLimit.copy()
    lower[:3], upper[:3] = -1.0, 1.0
    pin.seed(seed)
    q = pin.randomConfiguration(model, lower, upper)
    v = np.random.default_rng(seed).normal(size=model.nv)
    return q, v


def standing_state(robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    return q, np.zeros(robot.model.nv)


def pinocchio_point_jacobians(robot: RobotModel, q: np.ndarray) -> list[np.ndarray]:
    """Per contact, ``(3k, nv)``: ``J_lin − [r]× J_ang`` at each point (frame Jacobian shifted)."""
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    jacobians = []
    for contact in robot.contacts:
        frame = pin.getFrameJacobian(model, data, contact.frame_id, WORLD_ALIGNED)
        rotation = data.oMf[contact.frame_id].rotation
        rows = [
            frame[:3] - pin.skew(rotation @ point) @ frame[3:] for point in contact.points_in_frame
        ]
        jacobians.append(np.vstack(rows))
    return jacobians


def inverse_dynamics_residual(
    robot: RobotModel,
    q: np.ndarray,
    v: np.ndarray,
    acceleration: np.ndarray,
    joint_torque: np.ndarray,
    contact_force_in_world: np.ndarray,
) -> np.ndarray:
    """``rnea(q, v, q̈) − [0; τ] − Σ J_pᵀ f_p`` (eq. 4.2)."""
    model = robot.model
    residual = pin.rnea(model, model.createData(), q, v, acceleration).copy()
    residual[6:] -= joint_torque
    residual -= np.vstack(pinocchio_point_jacobians(robot, q)).T @ contact_force_in_world.reshape(
        -1
    )
    return residual


def point_friction(robot: RobotModel) -> np.ndarray:
    return np.concatenate(
        [np.full(len(c.points_in_frame), c.friction_coefficient) for c in robot.contacts]
    )


def point_support_mask(robot: RobotModel, flags: tuple[bool, ...]) -> np.ndarray:
    return np.concatenate(
        [np.full(len(c.points_in_frame), f) for c, f in zip(robot.contacts, flags, strict=True)]
    )


def assert_forces_admissible(
    robot: RobotModel, flags: tuple[bool, ...], contact_force_in_world: np.ndarray
) -> None:
    assert contact_force_in_world.shape == (robot.num_contact_points, 3)
    mu = point_friction(robot)
    fx, fy, fz = contact_force_in_world.T
    # The QP solver's feasibility tolerance is relative: -1e-9 N per N of the largest force.
    scale_N = max(1.0, float(np.max(np.abs(contact_force_in_world))))
    assert np.all(fz >= -1e-9 * scale_N), fz
    # Inside Coulomb's circular cone, not just a pyramid around it.
    assert np.all(np.hypot(fx, fy) <= mu * fz + 1e-6), (fx, fy, fz)
    off = ~point_support_mask(robot, flags)
    np.testing.assert_array_equal(contact_force_in_world[off], 0.0)


def solve(
    robot: RobotModel,
    q: np.ndarray,
    v: np.ndarray,
    acceleration: np.ndarray,
    flags: tuple[bool, ...],
) -> InverseDynamicsResult:
    terms = compute_dynamics_terms(robot, robot.model.createData(), q, v)
    return solve_inverse_dynamics(
        terms,
        acceleration,
        flags,
        [c.friction_coefficient for c in robot.contacts],
        robot.torque_limit,
    )


def support_classical_accelerations(
    robot: RobotModel, q: np.ndarray, v: np.ndarray, acceleration: np.ndarray
) -> list[np.ndarray]:
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, q, v, acceleration)
    pin.updateFramePlacements(model, data)
    return [
        pin.getFrameClassicalAcceleration(model, data, c.frame_id, WORLD_ALIGNED).vector
        for c in robot.contacts
    ]


@pytest.mark.parametrize("flags", FLAG_SETS)
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_random_states_give_admissible_consistent_solutions(
    name: str, flags: tuple[bool, bool]
) -> None:
    robot = load_robot_model(name)
    for seed in range(3):
        q, v = random_state(robot, 10 * seed + FLAG_SETS.index(flags))
        rng = np.random.default_rng(seed)
        desired = rng.normal(scale=5.0, size=robot.model.nv)
        result = solve(robot, q, v, desired, flags)

        assert_forces_admissible(robot, flags, result.contact_force_in_world)
        assert result.joint_torque.shape == (robot.nv_joints,)
        assert np.all(np.abs(result.joint_torque) <= robot.torque_limit)
        assert 0 <= result.saturated_joints <= robot.nv_joints
        assert np.isfinite(result.root_wrench_residual) and result.root_wrench_residual >= 0.0
        residual = inverse_dynamics_residual(
            robot, q, v, result.acceleration, result.joint_torque, result.contact_force_in_world
        )
        assert np.linalg.norm(residual) < 1e-6, residual


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_feasible_request_is_realized_exactly(name: str) -> None:
    """Standing still on both feet: q̈ = 0 is feasible (CoM over the feet, torques in limits),
    so the returned acceleration, which must be the one τ and f produce, is q̈ = 0."""
    robot = load_robot_model(name)
    q, v = standing_state(robot)
    result = solve(robot, q, v, np.zeros(robot.model.nv), (True, True))
    assert result.saturated_joints == 0
    assert result.root_wrench_residual < 1e-3
    np.testing.assert_allclose(result.acceleration, 0.0, atol=1e-6)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_tracking_controller_stands(name: str) -> None:
    robot = load_robot_model(name)
    q, v = standing_state(robot)
    flags = (True, True)
    output = TrackingController(robot).compute(ControlInput(0.0, q, v, flags))

    assert output.diagnostics["root_wrench_residual"] < 1e-3
    assert_forces_admissible(robot, flags, output.contact_force_in_world)
    total_vertical_N = output.contact_force_in_world[:, 2].sum()
    assert total_vertical_N == pytest.approx(robot.total_mass * GRAVITY, rel=1e-3)
    residual = inverse_dynamics_residual(
        robot, q, v, output.acceleration, output.joint_torque, output.contact_force_in_world
    )
    assert np.linalg.norm(residual) < 1e-6
    assert output.diagnostics["weighted"]["schur_condition_number"] >= 1.0
    np.testing.assert_allclose(
        output.diagnostics["position_com_in_world"],
        pin.centerOfMass(robot.model, robot.model.createData(), q),
        atol=1e-12,
    )
    # The realized q̈ keeps both feet still (eq. 5.1 with â_sup = 0).
    for acceleration in support_classical_accelerations(robot, q, v, output.acceleration):
        assert np.linalg.norm(acceleration) < 1e-6, acceleration


def assert_finite_output(robot: RobotModel, output: ControlOutput) -> None:
    assert output.acceleration.shape == (robot.model.nv,)
    assert output.joint_torque.shape == (robot.nv_joints,)
    assert output.contact_force_in_world.shape == (robot.num_contact_points, 3)
    for array in (
        output.acceleration,
        output.joint_torque,
        output.contact_force_in_world,
        output.diagnostics["position_com_in_world"],
    ):
        assert np.all(np.isfinite(array))
    assert np.isfinite(output.diagnostics["root_wrench_residual"])


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_tracking_controller_survives_changing_contact_flags(name: str) -> None:
    robot = load_robot_model(name)
    controller = TrackingController(robot)
    q, v = standing_state(robot)
    time_step_s = 0.001
    schedule = itertools.islice(itertools.cycle(FLAG_SETS), 16)
    for tick, flags in enumerate(schedule):
        output = controller.compute(ControlInput(tick * time_step_s, q, v, flags))
        assert_finite_output(robot, output)
        assert_forces_admissible(robot, flags, output.contact_force_in_world)
        assert np.all(np.abs(output.joint_torque) <= robot.torque_limit)
        v = v + time_step_s * output.acceleration
        q = pin.integrate(robot.model, q, time_step_s * v)


@pytest.mark.parametrize("model_name", MODEL_NAMES)
@pytest.mark.parametrize("flags", FLAG_SETS[:3])
def test_exact_inverse_dynamics_by_rnea_matches_the_full_solve(model_name, flags):
    """The 1 kHz RNEA path equals `solve_inverse_dynamics` whenever it answers, and answers
    in the common case: near standing, with the base tilted and moving, random q̈."""
    from controller_server.dynamics import compute_contact_geometry
    from controller_server.inverse_dynamics import exact_inverse_dynamics

    robot = load_robot_model(model_name)
    model, data = robot.model, robot.model.createData()
    mus = [0.8] * len(robot.contacts)
    limit = np.full(model.nv - 6, 1e4)
    rng = np.random.default_rng(7)
    answered = 0
    for _ in range(20):
        q, v = standing_state(robot)
        q[3:7] = pin.Quaternion(pin.exp3(rng.normal(scale=0.02, size=3))).coeffs()
        v = rng.normal(scale=0.05, size=model.nv)
        acceleration = rng.normal(scale=0.05, size=model.nv)
        geometry = compute_contact_geometry(robot, data, q)
        exact = exact_inverse_dynamics(robot, data, q, v, acceleration, geometry, flags, mus, limit)
        full = solve_inverse_dynamics(
            compute_dynamics_terms(robot, model.createData(), q, v), acceleration, flags, mus, limit
        )
        if exact is None:
            assert (
                full.saturated_joints
                or full.root_wrench_residual
                or not np.allclose(full.acceleration, acceleration)
            )
            continue
        answered += 1
        np.testing.assert_allclose(exact.acceleration, acceleration)
        np.testing.assert_allclose(exact.joint_torque, full.joint_torque, atol=1e-7)
        np.testing.assert_allclose(
            exact.contact_force_in_world, full.contact_force_in_world, atol=1e-7
        )
        np.testing.assert_allclose(
            exact.contact_wrench_in_world, full.contact_wrench_in_world, atol=1e-7
        )
        # And physics: M q̈ + h = Sᵀ τ + Σ J_pᵀ f with Pinocchio's own point Jacobians.
        residual = pin.rnea(model, model.createData(), q, v, acceleration)
        residual[6:] -= exact.joint_torque
        for J, f in zip(
            pinocchio_point_jacobians(robot, q),
            np.split(
                exact.contact_force_in_world,
                np.cumsum([len(c.points_in_frame) for c in robot.contacts])[:-1],
            ),
            strict=True,
        ):
            residual -= J.T @ f.reshape(-1)
        assert np.abs(residual).max() < 1e-7 * max(1.0, np.abs(exact.joint_torque).max())
    if all(flags):  # standing on both feet, the exact case is the common one
        assert answered >= 5
