"""The robot state a client measures, in wire conventions, and its ``state`` message."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clients.layout import JointIndices
from protocol.messages import Command, State

__all__ = ["RobotState"]


@dataclass
class RobotState:
    """Robot state in wire conventions (the fields of a ``state`` message, see docs/protocol.md)."""

    joint_position: np.ndarray
    joint_velocity: np.ndarray
    position_base_in_world: np.ndarray
    orientation_base_in_world_xyzw: np.ndarray
    linear_velocity_base_in_world: np.ndarray
    angular_velocity_base_in_base: np.ndarray

    def to_message(
        self,
        time_s: float,
        contact_flags: list[bool],
        contact_wrench_in_world: np.ndarray | None = None,
    ) -> State:
        """The ``state`` message for this instant (``seq`` is set by the client).

        Built without validation (a 1 kHz loop's worth of time): the server
        validates every state at its edge and answers a bad one (NaN, wrong
        sizes) with a typed ``error``, so nothing invalid is acted on.
        """
        return State.model_construct(
            time_s=time_s,
            joint_position=self.joint_position,
            joint_velocity=self.joint_velocity,
            position_base_in_world=self.position_base_in_world,
            orientation_base_in_world_xyzw=self.orientation_base_in_world_xyzw,
            linear_velocity_base_in_world=self.linear_velocity_base_in_world,
            angular_velocity_base_in_base=self.angular_velocity_base_in_base,
            contact_flags=contact_flags,
            contact_wrench_in_world=(
                None if contact_wrench_in_world is None else contact_wrench_in_world.reshape(-1)
            ),
        )

    def predicted(self, duration_s: float, joints: JointIndices, command: Command) -> RobotState:
        """The state ``duration_s`` ahead, if the accelerations of ``command`` act meanwhile.

        Semi-implicit Euler, as the simulators step: velocities first, then
        positions with the new velocities. Quaternions (base, ball joints)
        turn by their angular velocity in their own frame. Sending this
        instead of the measured state makes up for a command that acts one
        control period late (``command_delay_ticks = 1``).

        Args:
            duration_s: How far ahead (s).
            joints: Where the ball and 1-DoF joints are (``JointIndices.of(welcome.joints)``).
            command: The command acting until then.
        """
        dt = duration_s
        joint_velocity = self.joint_velocity + dt * command.joint_acceleration
        linear_velocity = (
            self.linear_velocity_base_in_world + dt * command.base_linear_acceleration_in_world
        )
        angular_velocity = (
            self.angular_velocity_base_in_base + dt * command.base_angular_acceleration_in_base
        )
        joint_position = self.joint_position.copy()
        joint_position[joints.scalar_position] += dt * joint_velocity[joints.scalar_velocity]
        if len(joints.ball_position):
            joint_position[joints.ball_position] = _turned(
                joint_position[joints.ball_position], dt * joint_velocity[joints.ball_velocity]
            )
        return RobotState(
            joint_position=joint_position,
            joint_velocity=joint_velocity,
            position_base_in_world=self.position_base_in_world + dt * linear_velocity,
            orientation_base_in_world_xyzw=_turned(
                self.orientation_base_in_world_xyzw[None], dt * angular_velocity[None]
            )[0],
            linear_velocity_base_in_world=linear_velocity,
            angular_velocity_base_in_base=angular_velocity,
        )


def _turned(quaternions_xyzw: np.ndarray, rotation_vectors: np.ndarray) -> np.ndarray:
    """``q ⊗ exp(θ)`` per row: each quaternion turned by a rotation vector in its own frame."""
    angle = np.linalg.norm(rotation_vectors, axis=1, keepdims=True)
    half = 0.5 * angle
    # sin(θ/2)/θ, with its limit 1/2 at θ = 0.
    scale = np.where(angle > 1e-12, np.sin(half) / np.maximum(angle, 1e-300), 0.5)
    dx, dy, dz = (rotation_vectors * scale).T
    dw = np.cos(half)[:, 0]
    x, y, z, w = quaternions_xyzw.T
    return np.stack(
        [
            w * dx + x * dw + y * dz - z * dy,
            w * dy - x * dz + y * dw + z * dx,
            w * dz + x * dy - y * dx + z * dw,
            w * dw - x * dx - y * dy - z * dz,
        ],
        axis=1,
    )
