"""Dynamixel X-series control table: register addresses, sizes, signedness and units.

The X-series control table (addresses, sizes, units) is from the ROBOTIS
e-Manual's model pages (``docs/en/dxl/x/xm430-w350.md``, ``xm540-w270.md``,
``xh430-w350.md``, ``xh540-w270.md``, source ``ROBOTIS-GIT/emanual``); the
four models share it. Here too: the values of Operating Mode (11), the bits
of Hardware Error Status (70), register values as the little-endian bytes a
packet carries, the per-tick feedback read (Present Current (126) to Present
Temperature (146)) and the Bus Watchdog (98) value for a timeout. Imported
through :mod:`clients.bridge.protocols.dynamixel`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from clients.bridge.protocols.dynamixel_packets import CommandError, PacketError

__all__ = [
    "BUS_WATCHDOG_UNIT_S",
    "CURRENT_UNIT_A",
    "EEPROM_END",
    "FEEDBACK_LENGTH_BYTES",
    "FEEDBACK_START",
    "POSITION_UNIT_RAD",
    "REGISTER_SIZE_BYTES",
    "RETURN_DELAY_UNIT_S",
    "SIGNED_REGISTERS",
    "VELOCITY_UNIT_RAD_S",
    "ControlTable",
    "Feedback",
    "HardwareError",
    "OperatingMode",
    "decode_feedback",
    "describe_hardware_error",
    "pack_register",
    "unpack_register",
    "watchdog_register_from_timeout",
]


# --------------------------------------------------------------------------- control table


class HardwareError(IntFlag):
    """Hardware Error Status (70) bits of the X series (e-Manual, Shutdown(63)).

    Any of them clears Torque Enable and sets the status packets' alert bit;
    only a REBOOT (or power cycle) clears them.
    """

    INPUT_VOLTAGE = 0x01
    OVERHEATING = 0x04
    MOTOR_ENCODER = 0x08
    ELECTRICAL_SHOCK = 0x10
    OVERLOAD = 0x20


_HARDWARE_ERROR_TEXT = {
    HardwareError.INPUT_VOLTAGE: "input voltage error",
    HardwareError.OVERHEATING: "overheating error",
    HardwareError.MOTOR_ENCODER: "motor encoder error",
    HardwareError.ELECTRICAL_SHOCK: "electrical shock error",
    HardwareError.OVERLOAD: "overload error",
}


def describe_hardware_error(bits: int) -> str:
    """Hardware Error Status in words, e.g. ``"overheating error, overload error"``.

    Args:
        bits: The register's value (0: ``""``); unknown bits are named by value.
    """
    words = [text for flag, text in _HARDWARE_ERROR_TEXT.items() if bits & flag]
    unknown = bits & ~sum(_HARDWARE_ERROR_TEXT) & 0xFF
    if unknown:
        words.append(f"unknown hardware error bits 0x{unknown:02X}")
    return ", ".join(words)


class OperatingMode(IntEnum):
    """Operating Mode (11) values of the X series (e-Manual, Operating Mode)."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


class ControlTable(IntEnum):
    """X-series (XM430/XH430/XM540/XH540) control table addresses.

    EEPROM area below 64 (writable only with Torque Enable 0), RAM from 64.
    Source: e-Manual, ``docs/en/dxl/x/xm430-w350.md`` and ``xm540-w270.md``,
    Control Table of EEPROM Area / RAM Area.
    """

    MODEL_NUMBER = 0
    MODEL_INFORMATION = 2
    FIRMWARE_VERSION = 6
    ID = 7
    BAUD_RATE = 8
    RETURN_DELAY_TIME = 9
    DRIVE_MODE = 10
    OPERATING_MODE = 11
    SECONDARY_ID = 12
    PROTOCOL_TYPE = 13
    HOMING_OFFSET = 20
    MOVING_THRESHOLD = 24
    TEMPERATURE_LIMIT = 31
    MAX_VOLTAGE_LIMIT = 32
    MIN_VOLTAGE_LIMIT = 34
    PWM_LIMIT = 36
    CURRENT_LIMIT = 38
    VELOCITY_LIMIT = 44
    MAX_POSITION_LIMIT = 48
    MIN_POSITION_LIMIT = 52
    SHUTDOWN = 63
    TORQUE_ENABLE = 64
    LED = 65
    STATUS_RETURN_LEVEL = 68
    REGISTERED_INSTRUCTION = 69
    HARDWARE_ERROR_STATUS = 70
    VELOCITY_I_GAIN = 76
    VELOCITY_P_GAIN = 78
    POSITION_D_GAIN = 80
    POSITION_I_GAIN = 82
    POSITION_P_GAIN = 84
    FEEDFORWARD_2ND_GAIN = 88
    FEEDFORWARD_1ST_GAIN = 90
    BUS_WATCHDOG = 98
    GOAL_PWM = 100
    GOAL_CURRENT = 102
    GOAL_VELOCITY = 104
    PROFILE_ACCELERATION = 108
    PROFILE_VELOCITY = 112
    GOAL_POSITION = 116
    REALTIME_TICK = 120
    MOVING = 122
    MOVING_STATUS = 123
    PRESENT_PWM = 124
    PRESENT_CURRENT = 126
    PRESENT_VELOCITY = 128
    PRESENT_POSITION = 132
    VELOCITY_TRAJECTORY = 136
    POSITION_TRAJECTORY = 140
    PRESENT_INPUT_VOLTAGE = 144
    PRESENT_TEMPERATURE = 146


EEPROM_END = 64
"""First RAM address: below it, writes need Torque Enable 0 (e-Manual, Control Table caution)."""

REGISTER_SIZE_BYTES: Mapping[ControlTable, int] = {
    **{reg: 1 for reg in ControlTable},
    ControlTable.MODEL_NUMBER: 2,
    ControlTable.MODEL_INFORMATION: 4,
    ControlTable.HOMING_OFFSET: 4,
    ControlTable.MOVING_THRESHOLD: 4,
    ControlTable.MAX_VOLTAGE_LIMIT: 2,
    ControlTable.MIN_VOLTAGE_LIMIT: 2,
    ControlTable.PWM_LIMIT: 2,
    ControlTable.CURRENT_LIMIT: 2,
    ControlTable.VELOCITY_LIMIT: 4,
    ControlTable.MAX_POSITION_LIMIT: 4,
    ControlTable.MIN_POSITION_LIMIT: 4,
    ControlTable.VELOCITY_I_GAIN: 2,
    ControlTable.VELOCITY_P_GAIN: 2,
    ControlTable.POSITION_D_GAIN: 2,
    ControlTable.POSITION_I_GAIN: 2,
    ControlTable.POSITION_P_GAIN: 2,
    ControlTable.FEEDFORWARD_2ND_GAIN: 2,
    ControlTable.FEEDFORWARD_1ST_GAIN: 2,
    ControlTable.GOAL_PWM: 2,
    ControlTable.GOAL_CURRENT: 2,
    ControlTable.GOAL_VELOCITY: 4,
    ControlTable.PROFILE_ACCELERATION: 4,
    ControlTable.PROFILE_VELOCITY: 4,
    ControlTable.GOAL_POSITION: 4,
    ControlTable.REALTIME_TICK: 2,
    ControlTable.PRESENT_PWM: 2,
    ControlTable.PRESENT_CURRENT: 2,
    ControlTable.PRESENT_VELOCITY: 4,
    ControlTable.PRESENT_POSITION: 4,
    ControlTable.VELOCITY_TRAJECTORY: 4,
    ControlTable.POSITION_TRAJECTORY: 4,
    ControlTable.PRESENT_INPUT_VOLTAGE: 2,
}
"""Size of every register in bytes (e-Manual, Size(Byte) column)."""

SIGNED_REGISTERS = frozenset(
    {
        ControlTable.HOMING_OFFSET,
        ControlTable.BUS_WATCHDOG,
        ControlTable.GOAL_PWM,
        ControlTable.GOAL_CURRENT,
        ControlTable.GOAL_VELOCITY,
        ControlTable.GOAL_POSITION,
        ControlTable.PRESENT_PWM,
        ControlTable.PRESENT_CURRENT,
        ControlTable.PRESENT_VELOCITY,
        ControlTable.PRESENT_POSITION,
        ControlTable.VELOCITY_TRAJECTORY,
        ControlTable.POSITION_TRAJECTORY,
    }
)
"""Registers holding two's-complement values (Bus Watchdog reads −1 after it fired)."""

CURRENT_UNIT_A = 2.69e-3
"""Goal/Present Current unit, "about 2.69 [mA]" (e-Manual, Goal Current(102))."""

VELOCITY_UNIT_RAD_S = 0.229 * 2.0 * math.pi / 60.0
"""Present Velocity unit, 0.229 rev/min (e-Manual, Present Velocity(128))."""

POSITION_UNIT_RAD = 2.0 * math.pi / 4096.0
"""Present Position unit, 1 pulse of 4096 per revolution (e-Manual, Resolution)."""

BUS_WATCHDOG_UNIT_S = 0.020
"""Bus Watchdog (98) unit, 20 ms; 1–127 arm it, 0 disarms and clears its error (e-Manual)."""

RETURN_DELAY_UNIT_S = 2e-6
"""Return Delay Time (9) unit, 2 µs; the X-series default 250 is 500 µs (e-Manual)."""

TEMPERATURE_UNIT_C = 1.0
"""Present Temperature (146) unit, 1 °C."""

INPUT_VOLTAGE_UNIT_V = 0.1
"""Present Input Voltage (144) unit, 0.1 V."""


# --------------------------------------------------------------------------- registers


def pack_register(register: ControlTable, value: int) -> bytes:
    """A register value as little-endian bytes of its size (two's complement if signed)."""
    size = REGISTER_SIZE_BYTES[register]
    signed = register in SIGNED_REGISTERS
    try:
        return int(value).to_bytes(size, "little", signed=signed)
    except OverflowError as error:
        raise PacketError(
            "params", f"{register.name}={value} does not fit {size} byte(s)"
        ) from error


def unpack_register(register: ControlTable, data: bytes | bytearray) -> int:
    """A register value from its little-endian bytes."""
    return int.from_bytes(
        bytes(data[: REGISTER_SIZE_BYTES[register]]), "little", signed=register in SIGNED_REGISTERS
    )


FEEDBACK_START = ControlTable.PRESENT_CURRENT
"""The per-tick sync read starts at Present Current (126) …"""

FEEDBACK_LENGTH_BYTES = ControlTable.PRESENT_TEMPERATURE + 1 - ControlTable.PRESENT_CURRENT
"""… and runs to Present Temperature (146): 21 bytes, one contiguous read per servo."""


@dataclass(frozen=True)
class Feedback:
    """What one servo's feedback read holds, in register units.

    Attributes:
        current_units: Present Current (2.69 mA).
        velocity_units: Present Velocity (0.229 rev/min).
        position_pulses: Present Position (4096 per turn, output shaft).
        input_voltage_units: Present Input Voltage (0.1 V).
        temperature_C: Present Temperature (°C).
    """

    current_units: int
    velocity_units: int
    position_pulses: int
    input_voltage_units: int
    temperature_C: int


def decode_feedback(data: bytes) -> Feedback:
    """Decode the 21 bytes read from Present Current (126) to Present Temperature (146)."""
    if len(data) != FEEDBACK_LENGTH_BYTES:
        raise PacketError("params", f"{len(data)} feedback bytes, expected {FEEDBACK_LENGTH_BYTES}")

    def at(register: ControlTable) -> int:
        offset = register - FEEDBACK_START
        return unpack_register(register, data[offset : offset + REGISTER_SIZE_BYTES[register]])

    return Feedback(
        current_units=at(ControlTable.PRESENT_CURRENT),
        velocity_units=at(ControlTable.PRESENT_VELOCITY),
        position_pulses=at(ControlTable.PRESENT_POSITION),
        input_voltage_units=at(ControlTable.PRESENT_INPUT_VOLTAGE),
        temperature_C=at(ControlTable.PRESENT_TEMPERATURE),
    )


def watchdog_register_from_timeout(timeout_s: float) -> int:
    """Bus Watchdog (98) value for a timeout: units of 20 ms, rounded up, 1–127.

    Raises:
        CommandError: ``timeout_s`` not finite and positive, or over 2.54 s.
    """
    if not (math.isfinite(timeout_s) and timeout_s > 0.0):
        raise CommandError(-1, "timeout_s", f"{timeout_s=} must be finite and > 0")
    units = max(1, math.ceil(timeout_s / BUS_WATCHDOG_UNIT_S - 1e-9))
    if units > 127:
        raise CommandError(-1, "timeout_s", f"{timeout_s=} exceeds 127 × 20 ms = 2.54 s")
    return units
