"""E_swing (``features/swing_foot.py``) against finite differences of the kinematics, and its
target profile against integration.

The objective's rows say how ``q̈`` moves and turns the swing foot's frame: solved alone, they
must produce exactly the accelerations the swing asks for. Followed exactly, the asked
accelerations lift the foot to the step height at mid-swing and set it on the foothold at the
end of the swing.
"""

import numpy as np
import pinocchio as pin
import pytest

from controller_server.dynamics import compute_dynamics_terms
from controller_server.features.swing_foot import (
    SwingTarget,
    compute_swing_objective,
    swing_acceleration,
    swing_angular_acceleration,
)
from controller_server.models import load_robot_model

STEP = 1e-6


@pytest.mark.parametrize("model_name", ["revolute_humanoid", "thesis_humanoid"])
def test_solved_alone_the_rows_give_the_swing_accelerations(model_name):
    robot = load_robot_model(model_name)
    model = robot.model
    rng = np.random.default_rng(5)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    q[7:] = np.clip(q[7:], model.lowerPositionLimit[7:], model.upperPositionLimit[7:])
    q = pin.normalize(model, q)
    v = rng.normal(size=model.nv) * 0.5
    data = model.createData()
    terms = compute_dynamics_terms(robot, data, q, v)
    foot = 0
    frame = robot.contacts[foot].frame_id
    target = SwingTarget(
        contact=foot,
        position_target_in_world=terms.position_contact_frames_in_world[foot] + [0.3, 0.05, -0.2],
        orientation_target_in_world=pin.rpy.rpyToMatrix(0.0, 0.1, 0.4),
        step_height=0.06,
        start_s=0.0,
        duration_s=0.5,
    )
    stiffness, damping, time_s = 100.0, 20.0, 0.1
    objective = compute_swing_objective(
        target,
        time_s,
        terms.support_jacobians[foot],
        terms.support_drifts[foot],
        terms.position_contact_frames_in_world[foot],
        data.oMf[frame].rotation.copy(),
        v,
        stiffness,
        damping,
        1.0,
    )
    acceleration = np.linalg.lstsq(objective.A, objective.b, rcond=None)[0]

    def pose(configuration):
        d = model.createData()
        pin.framesForwardKinematics(model, d, configuration)
        return d.oMf[frame].translation.copy(), d.oMf[frame].rotation.copy()

    def rates(configuration, velocity):
        ahead = pin.integrate(model, configuration, velocity * STEP)
        (p0, R0), (p1, R1) = pose(configuration), pose(ahead)
        return (p1 - p0) / STEP, pin.log3(R1 @ R0.T) / STEP

    linear_now, angular_now = rates(q, v)
    linear_next, angular_next = rates(pin.integrate(model, q, v * STEP), v + acceleration * STEP)
    position, rotation = pose(q)
    desired_linear = swing_acceleration(target, time_s, position, linear_now, stiffness, damping)
    desired_angular = swing_angular_acceleration(
        target, time_s, rotation, angular_now, stiffness, damping
    )
    np.testing.assert_allclose((linear_next - linear_now) / STEP, desired_linear, atol=1e-2)
    np.testing.assert_allclose((angular_next - angular_now) / STEP, desired_angular, atol=1e-2)


def test_followed_exactly_the_foot_clears_the_step_height_and_lands_on_the_foothold():
    start = np.array([0.0, 0.1, 0.0])
    foothold = np.array([0.35, 0.12, 0.0])
    target = SwingTarget(0, foothold, np.eye(3), 0.06, start_s=1.0, duration_s=0.5)
    position, velocity, dt = start.copy(), np.zeros(3), 1e-3
    heights = []
    for tick in range(500):
        acceleration = swing_acceleration(target, 1.0 + tick * dt, position, velocity, 100.0, 20.0)
        velocity = velocity + acceleration * dt
        position = position + velocity * dt
        heights.append(position[2])
    heights = np.array(heights)
    assert heights[240:260].max() == pytest.approx(0.06, abs=0.005)  # the step height, mid-swing
    assert heights.min() > -0.002  # not through the ground on the way
    np.testing.assert_allclose(position[:2], foothold[:2], atol=0.005)
    assert position[2] == pytest.approx(0.0, abs=0.01)
    assert velocity[2] < 0.0  # still moving down: it touches rather than hovers


def test_followed_exactly_a_tilted_foot_lands_flat():
    # A foot that leaves the ground on its toe (pitched 0.15 rad, turning) lands flat.
    flat = pin.rpy.rpyToMatrix(0.0, 0.0, 0.3)
    target = SwingTarget(0, np.zeros(3), flat, 0.06, start_s=1.0, duration_s=0.3)
    rotation = pin.rpy.rpyToMatrix(0.02, 0.15, 0.25)
    angular_velocity, dt = np.array([0.0, 2.0, 0.0]), 1e-4
    for tick in range(int(0.3 / dt)):
        acceleration = swing_angular_acceleration(
            target, 1.0 + tick * dt, rotation, angular_velocity, 100.0, 20.0
        )
        angular_velocity = angular_velocity + acceleration * dt
        rotation = pin.exp3(angular_velocity * dt) @ rotation
    assert np.linalg.norm(pin.log3(flat @ rotation.T)) < np.radians(0.3)
    assert np.linalg.norm(angular_velocity) < 0.5  # from 2 rad/s; the hand-over's setpoint ends it
