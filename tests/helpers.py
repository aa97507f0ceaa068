"""Helpers shared by tests: random wire states and an independent dynamics check."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from clients.layout import joint_slices, neutral_joint_position
from controller_server.models import BUILTIN_MODELS
from protocol.messages import Command, State, Welcome


def random_state(welcome: Welcome, rng: np.random.Generator, spread: float = 0.1) -> State:
    """A state near standing: small random pose, velocities, tilt and contact flags."""
    joints = list(welcome.joints)
    position = neutral_joint_position(joints)
    for joint, (q_slice, _) in zip(joints, joint_slices(joints).values(), strict=True):
        if joint.kind == "ball":
            position[q_slice] = Rotation.from_rotvec(rng.normal(0, spread, 3)).as_quat()
        else:
            lower, upper = joint.position_lower[0], joint.position_upper[0]
            position[q_slice] = np.clip(rng.normal(0, spread), lower, upper)
    nv = sum(j.nv for j in joints)
    flags = [bool(f) for f in rng.random(len(welcome.contacts)) < 0.8]
    return State(
        time_s=float(rng.random()),
        joint_position=position,
        joint_velocity=rng.normal(0, 3 * spread, nv),
        position_base_in_world=np.array(welcome.standing_position_base_in_world)
        + rng.normal(0, 0.01, 3),
        orientation_base_in_world_xyzw=Rotation.from_rotvec(rng.normal(0, spread / 2, 3)).as_quat(),
        linear_velocity_base_in_world=rng.normal(0, spread, 3),
        angular_velocity_base_in_base=rng.normal(0, spread, 3),
        contact_flags=flags,
    )


class IndependentDynamics:
    """Inverse-dynamics residual computed with Pinocchio alone, from the wire data.

    The model is parsed straight from the file (no Poise code), the wire state
    converted by hand, and the contact point Jacobians taken from Pinocchio's
    frame Jacobians: ``rnea(q, v, a) − [0; τ] − Σ J_pᵀ f``.
    """

    def __init__(self, path: str, welcome: Welcome):
        self.model = pin.buildModelFromMJCF(path)
        assert self.model.joints[1].shortname() == "JointModelFreeFlyer"
        self.data = self.model.createData()
        self.welcome = welcome

    def residual(self, state: State, command: Command) -> float:
        rotation = Rotation.from_quat(state.orientation_base_in_world_xyzw).as_matrix()
        q = np.concatenate(
            [
                state.position_base_in_world,
                state.orientation_base_in_world_xyzw
                / np.linalg.norm(state.orientation_base_in_world_xyzw),
                state.joint_position,
            ]
        )
        q = pin.normalize(self.model, q)
        v_local = rotation.T @ state.linear_velocity_base_in_world
        omega = state.angular_velocity_base_in_base
        v = np.concatenate([v_local, omega, state.joint_velocity])
        a_local = rotation.T @ command.base_linear_acceleration_in_world - np.cross(omega, v_local)
        a = np.concatenate(
            [a_local, command.base_angular_acceleration_in_base, command.joint_acceleration]
        )
        generalized = pin.rnea(self.model, self.data, q, v, a).copy()
        generalized[6:] -= command.joint_torque
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        forces = command.contact_force_in_world.reshape(-1, 3)
        index = 0
        for contact in self.welcome.contacts:
            frame_id = self.model.getFrameId(contact.frame)
            jacobian = pin.getFrameJacobian(
                self.model, self.data, frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            )
            rotation_frame = self.data.oMf[frame_id].rotation
            for point in contact.points_in_frame:
                offset = rotation_frame @ np.array(point)
                skew = pin.skew(offset)
                point_jacobian = jacobian[:3] - skew @ jacobian[3:]
                generalized -= point_jacobian.T @ forces[index]
                index += 1
        return float(np.abs(generalized).max())


def builtin_path(name: str) -> str:
    return str(BUILTIN_MODELS[name])
