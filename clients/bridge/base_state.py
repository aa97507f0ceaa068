"""Where the bridge gets what its actuators cannot tell: the base pose and twist, the contacts.

A :class:`BaseStateSource` answers once per tick. Two are built in:
:class:`FixedBase` (a robot on a stand: at rest, upright, at the standing
height, both feet flagged in support) and :class:`SimulatorBase` (the
simulated robot's ground truth behind ``poise bridge --emulate``). The IMU
estimator of the server will be the third.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from protocol.messages import Welcome

if TYPE_CHECKING:
    from clients.bridge.plant import Plant

__all__ = ["BaseReading", "BaseStateSource", "FixedBase", "SimulatorBase"]


@dataclass(frozen=True)
class BaseReading:
    """The base state and contacts of one tick, in wire conventions."""

    position_base_in_world: np.ndarray
    orientation_base_in_world_xyzw: np.ndarray
    linear_velocity_base_in_world: np.ndarray
    angular_velocity_base_in_base: np.ndarray
    contact_flags: list[bool]


class BaseStateSource(Protocol):
    """Gives the base state each tick."""

    def read(self) -> BaseReading:
        """The base state now."""
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


class SimulatorBase:
    """Ground truth of the simulated robot behind the emulated actuators.

    Feet are flagged in support as ``poise sim`` flags them: a touching
    foot once its normal force exceeds the threshold, until it lifts off.
    """

    def __init__(self, plant: Plant, support_force_threshold_N: float):
        self.plant = plant
        self.threshold_N = support_force_threshold_N
        self._flags = plant.backend.contact_flags()

    def read(self) -> BaseReading:
        """The simulated base and contacts now."""
        from clients.sim.runner import support_flags

        backend = self.plant.backend
        state = backend.state()
        self._flags = support_flags(
            self._flags,
            backend.contact_flags(),
            backend.contact_wrenches_in_world()[:, 2],
            self.threshold_N,
        )
        return BaseReading(
            state.position_base_in_world,
            state.orientation_base_in_world_xyzw,
            state.linear_velocity_base_in_world,
            state.angular_velocity_base_in_base,
            self._flags,
        )
