"""What every actuator bus offers the bridge, whatever its protocol.

An :class:`ActuatorBus` is all the actuators on one bus (a CAN channel, or
a Dynamixel serial port) that speak one protocol. The bridge only talks to
actuators through this interface; it speaks the motor's side of the gearing
in SI units (rad, rad/s, N·m) and leaves gear ratio, direction and zero
offset to the actuator map. Every protocol implements the same verbs, and
one conformance suite (``tests/clients/bridge/test_bus_conformance.py``)
runs over all of them against their emulators.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

from protocol.errors import PoiseError

__all__ = ["ZERO_COMMAND", "ActuatorBus", "BusError", "MotorCommand", "MotorFeedback"]


class BusError(PoiseError, ConnectionError):
    """A bus could not be used: interface down, send buffer full, port gone.

    Attributes:
        bus: The bus's name (from the actuator map).
        detail: What failed and what to check.
    """

    def __init__(self, bus: str, detail: str):
        self.bus = bus
        self.detail = detail
        super().__init__(f"bus {bus!r}: {detail}")


@dataclass(frozen=True)
class MotorCommand:
    """One actuator's command on the motor side, SI units.

    The torque the motor makes is the MIT-mode law
    ``kp (position − p) + kd (velocity − v) + torque`` (p, v measured);
    torque-only protocols (ODrive torque control, Dynamixel current control)
    use ``torque_Nm`` alone and need ``kp = kd = 0``.
    """

    position_rad: float = 0.0
    velocity_rad_s: float = 0.0
    kp_Nm_per_rad: float = 0.0
    kd_Nm_s_per_rad: float = 0.0
    torque_Nm: float = 0.0


ZERO_COMMAND = MotorCommand()
"""No stiffness, no damping, no torque: the command sent before enabling."""


@dataclass(frozen=True)
class MotorFeedback:
    """What one actuator reported, motor side, SI units.

    Attributes:
        position_rad: Rotor (or protocol output) position.
        velocity_rad_s: Its velocity.
        torque_Nm: Torque the actuator estimates it makes (from its current).
        temperature_C: Hottest temperature it reports (winding, MOSFET or
            case), ``None`` if the protocol reports none.
        fault: The actuator's fault in words (``""``: none), e.g.
            ``"MOSFET over-temperature"``.
        fault_code: The protocol's raw fault code (0: none).
    """

    position_rad: float
    velocity_rad_s: float
    torque_Nm: float
    temperature_C: float | None = None
    fault: str = ""
    fault_code: int = 0


class ActuatorBus(Protocol):
    """The actuators of one bus and one protocol, keyed by their bus id.

    Every method that waits has a timeout (the bus's reply timeout) and
    raises :class:`BusError` only when the bus itself fails; an actuator that
    does not answer gives ``None`` in the returned mapping, never an
    exception.
    """

    name: str
    actuator_ids: tuple[int, ...]

    def exchange(self, commands: Mapping[int, MotorCommand]) -> dict[int, MotorFeedback | None]:
        """Send each actuator its command and return what each reported.

        Reads as it writes: the feedback is the newest each actuator sent
        in reply within the bus's timeout (``None``: nothing valid came).
        Commands are clamped to the protocol's ranges before packing.
        """
        ...

    def enable(self) -> None:
        """Start applying commands (motor mode, closed loop, torque on).

        The bridge calls it only after an :meth:`exchange` of
        :data:`ZERO_COMMAND` read every position, so enabling cannot kick.
        """
        ...

    def arm_watchdog(self, timeout_s: float) -> None:
        """Arm the actuators' own command watchdogs, where the protocol has one.

        An actuator that hears no command for ``timeout_s`` then stops by
        itself (Damiao timeout register, ODrive axis watchdog, Dynamixel Bus
        Watchdog); a protocol without one (bgkatz MIT firmware, set over its
        serial menu only) does nothing.
        """
        ...

    def hold_safe(
        self, damping_Nm_s_per_rad: Mapping[int, float]
    ) -> dict[int, MotorFeedback | None]:
        """Command the safe state and return the feedback, like :meth:`exchange`.

        MIT and Damiao: ``kp = 0``, ``kd`` = the given damping, ``τ = 0``
        (the joint is a damper); Dynamixel: zero goal current; ODrive: axis
        idle. Called every tick while the bridge is latched safe.
        """
        ...

    def clear_faults(self) -> None:
        """Clear latched actuator faults where the protocol can (Damiao, ODrive)."""
        ...

    def disable(self) -> None:
        """Stop applying commands (exit motor mode, idle, torque off)."""
        ...

    def close(self) -> None:
        """Release the bus (the bridge disables first)."""
        ...
