"""A simulated robot whose joints are driven by emulated actuators (hardware in the loop).

Every physics step the plant tells each emulated motor its joint's
position and velocity (motor side, through the actuator map's gearing),
asks it for the torque its firmware makes from the last command it
received, and steps the simulator with those torques. So the bridge, the
protocols and the emulators carry the whole robot, quantization and
latency included; the plant advances only when the bridge waits for its
next tick (:class:`PlantPacer`), which makes a run reproducible on any
machine however loaded. Sensors on the robot (an IMU) are fed after every
physics step (:meth:`Plant.add_sensor`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from clients.bridge.emulators.motor import EmulatedMotor
from clients.bridge.joint_map import JointMap
from clients.physics.backend import PhysicsBackend, Push
from clients.physics.status import fall_reason
from clients.state import RobotState

__all__ = ["Plant", "PlantPacer", "PlantSensor", "RealTimePacer"]


class PlantSensor(Protocol):
    """A sensor on the simulated robot (e.g. :class:`~clients.physics.imu.SimulatedImu`)."""

    def reset(self, state: RobotState, time_s: float) -> None:
        """Start over at ``state`` (the plant's reset, or the sensor's mounting)."""
        ...

    def update(self, state: RobotState, time_s: float) -> object:
        """Account for the physics step that ended at ``time_s`` in ``state``."""
        ...


class Plant:
    """The simulated robot behind the emulated actuators.

    Args:
        backend: The physics (reference simulator or MuJoCo), reset already.
        joint_map: The actuator map (gearing per joint, wire order).
        motors: The emulated motor on each joint, wire order.
        pushes: External pushes, in simulated time.
        standing_height_m: Base height standing (to tell a fall).
    """

    def __init__(
        self,
        backend: PhysicsBackend,
        joint_map: JointMap,
        motors: Sequence[EmulatedMotor],
        pushes: Sequence[Push] = (),
        standing_height_m: float = 1.0,
    ):
        if len(motors) != len(joint_map):
            raise ValueError(f"{len(motors)} motors for {len(joint_map)} joints")
        self.backend = backend
        self.joint_map = joint_map
        self.motors = list(motors)
        self.pushes = list(pushes)
        self.standing_height_m = standing_height_m
        self.fall_reason = ""
        self.fall_time_s: float | None = None
        self.sensors: list[PlantSensor] = []
        self._sense(backend.state())

    @property
    def time_s(self) -> float:
        """Simulated time (s)."""
        return self.backend.time_s

    def add_sensor(self, sensor: PlantSensor) -> None:
        """Mount ``sensor``: reset now and at every reset, updated after every physics step."""
        sensor.reset(self.backend.state(), self.backend.time_s)
        self.sensors.append(sensor)

    def reset(self, state: RobotState) -> None:
        """Put the robot in ``state`` at time 0 (its sensors start over too)."""
        self.backend.reset(state)
        state = self.backend.state()
        self._sense(state)
        for sensor in self.sensors:
            sensor.reset(state, self.backend.time_s)

    def _sense(self, state: RobotState) -> None:
        """Tell each emulated motor its joint's position and velocity."""
        position = self.joint_map.motor_position_rad(state.joint_position)
        velocity = self.joint_map.motor_velocity_rad_s(state.joint_velocity)
        for motor, q, v in zip(self.motors, position, velocity, strict=True):
            motor.sense(float(q), float(v))

    def advance(self, duration_s: float) -> None:
        """Step the physics for ``duration_s`` with the torques the motors make."""
        dt = self.backend.timestep_s
        for _ in range(max(1, round(duration_s / dt))):
            motor_torque = np.array([motor.torque_Nm() for motor in self.motors])
            for motor, torque in zip(self.motors, motor_torque, strict=True):
                motor.heat(float(torque), dt)
            active = [push for push in self.pushes if push.active(self.backend.time_s)]
            report = self.backend.step(self.joint_map.joint_torque_Nm(motor_torque), active)
            state = self.backend.state()
            self._sense(state)
            for sensor in self.sensors:
                sensor.update(state, self.backend.time_s)
            if not self.fall_reason:
                reason = fall_reason(state, self.standing_height_m, report.non_foot_contact)
                if reason:
                    self.fall_reason, self.fall_time_s = reason, self.backend.time_s


class PlantPacer:
    """Paces the bridge by the plant: waiting for the next tick steps the physics."""

    def __init__(self, plant: Plant, period_s: float):
        self.plant = plant
        self.period_s = period_s

    def now_s(self) -> float:
        """Simulated time."""
        return self.plant.time_s

    def wait(self) -> bool:
        """Advance one period; never late (returns False)."""
        self.plant.advance(self.period_s)
        return False


class RealTimePacer:
    """Paces the bridge by the wall clock: ticks on a fixed grid of periods."""

    def __init__(self, period_s: float):
        self.period_s = period_s
        self._next_s = time.monotonic() + period_s

    def now_s(self) -> float:
        """``time.monotonic()`` (s)."""
        return time.monotonic()

    def wait(self) -> bool:
        """Sleep until the next tick; True if it had already begun (an overrun).

        After an overrun the next tick is one period from now, so a stall does
        not make a burst of catch-up ticks.
        """
        delay = self._next_s - time.monotonic()
        if delay < 0.0:
            self._next_s = time.monotonic() + self.period_s
            return True
        time.sleep(delay)
        self._next_s += self.period_s
        return False
