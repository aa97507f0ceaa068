"""The robot state a client measures, in wire conventions, and its ``state`` message."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from protocol.messages import State

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
