"""`RobotState.predicted`: one control period ahead, checked against Pinocchio's integrate."""

import numpy as np
import pinocchio as pin
import pytest

from clients.layout import JointIndices
from clients.state import RobotState
from controller_server.models import load_robot_model
from protocol.messages import Command


@pytest.mark.parametrize("model_name", ["thesis_humanoid", "revolute_humanoid"])
def test_prediction_is_semi_implicit_euler_on_the_configuration_manifold(model_name):
    robot = load_robot_model(model_name)
    model = robot.model
    rng = np.random.default_rng(11)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    v = rng.normal(size=model.nv)
    a = rng.normal(scale=10.0, size=model.nv)
    dt = 1e-3
    rotation = pin.Quaternion(q[3:7]).toRotationMatrix()
    state = RobotState(
        joint_position=q[7:].copy(),
        joint_velocity=v[6:].copy(),
        position_base_in_world=q[:3].copy(),
        orientation_base_in_world_xyzw=q[3:7].copy(),
        linear_velocity_base_in_world=rotation @ v[:3],
        angular_velocity_base_in_base=v[3:6].copy(),
    )
    command = Command.model_construct(
        joint_acceleration=a[6:],
        base_linear_acceleration_in_world=rotation @ a[:3],
        base_angular_acceleration_in_base=a[3:6],
    )
    predicted = state.predicted(dt, JointIndices.of(robot.joints), command)

    # Pinocchio: v' = v + a dt, then q' = q ⊕ v' dt (joints and base orientation).
    v_next = v + dt * a
    q_next = pin.integrate(model, q, v_next * dt)
    np.testing.assert_allclose(predicted.joint_position, q_next[7:], atol=1e-12)
    np.testing.assert_allclose(predicted.joint_velocity, v_next[6:], atol=1e-12)
    np.testing.assert_allclose(predicted.orientation_base_in_world_xyzw, q_next[3:7], atol=1e-12)
    np.testing.assert_allclose(predicted.angular_velocity_base_in_base, v_next[3:6], atol=1e-12)
    # The base moves with its world-frame velocity.
    np.testing.assert_allclose(
        predicted.position_base_in_world,
        q[:3] + dt * (rotation @ v[:3] + dt * rotation @ a[:3]),
        atol=1e-12,
    )
