"""The robot state a client measures, in wire conventions, and its ``state`` message."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from clients.layout import neutral_joint_position
from protocol.messages import Command, ImuSample, State, Welcome

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

    @classmethod
    def standing(cls, welcome: Welcome, joint_position: np.ndarray | None = None) -> RobotState:
        """At rest in ``welcome``'s standing pose (the neutral pose from an older server).

        ``joint_position`` (wire order) replaces the standing joints if given.
        """
        joints = list(welcome.joints)
        if joint_position is None:
            joint_position = (
                neutral_joint_position(joints)
                if welcome.standing_joint_position is None
                else np.array(welcome.standing_joint_position, dtype=float)
            )
        return cls(
            joint_position,
            np.zeros(sum(joint.nv for joint in joints)),
            np.array(welcome.standing_position_base_in_world),
            np.array(welcome.standing_orientation_base_in_world_xyzw),
            np.zeros(3),
            np.zeros(3),
        )

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

    def to_imu_message(
        self,
        time_s: float,
        contact_flags: list[bool],
        imu: ImuSample,
        contact_wrench_in_world: np.ndarray | None = None,
    ) -> State:
        """The ``state`` message with the joints of this state and the base as an IMU reading.

        The base fields of this state are not sent (the server estimates them from
        ``imu``); like :meth:`to_message`, built without validation.
        """
        return State.model_construct(
            time_s=time_s,
            joint_position=self.joint_position,
            joint_velocity=self.joint_velocity,
            imu=imu,
            contact_flags=contact_flags,
            contact_wrench_in_world=(
                None if contact_wrench_in_world is None else contact_wrench_in_world.reshape(-1)
            ),
        )

    def predicted(self, duration_s: float, model: pin.Model, command: Command) -> RobotState:
        """The state ``duration_s`` ahead, if the accelerations of ``command`` act meanwhile.

        Semi-implicit Euler, as the simulators step: velocities first, then
        the configuration moves with the new velocities, on its manifold
        (Pinocchio's ``integrate``: quaternions of the base and ball joints
        turn in their own frames). Sending this instead of the measured state
        makes up for a command that acts one control period late
        (``command_delay_ticks = 1``).

        Args:
            duration_s: How far ahead (s).
            model: Pinocchio model of the robot, free-flyer root first, joints
                in wire order (e.g. ``pin.buildModelFromMJCF`` of its MJCF).
            command: The command acting until then.
        """
        dt = duration_s
        q = np.concatenate(
            [self.position_base_in_world, self.orientation_base_in_world_xyzw, self.joint_position]
        )
        rotation = pin.Quaternion(self.orientation_base_in_world_xyzw).toRotationMatrix()
        linear_velocity = (
            self.linear_velocity_base_in_world + dt * command.base_linear_acceleration_in_world
        )
        angular_velocity = (
            self.angular_velocity_base_in_base + dt * command.base_angular_acceleration_in_base
        )
        joint_velocity = self.joint_velocity + dt * command.joint_acceleration
        v = np.concatenate([rotation.T @ linear_velocity, angular_velocity, joint_velocity])
        q_next = pin.integrate(model, q, dt * v)
        return RobotState(
            joint_position=q_next[7:],
            joint_velocity=joint_velocity,
            position_base_in_world=q_next[:3],
            orientation_base_in_world_xyzw=q_next[3:7],
            linear_velocity_base_in_world=linear_velocity,
            angular_velocity_base_in_base=angular_velocity,
        )
