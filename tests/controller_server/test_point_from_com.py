"""E_ankle (``features/point_from_com.py``) against finite differences of the kinematics.

The objective's rows say how ``q̈`` moves each foot relative to the CM, and how it turns the
foot: solved alone, they must produce exactly the accelerations the setpoint asks for.
"""

import numpy as np
import pinocchio as pin

from controller_server.dynamics import compute_dynamics_terms
from controller_server.features.point_from_com import compute_point_from_com_objective
from controller_server.models import load_robot_model

STEP = 1e-6


def test_solved_alone_the_rows_give_the_setpoint_accelerations():
    robot = load_robot_model("revolute_humanoid")
    model = robot.model
    rng = np.random.default_rng(3)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    q[7:] = np.clip(q[7:], model.lowerPositionLimit[7:], model.upperPositionLimit[7:])
    v = rng.normal(size=model.nv) * 0.5
    data = model.createData()
    terms = compute_dynamics_terms(robot, data, q, v)
    frames = [contact.frame_id for contact in robot.contacts]
    offsets = np.array([[0.05, 0.1, -0.8], [-0.02, -0.1, -0.75]])
    references = np.array([pin.rpy.rpyToMatrix(0.0, 0.1 * i, 0.0) for i in range(2)])
    stiffness, damping = 100.0, 20.0
    objective = compute_point_from_com_objective(
        [jacobian[:3] for jacobian in terms.support_jacobians],
        [drift[:3] for drift in terms.support_drifts],
        terms.position_contact_frames_in_world,
        v,
        terms.momentum,
        terms.total_mass,
        terms.position_com_in_world,
        offsets,
        stiffness,
        damping,
        1.0,
        rotations=[data.oMf[frame].rotation.copy() for frame in frames],
        reference_rotations=references,
        angular_jacobians=[jacobian[3:] for jacobian in terms.support_jacobians],
        angular_drifts=[drift[3:] for drift in terms.support_drifts],
    )
    acceleration = np.linalg.lstsq(objective.A, objective.b, rcond=None)[0]

    def relative(configuration):
        d = model.createData()
        pin.framesForwardKinematics(model, d, configuration)
        com = pin.centerOfMass(model, d, configuration)
        return np.array([d.oMf[frame].translation - com for frame in frames])

    def rotations(configuration):
        d = model.createData()
        pin.framesForwardKinematics(model, d, configuration)
        return [d.oMf[frame].rotation.copy() for frame in frames]

    def rates(configuration, velocity):
        ahead = pin.integrate(model, configuration, velocity * STEP)
        linear = (relative(ahead) - relative(configuration)) / STEP
        angular = [
            pin.log3(after @ before.T) / STEP
            for before, after in zip(rotations(configuration), rotations(ahead), strict=True)
        ]
        return linear, np.array(angular)

    linear_now, angular_now = rates(q, v)
    linear_next, angular_next = rates(pin.integrate(model, q, v * STEP), v + acceleration * STEP)
    linear_acceleration = (linear_next - linear_now) / STEP
    angular_acceleration = (angular_next - angular_now) / STEP
    offsets_now = relative(q)
    desired_linear = stiffness * (offsets - offsets_now) - damping * linear_now
    desired_angular = np.array(
        [
            stiffness * pin.log3(reference @ rotation.T) - damping * omega
            for reference, rotation, omega in zip(
                references, rotations(q), angular_now, strict=True
            )
        ]
    )
    np.testing.assert_allclose(linear_acceleration, desired_linear, atol=1e-2)
    np.testing.assert_allclose(angular_acceleration, desired_angular, atol=1e-2)
