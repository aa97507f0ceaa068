"""`RobotState.predicted`: one control period ahead, checked against Pinocchio's integrate."""

import numpy as np
import pinocchio as pin
import pytest

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
    predicted = state.predicted(dt, model, command)

    # v' = v + a dt, then each quaternion turns by its v' dt in its own frame
    # (written out here), 1-DoF joints and the base position move by v' dt.
    v_next = v + dt * a
    np.testing.assert_allclose(predicted.joint_velocity, v_next[6:], atol=1e-12)
    np.testing.assert_allclose(predicted.angular_velocity_base_in_base, v_next[3:6], atol=1e-12)
    np.testing.assert_allclose(
        predicted.linear_velocity_base_in_world, rotation @ v_next[:3], atol=1e-12
    )
    expected_base = pin.Quaternion(q[3:7]) * pin.Quaternion(pin.exp3(v_next[3:6] * dt))
    np.testing.assert_allclose(
        predicted.orientation_base_in_world_xyzw, expected_base.coeffs(), atol=1e-12
    )
    for joint in model.joints[2:]:
        iq, iv = joint.idx_q - 7, joint.idx_v - 6
        if joint.nq == 4:  # ball: quaternion xyzw
            turned = pin.Quaternion(q[7 + iq : 11 + iq]) * pin.Quaternion(
                pin.exp3(v_next[6 + iv : 9 + iv] * dt)
            )
            np.testing.assert_allclose(
                predicted.joint_position[iq : iq + 4], turned.coeffs(), atol=1e-12
            )
        else:
            np.testing.assert_allclose(
                predicted.joint_position[iq], q[7 + iq] + dt * v_next[6 + iv], atol=1e-12
            )
    # The base origin moves by its velocity (Pinocchio's SE(3) step: to O(dt²)).
    np.testing.assert_allclose(
        predicted.position_base_in_world, q[:3] + dt * rotation @ v_next[:3], atol=1e-6
    )
