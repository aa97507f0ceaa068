"""The physics every emulated actuator shares, whatever protocol it speaks."""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import can

from clients.bridge.actuator import ZERO_COMMAND, MotorCommand

__all__ = [
    "RECEIVED_LOG_LENGTH",
    "CanDevice",
    "CanDeviceHost",
    "EmulatedMotor",
    "ReceivedCommand",
]


RECEIVED_LOG_LENGTH = 1000
"""Commands each emulated motor remembers (2 s at 500 Hz).

Bounded so that a long emulated run neither grows nor makes the garbage
collector walk millions of records (an 80 ms pause, seen, misses replies).
"""


@dataclass(frozen=True)
class ReceivedCommand:
    """A command an emulated motor took, and when (``time.monotonic`` s)."""

    time_s: float
    kind: str
    """What it was: ``"command"``, ``"safe"`` (no stiffness, no torque), ``"enable"``,
    ``"disable"``, ``"watchdog"`` (its own watchdog stopped it)."""
    command: MotorCommand = ZERO_COMMAND


@dataclass
class EmulatedMotor:
    """A torque source on one joint, motor side, as its firmware runs it.

    The plant calls :meth:`sense` with the joint's motor-side position and
    velocity after every physics step and applies :meth:`torque_Nm`. While
    enabled the motor makes the MIT-mode law of its last command, clamped to
    ``torque_limit_Nm``; disabled, faulted or stopped by its watchdog, it
    makes none.

    Attributes:
        torque_limit_Nm: Peak torque the motor can make.
        continuous_torque_Nm: Torque it can hold for ever (default: a third
            of the peak, typical of the actuators emulated here).
        temperature_rise_at_continuous_K: Winding temperature rise above
            ambient, at steady state, holding ``continuous_torque_Nm``. Copper
            losses go with the square of the current, so with ``τ²``.
        thermal_time_constant_s: How fast the winding heats up (first order).
        torque_constant_Nm_per_A: Torque per ampere (the current it reports).
        clock: Time source of its watchdog and of ``received`` (``time.monotonic``).
    """

    torque_limit_Nm: float
    continuous_torque_Nm: float = 0.0
    temperature_rise_at_continuous_K: float = 60.0
    thermal_time_constant_s: float = 60.0
    torque_constant_Nm_per_A: float = 0.1
    ambient_C: float = 25.0
    clock: Callable[[], float] = time.monotonic
    position_rad: float = 0.0
    velocity_rad_s: float = 0.0
    temperature_C: float = 25.0
    enabled: bool = False
    command: MotorCommand = ZERO_COMMAND
    silent: bool = False
    """Fault injection: the motor answers nothing (a cut wire, a dead node)."""
    fault_code: int = 0
    """Latched fault (protocol's code); a faulted motor makes no torque."""
    watchdog_timeout_s: float = 0.0
    """Its own command watchdog (0: off)."""
    received: deque[ReceivedCommand] = field(
        default_factory=lambda: deque(maxlen=RECEIVED_LOG_LENGTH)
    )
    """The newest commands it took, oldest first (a ring: a long run stays small)."""
    _last_command_s: float = 0.0
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def sense(self, position_rad: float, velocity_rad_s: float) -> None:
        """The joint's motor-side position and velocity now."""
        with self._lock:
            self.position_rad = position_rad
            self.velocity_rad_s = velocity_rad_s

    def take(self, command: MotorCommand, kind: str = "command") -> None:
        """A command arrived (the protocol layer decoded and quantized it)."""
        now = self.clock()
        with self._lock:
            self.command = command
            self._last_command_s = now
            self.received.append(ReceivedCommand(now, kind, command))

    def set_enabled(self, enabled: bool) -> None:
        """Motor mode on or off (off also drops the command)."""
        now = self.clock()
        with self._lock:
            self.enabled = enabled
            self.command = ZERO_COMMAND
            self._last_command_s = now
            self.received.append(ReceivedCommand(now, "enable" if enabled else "disable"))

    def watchdog_expired(self) -> bool:
        """Whether its own watchdog stopped it (and record that once)."""
        if not (self.enabled and self.watchdog_timeout_s > 0.0):
            return False
        now = self.clock()
        if now - self._last_command_s <= self.watchdog_timeout_s:
            return False
        with self._lock:
            self.enabled = False
            self.command = ZERO_COMMAND
            self.received.append(ReceivedCommand(now, "watchdog"))
        return True

    def torque_Nm(self) -> float:
        """Torque it makes now (motor side)."""
        self.watchdog_expired()
        with self._lock:
            if not self.enabled or self.fault_code:
                return 0.0
            c = self.command
            torque = (
                c.kp_Nm_per_rad * (c.position_rad - self.position_rad)
                + c.kd_Nm_s_per_rad * (c.velocity_rad_s - self.velocity_rad_s)
                + c.torque_Nm
            )
        return max(-self.torque_limit_Nm, min(self.torque_limit_Nm, torque))

    def heat(self, torque_Nm: float, duration_s: float) -> None:
        """Advance the winding temperature: copper losses in, conduction out."""
        continuous = self.continuous_torque_Nm or self.torque_limit_Nm / 3.0
        steady_C = (
            self.ambient_C + self.temperature_rise_at_continuous_K * (torque_Nm / continuous) ** 2
        )
        self.temperature_C += (steady_C - self.temperature_C) * min(
            1.0, duration_s / self.thermal_time_constant_s
        )


class CanDevice:
    """An emulated device on a CAN bus: frames in, reply frames out."""

    def on_frame(self, message: can.Message) -> list[can.Message]:
        """Replies to ``message`` (empty if it is not addressed to this device)."""
        raise NotImplementedError


class CanDeviceHost:
    """Serves emulated CAN devices on one python-can bus from a thread.

    Every frame received goes to every device; their replies are sent after
    ``reply_delay_s`` (a real actuator answers 100–300 µs after a command).
    Use as a context manager: the thread starts on entry and stops on exit.
    """

    def __init__(self, bus: can.BusABC, devices: list[CanDevice], reply_delay_s: float = 0.0):
        self.bus = bus
        self.devices = devices
        self.reply_delay_s = reply_delay_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="can-emulator", daemon=True)

    def __enter__(self) -> CanDeviceHost:
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _serve(self) -> None:
        while not self._stop.is_set():
            message = self.bus.recv(timeout=0.05)
            if message is None:
                continue
            replies = [reply for device in self.devices for reply in device.on_frame(message)]
            if replies and self.reply_delay_s > 0.0:
                time.sleep(self.reply_delay_s)
            for reply in replies:
                self.bus.send(reply)
