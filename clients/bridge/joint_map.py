"""Joint side ↔ motor side: gearing, direction, zero offset and limits, in wire order.

``q_joint = direction · q_motor / gear_ratio + zero_offset_rad``, so
``q̇_joint = direction · q̇_motor / gear_ratio`` and, by power balance over a
lossless gear, ``τ_motor = direction · τ_joint / gear_ratio``; a joint-side
damping ``d`` is ``d / gear_ratio²`` on the motor side.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from clients.bridge.actuator import MotorCommand, MotorFeedback
from clients.bridge.config import BridgeConfig
from protocol.messages import Welcome

__all__ = ["ActuatorRef", "JointMap"]


@dataclass(frozen=True)
class ActuatorRef:
    """Where a joint's actuator is: its bus and id there."""

    joint: str
    bus: str
    id: int


class JointMap:
    """The robot's joints (wire order) and the actuators that drive them.

    Args:
        config: The bridge file (validated).
        welcome: The server's handshake; its joint order is the wire order,
            and its limits fill the limits the map leaves out.
        motor_peak_torque_Nm: Per joint, the most its motor can make (motor
            side); the joint's torque limit is at most that through the gear.
    """

    def __init__(
        self,
        config: BridgeConfig,
        welcome: Welcome,
        motor_peak_torque_Nm: Mapping[str, float] | None = None,
    ):
        joints = list(welcome.joints)
        self.names = [joint.name for joint in joints]
        entries = [config.joints[name] for name in self.names]
        self.actuators = [
            ActuatorRef(name, e.bus, e.id) for name, e in zip(self.names, entries, strict=True)
        ]
        self.gear_ratio = np.array([e.gear_ratio for e in entries])
        self.direction = np.array([float(e.direction) for e in entries])
        self.zero_offset_rad = np.array([e.zero_offset_rad for e in entries])
        self.torque_limit_Nm = np.array(
            [
                e.torque_limit_Nm if e.torque_limit_Nm is not None else joint.torque_limit[0]
                for e, joint in zip(entries, joints, strict=True)
            ]
        )
        self.position_lower_rad = np.array(
            [
                e.position_limit_rad[0]
                if e.position_limit_rad
                else (joint.position_lower or [-np.inf])[0]
                for e, joint in zip(entries, joints, strict=True)
            ]
        )
        self.position_upper_rad = np.array(
            [
                e.position_limit_rad[1]
                if e.position_limit_rad
                else (joint.position_upper or [np.inf])[0]
                for e, joint in zip(entries, joints, strict=True)
            ]
        )
        if motor_peak_torque_Nm is not None:
            peak = np.array([motor_peak_torque_Nm.get(name, np.inf) for name in self.names])
            self.torque_limit_Nm = np.minimum(self.torque_limit_Nm, peak * self.gear_ratio)
        self.velocity_limit_rad_s = np.array([e.velocity_limit_rad_s for e in entries])
        self.derate_above_C = np.array([e.derate_above_C for e in entries])
        self.temperature_limit_C = np.array([e.temperature_limit_C for e in entries])
        self._scale = self.direction / self.gear_ratio  # joint per motor unit
        self.buses = list(dict.fromkeys(ref.bus for ref in self.actuators))
        self._indices = {
            bus: [i for i, ref in enumerate(self.actuators) if ref.bus == bus] for bus in self.buses
        }

    def __len__(self) -> int:
        return len(self.names)

    def joint_position_rad(self, motor_position_rad: np.ndarray) -> np.ndarray:
        """Joint positions of motor positions (wire order)."""
        return self._scale * motor_position_rad + self.zero_offset_rad

    def motor_position_rad(self, joint_position_rad: np.ndarray) -> np.ndarray:
        """Motor positions of joint positions (wire order)."""
        return (joint_position_rad - self.zero_offset_rad) / self._scale

    def joint_velocity_rad_s(self, motor_velocity_rad_s: np.ndarray) -> np.ndarray:
        """Joint velocities of motor velocities."""
        return self._scale * motor_velocity_rad_s

    def motor_velocity_rad_s(self, joint_velocity_rad_s: np.ndarray) -> np.ndarray:
        """Motor velocities of joint velocities."""
        return joint_velocity_rad_s / self._scale

    def motor_torque_Nm(self, joint_torque_Nm: np.ndarray) -> np.ndarray:
        """Motor torques that make these joint torques (lossless gearing)."""
        return self._scale * joint_torque_Nm

    def joint_torque_Nm(self, motor_torque_Nm: np.ndarray) -> np.ndarray:
        """Joint torques these motor torques make."""
        return motor_torque_Nm / self._scale

    def derated_torque_limit_Nm(self, temperature_C: np.ndarray) -> np.ndarray:
        """Joint torque limits with over-temperature derating.

        Full limit up to ``derate_above_C``, falling linearly to 0 at
        ``temperature_limit_C``; an unknown temperature (NaN) does not derate.
        """
        span = self.temperature_limit_C - self.derate_above_C
        fraction = np.clip((self.temperature_limit_C - temperature_C) / span, 0.0, 1.0)
        return self.torque_limit_Nm * np.where(np.isnan(temperature_C), 1.0, fraction)

    def split(self, values: np.ndarray) -> dict[str, dict[int, float]]:
        """Per bus, per actuator id, the value of each joint (wire order in)."""
        return {
            bus: {self.actuators[i].id: float(values[i]) for i in indices}
            for bus, indices in self._indices.items()
        }

    def torque_commands(self, joint_torque_Nm: np.ndarray) -> dict[str, dict[int, MotorCommand]]:
        """Per bus, the torque-only commands making these joint torques."""
        return {
            bus: {i: MotorCommand(torque_Nm=torque) for i, torque in torques.items()}
            for bus, torques in self.split(self.motor_torque_Nm(joint_torque_Nm)).items()
        }

    def motor_damping(self, joint_damping_Nm_s_per_rad: float) -> dict[str, dict[int, float]]:
        """Per bus, the motor-side damping of a joint-side damping (``d / gear_ratio²``)."""
        return self.split(joint_damping_Nm_s_per_rad / self.gear_ratio**2)

    def gather(
        self, feedback: Mapping[str, Mapping[int, MotorFeedback | None]]
    ) -> list[MotorFeedback | None]:
        """Each joint's actuator feedback (wire order) from the buses' replies."""
        return [feedback.get(ref.bus, {}).get(ref.id) for ref in self.actuators]

    def joint_state(
        self, feedback: Sequence[MotorFeedback | None], previous: tuple[np.ndarray, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint positions, velocities and motor temperatures from feedback.

        A missed reply keeps the joint's previous position and velocity;
        an unknown temperature is NaN.
        """
        motor_q = self.motor_position_rad(previous[0])
        motor_v = self.motor_velocity_rad_s(previous[1])
        temperature = np.full(len(self), np.nan)
        for i, reply in enumerate(feedback):
            if reply is not None:
                motor_q[i] = reply.position_rad
                motor_v[i] = reply.velocity_rad_s
                if reply.temperature_C is not None:
                    temperature[i] = reply.temperature_C
        return (
            self.joint_position_rad(motor_q),
            self.joint_velocity_rad_s(motor_v),
            temperature,
        )
