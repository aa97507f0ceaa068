"""Where the bridge gets what its actuators cannot tell: the base state, the contacts.

A :class:`BaseStateSource` answers once per tick, with either the base
pose and twist (:class:`BaseReading`) or an IMU sample from which the
server estimates them (:class:`ImuBaseReading`), and the contact flags.
Three are built in: :class:`FixedBase` (a robot on a stand: at rest,
upright, at the standing height, both feet flagged in support),
:class:`SimulatorBase` (the simulated robot's ground truth behind
``poise bridge --emulate``) and :class:`SimulatedImuBase` (the simulated
robot's IMU, ``base_state = "imu"``). On real hardware the IMU and the
contact flags come from an :class:`ImuSource` that the program running the
bridge implements and passes to :func:`~clients.bridge.app.run_bridge`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from protocol.messages import ImuSample, Welcome

if TYPE_CHECKING:
    from clients.bridge.plant import Plant
    from clients.physics.imu import SimulatedImu

__all__ = [
    "BaseReading",
    "BaseStateSource",
    "FixedBase",
    "ImuBaseReading",
    "ImuSource",
    "SimulatedImuBase",
    "SimulatorBase",
    "SupportFlags",
]


@dataclass(frozen=True)
class BaseReading:
    """The base state and contacts of one tick, in wire conventions."""

    position_base_in_world: np.ndarray
    orientation_base_in_world_xyzw: np.ndarray
    linear_velocity_base_in_world: np.ndarray
    angular_velocity_base_in_base: np.ndarray
    contact_flags: list[bool]


@dataclass(frozen=True)
class ImuBaseReading:
    """The IMU's newest sample and the contacts of one tick: the server estimates the base.

    Attributes:
        imu: Gyroscope, accelerometer (specific force, +9.81 m/s² up at rest)
            and optionally the IMU's own orientation, in the axes of the IMU
            that ``[imu]`` mounts.
        contact_flags: Per contact (``welcome`` order): is it a support now.
            The estimator holds a flagged foot still on the ground: flag a
            foot only when it carries load.
    """

    imu: ImuSample
    contact_flags: list[bool]


class BaseStateSource(Protocol):
    """Gives the base state (or the IMU sample it is estimated from) each tick."""

    def read(self) -> BaseReading | ImuBaseReading:
        """The base state now."""
        ...


class ImuSource(Protocol):
    """A robot's IMU and contact flags, for ``base_state = "imu"`` with ``source = "external"``.

    Implement it for real hardware: read the IMU's driver (its newest
    sample, in the IMU's axes: the mount in ``[imu]`` says where they are on
    the robot) and the feet's support flags (force sensors, or a contact
    detector of your own; the bridge has no way to tell them), and pass it
    to :func:`~clients.bridge.app.run_bridge` or
    :func:`~clients.bridge.app.open_bridge` as ``imu_source``. The loop
    calls :meth:`read` once per tick from its own thread; it must not block
    (return the newest sample a driver thread keeps). An exception from it
    ends the run, the actuators disabled.
    """

    def read(self) -> ImuBaseReading:
        """The newest IMU sample and this tick's contact flags."""
        ...


class FixedBase:
    """At rest, upright, at the standing height, every contact in support (a stand)."""

    def __init__(self, welcome: Welcome):
        self._reading = BaseReading(
            np.array(welcome.standing_position_base_in_world),
            np.array([0.0, 0.0, 0.0, 1.0]),
            np.zeros(3),
            np.zeros(3),
            [True] * len(welcome.contacts),
        )

    def read(self) -> BaseReading:
        """The same reading every tick."""
        return self._reading


class SupportFlags:
    """The simulated robot's feet flagged in support, as ``poise sim`` flags them.

    A touching foot once its normal force exceeds the threshold, until it
    lifts off (:func:`clients.physics.status.support_flags`).
    """

    def __init__(self, plant: Plant, support_force_threshold_N: float):
        self.plant = plant
        self.threshold_N = support_force_threshold_N
        self._flags = plant.backend.contact_flags()

    def read(self) -> list[bool]:
        """The flags now."""
        from clients.physics.status import support_flags

        backend = self.plant.backend
        self._flags = support_flags(
            self._flags,
            backend.contact_flags(),
            backend.contact_wrenches_in_world()[:, 2],
            self.threshold_N,
        )
        return self._flags


class SimulatorBase:
    """Ground truth of the simulated robot behind the emulated actuators.

    Feet are flagged in support by :class:`SupportFlags`.
    """

    def __init__(self, plant: Plant, support_force_threshold_N: float):
        self.plant = plant
        self.support = SupportFlags(plant, support_force_threshold_N)

    def read(self) -> BaseReading:
        """The simulated base and contacts now."""
        state = self.plant.backend.state()
        return BaseReading(
            state.position_base_in_world,
            state.orientation_base_in_world_xyzw,
            state.linear_velocity_base_in_world,
            state.angular_velocity_base_in_base,
            self.support.read(),
        )


class SimulatedImuBase:
    """The simulated robot's IMU and support flags: an :class:`ImuSource` for emulation.

    The IMU is a :class:`~clients.physics.imu.SimulatedImu` that the plant
    updates after every physics step (:meth:`~clients.bridge.plant.Plant.add_sensor`);
    feet are flagged in support by :class:`SupportFlags`, as for
    :class:`SimulatorBase`.
    """

    def __init__(self, imu: SimulatedImu, plant: Plant, support_force_threshold_N: float):
        self.imu = imu
        self.support = SupportFlags(plant, support_force_threshold_N)

    def read(self) -> ImuBaseReading:
        """The IMU's newest sample and the support flags now."""
        reading = self.imu.reading()
        if reading is None:
            raise RuntimeError("the simulated IMU has no sample: the plant did not reset it")
        return ImuBaseReading(reading.to_sample(), self.support.read())
