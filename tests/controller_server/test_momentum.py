"""App. B momentum matrices, COP/CMP, and point rows against independent references."""

import numpy as np
import pinocchio as pin
import pytest

from controller_server.balance_points import (
    center_of_pressure,
    centroidal_moment_pivot,
    support_polygon,
)
from controller_server.dynamics import compute_dynamics_terms, point_kinematics
from controller_server.features import PointTarget, compute_point_objective
from controller_server.models import BUILTIN_MODELS, load_robot_model


def random_state(model, rng):
    lower = np.full(model.nq, -1.0)
    upper = np.full(model.nq, 1.0)
    return pin.randomConfiguration(model, lower, upper), rng.normal(0.0, 1.0, model.nv)


@pytest.mark.parametrize("name", BUILTIN_MODELS)
@pytest.mark.parametrize("seed", range(5))
def test_momentum_matrices_match_pinocchio_centroidal_dynamics(name, seed):
    robot = load_robot_model(name)
    model = robot.model
    q, v = random_state(model, np.random.default_rng(seed))
    terms = compute_dynamics_terms(robot, model.createData(), q, v)
    reference = model.createData()
    pin.computeCentroidalMapTimeVariation(model, reference, q, v)
    momentum = terms.momentum
    np.testing.assert_allclose(momentum.R, reference.Ag[:3], atol=1e-8)
    np.testing.assert_allclose(momentum.S, reference.Ag[3:], atol=1e-8)
    np.testing.assert_allclose(momentum.r_bias, reference.dAg[:3] @ v, atol=1e-8)
    np.testing.assert_allclose(momentum.s_bias, reference.dAg[3:] @ v, atol=1e-8)
    centroidal = model.createData()
    pin.ccrba(model, centroidal, q, v)
    np.testing.assert_allclose(momentum.linear_momentum, centroidal.hg.linear, atol=1e-8)
    np.testing.assert_allclose(momentum.angular_momentum, centroidal.hg.angular, atol=1e-8)
    # L = m ċ (eq. 5.8).
    pin.centerOfMass(model, reference, q, v)
    np.testing.assert_allclose(
        momentum.linear_momentum, terms.total_mass * reference.vcom[0], atol=1e-8
    )


@pytest.mark.parametrize("seed", range(10))
def test_cop_of_point_forces_is_their_normal_force_average(seed):
    """Eq. 3.3–3.6 on the aggregate wrench equals Σ f_z x / Σ f_z for points on the ground."""
    rng = np.random.default_rng(seed)
    ground = rng.uniform(-0.2, 0.2)
    points = np.column_stack([rng.uniform(-0.3, 0.3, (6, 2)), np.full(6, ground)])
    forces = np.column_stack([rng.normal(0, 30, (6, 2)), rng.uniform(10, 300, 6)])
    reference = np.array([0.05, -0.02, ground + rng.uniform(0.0, 1.0)])
    total = forces.sum(axis=0)
    torque = np.cross(points - reference, forces).sum(axis=0)
    cop = center_of_pressure(total, torque, reference, ground)
    expected_xy = (forces[:, 2:] * points[:, :2]).sum(axis=0) / total[2]
    np.testing.assert_allclose(cop[:2], expected_xy, atol=1e-12)
    assert cop[2] == pytest.approx(ground)


def test_cop_and_cmp_hand_cases():
    # A 600 N vertical force under a foot 0.1 m in front of the reference, torque-free there.
    reference = np.array([0.0, 0.0, 0.05])
    cop = center_of_pressure(
        np.array([0.0, 0.0, 600.0]), np.array([0.0, -60.0, 0.0]), reference, 0.0
    )
    np.testing.assert_allclose(cop, [0.1, 0.0, 0.0], atol=1e-12)
    # CMP: vertical force → the CM's projection; tilted force → the line through the CM.
    com = np.array([0.02, 0.01, 1.0])
    np.testing.assert_allclose(
        centroidal_moment_pivot(com, np.array([0.0, 0.0, 500.0]), 0.0), [0.02, 0.01, 0.0]
    )
    np.testing.assert_allclose(
        centroidal_moment_pivot(com, np.array([100.0, -50.0, 500.0]), 0.0), [-0.18, 0.11, 0.0]
    )
    assert np.all(np.isnan(centroidal_moment_pivot(com, np.zeros(3), 0.0)))
    assert np.all(np.isnan(center_of_pressure(np.zeros(3), np.zeros(3), reference, 0.0)))


def test_support_polygon_of_two_feet():
    feet = np.array(
        [
            [0.1, 0.15, 0],
            [0.1, 0.05, 0],
            [-0.1, 0.15, 0],
            [-0.1, 0.05, 0],
            [0.1, -0.05, 0],
            [0.1, -0.15, 0],
            [-0.1, -0.05, 0],
            [-0.1, -0.15, 0],
        ],
        dtype=float,
    )
    polygon = support_polygon(feet)
    assert {tuple(p) for p in polygon} == {(0.1, 0.15), (-0.1, 0.15), (0.1, -0.15), (-0.1, -0.15)}
    area = 0.5 * np.abs(
        np.dot(polygon[:, 0], np.roll(polygon[:, 1], 1))
        - np.dot(polygon[:, 1], np.roll(polygon[:, 0], 1))
    )
    assert area == pytest.approx(0.2 * 0.3)
    assert support_polygon(feet[:2]).shape == (2, 2)
    assert support_polygon(np.zeros((0, 3))).shape == (0, 2)


@pytest.mark.parametrize("name", BUILTIN_MODELS)
def test_point_acceleration_rows_match_finite_differences(name):
    """App. C: Q = ∂p/∂q (manifold FD) and q_bias = d/dt (Q q̇) at q̈ = 0."""
    robot = load_robot_model(name)
    model = robot.model
    rng = np.random.default_rng(11)
    q, v = random_state(model, rng)
    frame = model.getFrameId(robot.contacts[0].frame_name)
    offset = np.array([[0.05, -0.02, 0.1]])
    data = model.createData()
    compute_dynamics_terms(robot, data, q, v)  # fills Jacobians and zero-acceleration kinematics
    point = point_kinematics(model, data, frame, offset)

    def position(config):
        d = model.createData()
        pin.framesForwardKinematics(model, d, config)
        return d.oMf[frame].act(offset[0])

    eps = 1e-6
    jacobian_fd = np.column_stack(
        [
            (
                position(pin.integrate(model, q, eps * e))
                - position(pin.integrate(model, q, -eps * e))
            )
            / (2 * eps)
            for e in np.eye(model.nv)
        ]
    )
    np.testing.assert_allclose(point.jacobian, jacobian_fd, atol=1e-6)

    def velocity(config):
        d = model.createData()
        compute_dynamics_terms(robot, d, config, v)
        return point_kinematics(model, d, frame, offset).jacobian @ v

    drift_fd = (
        velocity(pin.integrate(model, q, eps * v)) - velocity(pin.integrate(model, q, -eps * v))
    ) / (2 * eps)
    np.testing.assert_allclose(point.drift, drift_fd, atol=1e-5)

    target = PointTarget(
        robot.contacts[0].frame_name, offset[0], np.zeros(3), np.zeros(3), 50.0, 10.0, 2.0
    )
    objective = compute_point_objective("p", target, point)
    desired = 50.0 * (np.zeros(3) - point.position_in_world[0]) + 10.0 * (
        -point.velocity_in_world[0]
    )
    np.testing.assert_allclose(objective.b + point.drift, desired, atol=1e-12)
