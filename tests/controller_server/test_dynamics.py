"""Dynamics terms checked against finite differences and Pinocchio's own algorithms.

Every Jacobian column is compared with a central difference taken on the
configuration manifold (``pin.integrate`` along one DoF); every drift ``J̇ q̇``
with the time derivative of ``J(q(t)) v`` along ``q(t) = q ⊕ t v`` (constant
``v``, hence ``q̈ = 0``); ``M`` and ``h`` with ``rnea``; the support rows with
the classical acceleration Pinocchio computes for a ``q̈`` that satisfies them.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from controller_server.constraints import compute_support_equalities
from controller_server.dynamics import DynamicsTerms, compute_dynamics_terms
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model

MODEL_NAMES = tuple(BUILTIN_MODELS)
SEEDS = (0, 1)
WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
JACOBIAN_STEP = 1e-6
DRIFT_STEP = 1e-5


def random_state(robot: RobotModel, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded configuration (base within ±1 m, any orientation) and velocity."""
    model = robot.model
    rng = np.random.default_rng(seed)
    lower = model.lowerPositionLimit.copy()
    upper = model.upperPositionLimit.copy()
    lower[:3], upper[:3] = -1.0, 1.0
    pin.seed(seed)  # randomConfiguration draws from Pinocchio's own generator
    q = pin.randomConfiguration(model, lower, upper)
    v = rng.normal(size=model.nv)
    return q, v


def terms_at(robot: RobotModel, seed: int) -> DynamicsTerms:
    q, v = random_state(robot, seed)
    return compute_dynamics_terms(robot, robot.model.createData(), q, v)


def frame_pose(robot: RobotModel, data: pin.Data, q: np.ndarray, frame_id: int) -> pin.SE3:
    pin.framesForwardKinematics(robot.model, data, q)
    return pin.SE3(data.oMf[frame_id])


def finite_difference_jacobian(
    robot: RobotModel, q: np.ndarray, frame_id: int, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Central differences: ``(6, nv)`` frame twist rows and ``(3k, nv)`` point rows."""
    model = robot.model
    data = model.createData()
    frame = np.zeros((6, model.nv))
    point_rows = np.zeros((3 * len(points), model.nv))
    for i in range(model.nv):
        step = np.zeros(model.nv)
        step[i] = JACOBIAN_STEP
        plus = frame_pose(robot, data, pin.integrate(model, q, step), frame_id)
        minus = frame_pose(robot, data, pin.integrate(model, q, -step), frame_id)
        frame[:3, i] = (plus.translation - minus.translation) / (2 * JACOBIAN_STEP)
        frame[3:, i] = pin.log3(plus.rotation @ minus.rotation.T) / (2 * JACOBIAN_STEP)
        points_plus = plus.translation + points @ plus.rotation.T
        points_minus = minus.translation + points @ minus.rotation.T
        point_rows[:, i] = ((points_plus - points_minus) / (2 * JACOBIAN_STEP)).reshape(-1)
    return frame, point_rows


def pinocchio_velocities(
    robot: RobotModel, q: np.ndarray, v: np.ndarray, frame_id: int, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``J(q) v`` from Pinocchio directly: frame ``[v_o; ω]`` and point velocities (world axes)."""
    model = robot.model
    data = model.createData()
    jacobian = pin.computeFrameJacobian(model, data, q, frame_id, WORLD_ALIGNED)
    twist = jacobian @ v
    offsets = points @ data.oMf[frame_id].rotation.T
    point_velocities = twist[:3] + np.cross(twist[3:], offsets)
    return twist, point_velocities.reshape(-1)


def assert_close_relative(actual: np.ndarray, expected: np.ndarray, tolerance: float) -> None:
    scale = max(1.0, float(np.max(np.abs(expected))))
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=tolerance * scale)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_support_and_point_jacobians_match_finite_differences(name: str, seed: int) -> None:
    robot = load_robot_model(name)
    terms = terms_at(robot, seed)
    for index, contact in enumerate(robot.contacts):
        frame, points = finite_difference_jacobian(
            robot, terms.q, contact.frame_id, contact.points_in_frame
        )
        assert terms.support_jacobians[index].shape == (6, robot.model.nv)
        assert terms.point_jacobians[index].shape == (
            3 * len(contact.points_in_frame),
            robot.model.nv,
        )
        assert_close_relative(terms.support_jacobians[index], frame, 1e-6)
        assert_close_relative(terms.point_jacobians[index], points, 1e-6)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_point_positions_match_forward_kinematics(name: str, seed: int) -> None:
    robot = load_robot_model(name)
    terms = terms_at(robot, seed)
    data = robot.model.createData()
    for index, contact in enumerate(robot.contacts):
        pose = frame_pose(robot, data, terms.q, contact.frame_id)
        expected = np.array([pose.act(point) for point in contact.points_in_frame])
        np.testing.assert_allclose(terms.position_points_in_world[index], expected, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_drifts_match_time_derivative_of_jacobian_times_velocity(name: str, seed: int) -> None:
    robot = load_robot_model(name)
    terms = terms_at(robot, seed)
    q, v = terms.q, terms.v
    q_plus = pin.integrate(robot.model, q, DRIFT_STEP * v)
    q_minus = pin.integrate(robot.model, q, -DRIFT_STEP * v)
    for index, contact in enumerate(robot.contacts):
        twist_plus, points_plus = pinocchio_velocities(
            robot, q_plus, v, contact.frame_id, contact.points_in_frame
        )
        twist_minus, points_minus = pinocchio_velocities(
            robot, q_minus, v, contact.frame_id, contact.points_in_frame
        )
        support_drift = (twist_plus - twist_minus) / (2 * DRIFT_STEP)
        point_drift = (points_plus - points_minus) / (2 * DRIFT_STEP)
        assert_close_relative(terms.support_drifts[index], support_drift, 1e-5)
        assert_close_relative(terms.point_drifts[index], point_drift, 1e-5)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_mass_matrix_and_bias_forces_match_rnea(name: str, seed: int) -> None:
    robot = load_robot_model(name)
    model = robot.model
    terms = terms_at(robot, seed)
    data = model.createData()
    rng = np.random.default_rng(100 + seed)
    for _ in range(3):
        a = rng.normal(size=model.nv)
        expected = pin.rnea(model, data, terms.q, terms.v, a)
        assert_close_relative(terms.mass_matrix @ a + terms.bias_forces, expected, 1e-10)
    M = terms.mass_matrix
    np.testing.assert_array_equal(M, M.T)
    assert np.linalg.eigvalsh(M)[0] > 0.0
    np.testing.assert_allclose(
        terms.position_com_in_world, pin.centerOfMass(model, data, terms.q), atol=1e-12
    )


@pytest.mark.parametrize("flags_seed", range(4))
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_support_rows_zero_the_classical_acceleration_of_supports(
    name: str, flags_seed: int
) -> None:
    robot = load_robot_model(name)
    model = robot.model
    terms = terms_at(robot, flags_seed)
    rng = np.random.default_rng(200 + flags_seed)
    flags = tuple(bool(f) for f in rng.integers(0, 2, len(robot.contacts)))
    equality = compute_support_equalities(terms, flags)
    assert equality.C.shape == (6 * sum(flags), model.nv)
    assert equality.d.shape == (6 * sum(flags),)

    # A q̈ with C q̈ = d: least squares plus a random null-space component.
    a = rng.normal(size=model.nv)
    if sum(flags):
        a -= np.linalg.pinv(equality.C) @ (equality.C @ a - equality.d)
        np.testing.assert_allclose(equality.C @ a, equality.d, atol=1e-9)

    data = model.createData()
    pin.forwardKinematics(model, data, terms.q, terms.v, a)
    pin.updateFramePlacements(model, data)
    for contact, supporting in zip(robot.contacts, flags, strict=True):
        acceleration = pin.getFrameClassicalAcceleration(
            model, data, contact.frame_id, WORLD_ALIGNED
        )
        if supporting:
            np.testing.assert_allclose(acceleration.vector, np.zeros(6), atol=1e-8)
        else:  # an unconstrained foot generically accelerates
            assert np.linalg.norm(acceleration.vector) > 1e-3
