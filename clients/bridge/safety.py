"""What the bridge checks every tick before anything reaches an actuator.

Each check returns a *reason* (one line naming the joint and the value) or
``""``. A reason latches the safe state (:class:`SafetyLatch`) until the
operator re-arms; the bridge never leaves it on its own. What latches, and
what is only clamped and counted, is tabled in ``docs/bridge.md``:

- no valid command from the server within ``watchdog_s`` (:class:`Watchdog`);
- an actuator reporting a fault, or silent ``max_missed_replies`` ticks in a row;
- a joint outside its position limits or faster than its velocity limit;
- a motor at or above its temperature limit (below it, the torque limit is
  derated instead, :meth:`JointMap.derated_torque_limit_Nm`).

A command whose torques are not finite or not one per joint is refused
(:class:`InvalidCommand`, counted): the previous valid torques stay, and the
watchdog keeps running, so a server that only sends bad commands trips it.
Finite torques beyond the (derated) limit are clamped and counted.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from clients.bridge.actuator import MotorFeedback
from clients.bridge.joint_map import JointMap
from protocol.errors import PoiseError

__all__ = [
    "InvalidCommand",
    "SafetyLatch",
    "Watchdog",
    "check_feedback",
    "check_joints",
    "clamp_torque",
]


class InvalidCommand(PoiseError, ValueError):
    """A command from the server that must not reach an actuator."""


@dataclass
class Watchdog:
    """Time since the last valid command, against a limit (host side)."""

    timeout_s: float
    clock: Callable[[], float] = time.monotonic
    last_fed_s: float = 0.0

    def feed(self) -> None:
        """A valid command arrived now."""
        self.last_fed_s = self.clock()

    def remaining_s(self) -> float:
        """Time left before it expires (≤ 0: expired)."""
        return self.last_fed_s + self.timeout_s - self.clock()


@dataclass
class SafetyLatch:
    """The safe state, latched with its reason until the operator re-arms."""

    reason: str = ""
    latched_at_s: float = 0.0

    @property
    def latched(self) -> bool:
        """Whether the safe state holds."""
        return bool(self.reason)

    def trip(self, reason: str, now_s: float) -> bool:
        """Latch (keeping the first reason); True if this call latched it."""
        if self.reason:
            return False
        self.reason, self.latched_at_s = reason, now_s
        return True

    def rearm(self) -> str:
        """Release (the operator's decision); returns the reason it held."""
        reason, self.reason = self.reason, ""
        return reason


def clamp_torque(
    joint_torque: Sequence[float] | np.ndarray, limit_Nm: np.ndarray, names: Sequence[str]
) -> tuple[np.ndarray, list[str]]:
    """Torques within the limits, and the joints that were clamped.

    Raises:
        InvalidCommand: Not one torque per joint, or a torque is NaN or infinite.
    """
    torque = np.asarray(joint_torque, dtype=float)
    if torque.shape != limit_Nm.shape:
        raise InvalidCommand(
            f"joint_torque has {torque.size} entries, the robot {limit_Nm.size} joints"
        )
    bad = ~np.isfinite(torque)
    if bad.any():
        joints = [f"{names[i]}={torque[i]}" for i in np.flatnonzero(bad).tolist()]
        raise InvalidCommand(f"joint_torque is not finite at {', '.join(joints)}")
    over = np.abs(torque) > limit_Nm
    return np.clip(torque, -limit_Nm, limit_Nm), [names[i] for i in np.flatnonzero(over).tolist()]


def check_joints(
    joint_map: JointMap,
    position_rad: np.ndarray,
    velocity_rad_s: np.ndarray,
    temperature_C: np.ndarray,
    margin_rad: float = 0.0,
) -> str:
    """The first joint out of its position, velocity or temperature limit, as a reason.

    A position counts as out once it is beyond a limit by more than
    ``margin_rad`` (encoder quantization puts a joint resting on its end stop
    a hair outside).
    """
    names = joint_map.names
    for i in np.flatnonzero(
        (position_rad < joint_map.position_lower_rad - margin_rad)
        | (position_rad > joint_map.position_upper_rad + margin_rad)
    ):
        return (
            f"{names[i]} at {position_rad[i]:.3f} rad is outside its limits "
            f"[{joint_map.position_lower_rad[i]:.3f}, {joint_map.position_upper_rad[i]:.3f}]"
        )
    for i in np.flatnonzero(np.abs(velocity_rad_s) > joint_map.velocity_limit_rad_s):
        return (
            f"{names[i]} at {velocity_rad_s[i]:.2f} rad/s is faster than its limit "
            f"{joint_map.velocity_limit_rad_s[i]:.2f} rad/s"
        )
    for i in np.flatnonzero(temperature_C >= joint_map.temperature_limit_C):
        return (
            f"{names[i]}'s motor at {temperature_C[i]:.0f} °C reached its limit "
            f"{joint_map.temperature_limit_C[i]:.0f} °C"
        )
    return ""


def check_feedback(
    joint_map: JointMap,
    feedback: Sequence[MotorFeedback | None],
    missed_in_a_row: np.ndarray,
    max_missed_replies: int,
) -> str:
    """Count silent actuators (in place) and name the first fault or long silence."""
    for i, reply in enumerate(feedback):
        missed_in_a_row[i] = missed_in_a_row[i] + 1 if reply is None else 0
    for i, reply in enumerate(feedback):
        ref = joint_map.actuators[i]
        if reply is not None and reply.fault:
            return (
                f"{ref.joint}'s actuator (bus {ref.bus!r}, id {ref.id}) reports a fault: "
                f"{reply.fault} (code {reply.fault_code:#x})"
            )
        if missed_in_a_row[i] >= max_missed_replies:
            return (
                f"{ref.joint}'s actuator (bus {ref.bus!r}, id {ref.id}) did not answer "
                f"{int(missed_in_a_row[i])} ticks in a row"
            )
    return ""
