"""Scripted client: follow the server's accelerations by kinematic integration.

Until the reference simulator lands, this is the demo's client. It starts
the robot standing with its upper body (back, neck, arms) out of pose,
sends the state each tick, and integrates the returned accelerations with
semi-implicit Euler on the configuration manifold: base orientation and
ball joints by their rotation vector. There is no physics here (no gravity,
no ground): it shows the controller's plan — the pose converges to the
reference while the supporting feet stay put and the contact forces carry
the weight — not whether the robot would balance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from clients.client import ControllerClient
from clients.layout import joint_slices, neutral_joint_position
from clients.state import RobotState
from protocol.messages import Command, JointInfo

__all__ = ["ScriptedRun", "integrate", "perturbed_pose", "run_scripted"]


def _rotate_local(quaternion_xyzw: np.ndarray, rotation_vector: np.ndarray) -> np.ndarray:
    return (Rotation.from_quat(quaternion_xyzw) * Rotation.from_rotvec(rotation_vector)).as_quat()


def integrate(
    state: RobotState, command: Command, joints: list[JointInfo], dt_s: float
) -> RobotState:
    """Semi-implicit Euler step with the command's accelerations."""
    joint_velocity = state.joint_velocity + dt_s * command.joint_acceleration
    joint_position = state.joint_position.copy()
    for joint, (q_slice, v_slice) in zip(joints, joint_slices(joints).values(), strict=True):
        step = dt_s * joint_velocity[v_slice]
        if joint.kind == "ball":
            joint_position[q_slice] = _rotate_local(joint_position[q_slice], step)
        else:
            joint_position[q_slice] += step
    linear_velocity = (
        state.linear_velocity_base_in_world + dt_s * command.base_linear_acceleration_in_world
    )
    angular_velocity = (
        state.angular_velocity_base_in_base + dt_s * command.base_angular_acceleration_in_base
    )
    return RobotState(
        joint_position=joint_position,
        joint_velocity=joint_velocity,
        position_base_in_world=state.position_base_in_world + dt_s * linear_velocity,
        orientation_base_in_world_xyzw=_rotate_local(
            state.orientation_base_in_world_xyzw, dt_s * angular_velocity
        ),
        linear_velocity_base_in_world=linear_velocity,
        angular_velocity_base_in_base=angular_velocity,
    )


LEG_JOINT_WORDS = ("hip", "knee", "ankle", "foot", "toe")
"""Joints whose names contain these are legs and keep the neutral pose."""


def perturbed_pose(joints: list[JointInfo], angle_rad: float) -> np.ndarray:
    """Neutral pose with every upper-body joint turned by ``angle_rad``.

    Ball joints turn about their y axis; revolute joints toward the middle of
    their range, so the pose stays within limits. Leg joints stay neutral, so
    the feet are flat and the centre of mass stays over them.
    """
    position = neutral_joint_position(joints)
    for joint, (q_slice, _) in zip(joints, joint_slices(joints).values(), strict=True):
        if any(word in joint.name for word in LEG_JOINT_WORDS):
            continue
        if joint.kind == "ball":
            position[q_slice] = Rotation.from_rotvec([0.0, angle_rad, 0.0]).as_quat()
        elif joint.position_lower is not None and joint.position_upper is not None:
            lower, upper = joint.position_lower[0], joint.position_upper[0]
            position[q_slice] = np.clip(np.sign(0.5 * (lower + upper)) * angle_rad, lower, upper)
    return position


@dataclass
class ScriptedRun:
    """Time series of one scripted run."""

    time_s: list[float] = field(default_factory=list)
    pose_error_rad: list[float] = field(default_factory=list)
    joint_torque: list[np.ndarray] = field(default_factory=list)
    vertical_force_N: list[float] = field(default_factory=list)
    position_com_in_world: list[np.ndarray] = field(default_factory=list)
    compute_time_s: list[float] = field(default_factory=list)


def run_scripted(
    client: ControllerClient,
    duration_s: float = 2.0,
    dt_s: float = 0.001,
    angle_rad: float = 0.08,
) -> ScriptedRun:
    """Run from a perturbed standing pose, both feet supporting, for ``duration_s``.

    ``client`` must be connected. The base starts where the neutral pose
    stands (``welcome.standing_position_base_in_world``).
    """
    welcome = client.welcome
    assert welcome is not None, "connect() the client first"
    joints = list(welcome.joints)
    neutral = neutral_joint_position(joints)
    nv = sum(j.nv for j in joints)
    state = RobotState(
        joint_position=perturbed_pose(joints, angle_rad),
        joint_velocity=np.zeros(nv),
        position_base_in_world=np.array(welcome.standing_position_base_in_world),
        orientation_base_in_world_xyzw=np.array([0.0, 0.0, 0.0, 1.0]),
        linear_velocity_base_in_world=np.zeros(3),
        angular_velocity_base_in_base=np.zeros(3),
    )
    flags = [True] * len(welcome.contacts)
    run = ScriptedRun()
    for tick in range(round(duration_s / dt_s)):
        time_s = tick * dt_s
        command = client.step(state.to_message(time_s, flags))
        run.time_s.append(time_s)
        run.pose_error_rad.append(_pose_error(state.joint_position, neutral, joints))
        run.joint_torque.append(command.joint_torque)
        run.vertical_force_N.append(
            float(command.contact_force_in_world.reshape(-1, 3)[:, 2].sum())
        )
        run.position_com_in_world.append(command.diagnostics.position_com_in_world)
        run.compute_time_s.append(command.diagnostics.compute_time_s)
        state = integrate(state, command, joints, dt_s)
    return run


def _pose_error(position: np.ndarray, reference: np.ndarray, joints: list[JointInfo]) -> float:
    errors = []
    for joint, (q_slice, _) in zip(joints, joint_slices(joints).values(), strict=True):
        if joint.kind == "ball":
            relative = Rotation.from_quat(reference[q_slice]).inv() * Rotation.from_quat(
                position[q_slice]
            )
            errors.append(relative.magnitude())
        else:
            errors.extend(np.abs(position[q_slice] - reference[q_slice]))
    return float(np.sqrt(np.mean(np.square(errors))))
