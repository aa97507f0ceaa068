"""Dynamixel Protocol 2.0 for the X series: packets, control table and torque map.

The pure part builds and parses packets byte for byte as the ROBOTIS e-Manual
specifies them (https://emanual.robotis.com/docs/en/dxl/protocol2/, source
``ROBOTIS-GIT/emanual`` ``docs/en/dxl/protocol2.md``)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM … | CRC_L CRC_H

``LEN`` counts the instruction, the parameters (after byte stuffing) and the
CRC; a status packet's first parameter is its error byte. The CRC is CRC-16
with polynomial 0x8005 (x¹⁶ + x¹⁵ + x² + 1), initial value 0, not reflected,
over every byte from the header to the last parameter (CRC-16/BUYPASS). Byte
stuffing inserts ``FD`` after each ``FF FF FD`` in the instruction and
parameters, so that a header never appears inside a packet.

The X-series control table (addresses, sizes, units) is from the e-Manual's
model pages (``docs/en/dxl/x/xm430-w350.md``, ``xm540-w270.md``,
``xh430-w350.md``, ``xh540-w270.md``); the torque ↔ current map per model is
from their stall-torque specifications (``docs/en/dxl/x/x.md``), see
:class:`DynamixelModel`.

The I/O part, :class:`~clients.bridge.protocols.dynamixel_bus.DynamixelBus`,
is in ``dynamixel_bus.py``.

dynamixel-sdk 4.1.0 caveats found while testing against it: its Python
``txPacket`` discards ``addStuffing``'s result, so a packet that needs stuffing
goes out unstuffed (the bus never sends an ``FF FF FD`` run: Goal Current
sync writes put an ID ≤ 0xFC after every two data bytes); its GroupSyncRead
stops at the first missing status packet and its ``readRx`` discards other
IDs' packets while waiting, so the bus collects the sync-read replies itself.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from protocol.errors import PoiseError

__all__ = [
    "ALERT_BIT",
    "BROADCAST_ID",
    "BUS_WATCHDOG_UNIT_S",
    "CURRENT_UNIT_A",
    "DYNAMIXEL_MODELS",
    "EEPROM_END",
    "FEEDBACK_LENGTH_BYTES",
    "FEEDBACK_START",
    "HEADER",
    "MAX_ID",
    "POSITION_UNIT_RAD",
    "REGISTER_SIZE_BYTES",
    "RETURN_DELAY_UNIT_S",
    "SIGNED_REGISTERS",
    "VELOCITY_UNIT_RAD_S",
    "CommandError",
    "ControlTable",
    "DynamixelError",
    "DynamixelModel",
    "Feedback",
    "HardwareError",
    "Instruction",
    "OperatingMode",
    "Packet",
    "PacketError",
    "PacketReader",
    "StatusError",
    "crc16",
    "current_from_torque",
    "decode_feedback",
    "describe_hardware_error",
    "get_model",
    "goal_current_from_torque",
    "make_packet",
    "make_ping",
    "make_read",
    "make_reboot",
    "make_status",
    "make_sync_read",
    "make_sync_write",
    "make_write",
    "pack_register",
    "parse_packet",
    "stuff",
    "torque_from_current",
    "unpack_register",
    "unstuff",
    "watchdog_register_from_timeout",
]


# --------------------------------------------------------------------------- codes

HEADER = b"\xff\xff\xfd\x00"
"""Header 1–3 and Reserved (e-Manual, Protocol 2.0, Instruction Packet)."""

BROADCAST_ID = 0xFE
"""Every device executes it; READ and WRITE get no status (e-Manual, Packet ID)."""

MAX_ID = 0xFC
"""Highest device ID (0–252; 253 and 255 are never IDs, they look like the header)."""

MAX_PACKET_LENGTH = 1024
"""Longest LEN this module accepts (the SDK's RXPACKET_MAX_LEN): longer is garbage."""

ALERT_BIT = 0x80
"""Bit 7 of a status packet's error byte: the device has a hardware error (e-Manual, Error)."""


class Instruction(IntEnum):
    """Protocol 2.0 instructions (e-Manual, Protocol 2.0, Instruction)."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    BULK_READ = 0x92
    BULK_WRITE = 0x93


class StatusError(IntEnum):
    """Error number in bits 0–6 of a status packet's error byte (e-Manual, Error)."""

    description: str

    def __new__(cls, value: int, description: str) -> StatusError:  # noqa: D102
        member = int.__new__(cls, value)
        member._value_ = value
        member.description = description
        return member

    NONE = 0x00, "no error"
    RESULT_FAIL = 0x01, "result fail: the instruction could not be processed"
    INSTRUCTION = 0x02, "instruction error: undefined instruction, or Action without Reg Write"
    CRC = 0x03, "CRC error: the packet's CRC does not match"
    DATA_RANGE = 0x04, "data range error: value outside the register's range (or goal read-only)"
    DATA_LENGTH = 0x05, "data length error: fewer bytes than the register holds"
    DATA_LIMIT = 0x06, "data limit error: value beyond the register's limit"
    ACCESS = 0x07, "access error: read-only/undefined address, or EEPROM written with torque on"


_STATUS_BY_NUMBER: dict[int, StatusError] = {int(error): error for error in StatusError}


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


# --------------------------------------------------------------------------- errors


class DynamixelError(PoiseError):
    """Base class of this module's errors."""


class PacketError(DynamixelError, ValueError):
    """Bytes that are not one valid Protocol 2.0 packet.

    Attributes:
        field: What is wrong (``"header"``, ``"length"``, ``"crc"``, ``"id"``, …).
        detail: The bad value and what was expected.
        packet_id: The packet's ID when it could be read (``-1`` otherwise), so
            a device can answer a CRC error to the right sender.
        data: The offending bytes.
    """

    def __init__(self, field: str, detail: str, packet_id: int = -1, data: bytes = b""):
        self.field = field
        self.detail = detail
        self.packet_id = packet_id
        self.data = bytes(data)
        super().__init__(f"bad Dynamixel packet ({field}): {detail}")


class CommandError(DynamixelError, ValueError):
    """A command this protocol cannot send (non-finite value, MIT gains, unknown servo).

    Attributes:
        servo_id: The servo it was for (``-1``: none in particular).
        field: The offending field (``"torque_Nm"``, ``"kp_Nm_per_rad"``, ``"model"``, …).
        detail: The bad value and what to do instead.
    """

    def __init__(self, servo_id: int, field: str, detail: str):
        self.servo_id = servo_id
        self.field = field
        self.detail = detail
        super().__init__(f"servo {servo_id} {field}: {detail}")


# --------------------------------------------------------------------------- CRC, stuffing


def _make_crc_table(polynomial: int) -> tuple[int, ...]:
    """CRC-16 lookup table, MSB first (one entry per leading byte)."""
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ polynomial) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _make_crc_table(0x8005)


def crc16(data: bytes, crc: int = 0) -> int:
    """CRC-16 of Protocol 2.0 (poly 0x8005, init 0, MSB first, no final XOR).

    Table driven, as the e-Manual's CRC page (``/docs/en/dxl/crc/``) describes.

    Args:
        data: Bytes from Header 1 to the last parameter.
        crc: Running value to continue from (0 for a new packet).
    """
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ _CRC_TABLE[((crc >> 8) ^ byte) & 0xFF]
    return crc


_STUFF_PATTERN = b"\xff\xff\xfd"


def stuff(body: bytes) -> bytes:
    """Add byte stuffing: ``FF FF FD`` becomes ``FF FF FD FD`` (e-Manual, Packet Process).

    Args:
        body: Instruction and parameters (the range that is stuffed).
    """
    if _STUFF_PATTERN not in body:
        return bytes(body)
    out = bytearray()
    for i, byte in enumerate(body):
        out.append(byte)
        if byte == 0xFD and i >= 2 and body[i - 2] == 0xFF and body[i - 1] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove byte stuffing: the ``FD`` after each ``FF FF FD`` is dropped.

    Args:
        body: Stuffed instruction and parameters.

    Raises:
        PacketError: A ``FF FF FD`` without its stuffing byte (not made by :func:`stuff`).
    """
    if _STUFF_PATTERN not in body:
        return bytes(body)
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        i += 1
        if len(out) >= 3 and out[-3:] == _STUFF_PATTERN:
            if i >= len(body) or body[i] != 0xFD:
                raise PacketError("stuffing", f"FF FF FD not followed by FD in {body.hex(' ')}")
            i += 1
    return bytes(out)


# --------------------------------------------------------------------------- packets


@dataclass(frozen=True)
class Packet:
    """One Protocol 2.0 packet, unstuffed.

    Attributes:
        packet_id: Device ID (0–252) or :data:`BROADCAST_ID`.
        instruction: The instruction (``STATUS`` for a device's reply).
        params: Parameters after the error byte, unstuffed.
        error: A status packet's error byte (alert bit and :class:`StatusError`);
            0 for instruction packets.
    """

    packet_id: int
    instruction: int
    params: bytes = b""
    error: int = 0

    @property
    def is_status(self) -> bool:
        """Whether it is a device's reply."""
        return self.instruction == Instruction.STATUS

    @property
    def alert(self) -> bool:
        """Whether the device reports a hardware error (read Hardware Error Status)."""
        return bool(self.error & ALERT_BIT)

    @property
    def status_error(self) -> StatusError | int:
        """The error number without the alert bit (an int if it is not a known one)."""
        number = self.error & 0x7F
        return _STATUS_BY_NUMBER.get(number, number)


def _check_id(packet_id: int, *, broadcast: bool = True) -> None:
    if not (0 <= packet_id <= MAX_ID or (broadcast and packet_id == BROADCAST_ID)):
        raise PacketError("id", f"packet_id={packet_id} is not 0–252 (or 254, broadcast)")


def make_packet(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """One packet: header, ID, length, stuffed instruction and parameters, CRC.

    Args:
        packet_id: Device ID 0–252, or 254 (broadcast).
        instruction: An :class:`Instruction` value.
        params: Parameters as they are (stuffed here); a status packet's
            first parameter is its error byte.
    """
    _check_id(packet_id)
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    if length > MAX_PACKET_LENGTH:
        raise PacketError("length", f"LEN={length} exceeds {MAX_PACKET_LENGTH}")
    raw = HEADER + bytes([packet_id]) + length.to_bytes(2, "little") + body
    return raw + crc16(raw).to_bytes(2, "little")


def make_status(packet_id: int, error: int = 0, params: bytes = b"") -> bytes:
    """A device's status packet (instruction 0x55, error byte, parameters)."""
    _check_id(packet_id, broadcast=False)
    return make_packet(packet_id, Instruction.STATUS, bytes([error]) + bytes(params))


def make_ping(packet_id: int) -> bytes:
    """PING: the device answers model number (2 B) and firmware version (1 B)."""
    return make_packet(packet_id, Instruction.PING)


def make_read(packet_id: int, address: int, length: int) -> bytes:
    """READ ``length`` bytes from ``address``."""
    return make_packet(
        packet_id, Instruction.READ, address.to_bytes(2, "little") + length.to_bytes(2, "little")
    )


def make_write(packet_id: int, address: int, data: bytes) -> bytes:
    """WRITE ``data`` at ``address`` (little-endian values, see :func:`pack_register`)."""
    return make_packet(packet_id, Instruction.WRITE, address.to_bytes(2, "little") + bytes(data))


def make_reboot(packet_id: int) -> bytes:
    """REBOOT: the device answers, then restarts (clears Hardware Error Status)."""
    return make_packet(packet_id, Instruction.REBOOT)


def make_sync_read(address: int, length: int, ids: Iterable[int]) -> bytes:
    """SYNC READ the same ``length`` bytes at ``address`` from each ID, in the given order.

    Each device answers with its own status packet, in the order of ``ids``.
    """
    id_bytes = bytes(ids)
    for packet_id in id_bytes:
        _check_id(packet_id, broadcast=False)
    params = address.to_bytes(2, "little") + length.to_bytes(2, "little") + id_bytes
    return make_packet(BROADCAST_ID, Instruction.SYNC_READ, params)


def make_sync_write(address: int, length: int, data: Mapping[int, bytes]) -> bytes:
    """SYNC WRITE ``length`` bytes at ``address`` on each device (no status packet).

    Args:
        address: First register address.
        length: Bytes per device.
        data: ID → exactly ``length`` bytes, in the order sent.
    """
    params = bytearray(address.to_bytes(2, "little") + length.to_bytes(2, "little"))
    for packet_id, values in data.items():
        _check_id(packet_id, broadcast=False)
        if len(values) != length:
            raise PacketError(
                "params", f"servo {packet_id}: {len(values)} bytes, sync write needs {length}"
            )
        params.append(packet_id)
        params.extend(values)
    return make_packet(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def _parse_one(data: bytes) -> Packet:
    """Parse one complete packet starting at a header; ``data`` is exactly that packet."""
    packet_id = data[4]
    length = int.from_bytes(data[5:7], "little")
    if len(data) != 7 + length:
        raise PacketError(
            "length", f"LEN={length} needs {7 + length} bytes, got {len(data)}", packet_id, data
        )
    expected = crc16(data[:-2])
    received = int.from_bytes(data[-2:], "little")
    if expected != received:
        raise PacketError(
            "crc", f"CRC 0x{received:04X}, computed 0x{expected:04X}", packet_id, data
        )
    body = unstuff(data[7:-2])
    instruction = body[0]
    if instruction == Instruction.STATUS:
        if len(body) < 2:
            raise PacketError("length", "status packet without its error byte", packet_id, data)
        return Packet(packet_id, instruction, body[2:], body[1])
    return Packet(packet_id, instruction, body[1:])


def parse_packet(data: bytes) -> Packet:
    """Parse exactly one packet (instruction or status).

    Raises:
        PacketError: Wrong header, length, ID, CRC or stuffing (``field`` says which).
    """
    data = bytes(data)
    if len(data) < 10:
        raise PacketError("length", f"{len(data)} bytes, a packet has at least 10", data=data)
    if data[:4] != HEADER:
        raise PacketError("header", f"{data[:4].hex(' ')}, expected ff ff fd 00", data=data)
    length = int.from_bytes(data[5:7], "little")
    if length < 3:
        raise PacketError("length", f"LEN={length} < 3", data[4], data)
    return _parse_one(data)


class PacketReader:
    """Splits a byte stream into packets (pure: feed bytes, get packets).

    Garbage before a header is skipped; a packet whose CRC fails comes out as
    a :class:`PacketError` (with its ID), so a device can answer "CRC error"
    and a host can count a missed reply.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[Packet | PacketError]:
        """Add received bytes; return every packet now complete, in order."""
        self._buffer.extend(data)
        out: list[Packet | PacketError] = []
        while True:
            start = self._buffer.find(HEADER)
            if start < 0:
                # Keep a possible partial header at the end.
                keep = 3 if self._buffer.endswith(b"\xff\xff\xfd") else 0
                keep = keep or (2 if self._buffer.endswith(b"\xff\xff") else 0)
                keep = keep or (1 if self._buffer.endswith(b"\xff") else 0)
                del self._buffer[: len(self._buffer) - keep]
                return out
            del self._buffer[:start]
            if len(self._buffer) < 7:
                return out
            length = int.from_bytes(self._buffer[5:7], "little")
            if length < 3 or length > MAX_PACKET_LENGTH:
                del self._buffer[:1]  # not a real header; resynchronise
                continue
            if len(self._buffer) < 7 + length:
                return out
            raw = bytes(self._buffer[: 7 + length])
            try:
                out.append(_parse_one(raw))
                del self._buffer[: 7 + length]
            except PacketError as error:
                out.append(error)
                # A corrupt packet may hide the next header: resynchronise byte-wise.
                del self._buffer[:1]

    def clear(self) -> None:
        """Drop buffered bytes (after a timeout, or before a new request)."""
        self._buffer.clear()


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


# --------------------------------------------------------------------------- models


@dataclass(frozen=True)
class DynamixelModel:
    """One X-series model in current-control mode: its limits and torque ↔ current map.

    Datasheet values (ROBOTIS e-Manual, model pages and the X-series table
    ``docs/en/dxl/x/x.md``): model number, Current Limit (38) default, the
    current unit, and the stall torque and stall current at 11.1, 12.0 and
    14.8 V. At stall the speed is zero, so torque depends on current alone:
    the three stall points lie on the servo's torque(current) curve. The map
    is piecewise linear through (0 A, 0 N·m) and those three points
    (``torque_table``), extrapolated with the last segment's slope beyond
    them. That is an approximation: it ignores the no-load current and the
    gearbox's static friction near zero, which the performance graph shows
    but which we did not digitise; replace ``torque_table`` with points read
    off the 12 V graph for better low-torque accuracy.

    Commands are clamped to the stall torque at 12 V (``stall_torque_Nm``,
    the recommended supply) and to Current Limit (38).

    Positions and velocities are of the output shaft (the gear is inside the
    servo), so the bridge's gear ratio for a Dynamixel joint is 1.
    """

    name: str
    model_number: int
    current_limit_units: int
    stall_torque_Nm: float
    stall_current_A: float
    torque_table: tuple[tuple[float, float], ...]
    """(current A, output torque N·m) points, increasing, starting at (0, 0)."""
    gear_ratio: float
    current_unit_A: float = CURRENT_UNIT_A

    @property
    def current_limit_A(self) -> float:
        """Current Limit (38) default in amperes."""
        return self.current_limit_units * self.current_unit_A


def _model(
    name: str,
    model_number: int,
    current_limit_units: int,
    stall_points: tuple[tuple[float, float], ...],
    gear_ratio: float,
) -> DynamixelModel:
    """A model from its stall points at 11.1, 12.0 and 14.8 V ((A, N·m) each)."""
    current_12V_A, torque_12V_Nm = stall_points[1]
    return DynamixelModel(
        name=name,
        model_number=model_number,
        current_limit_units=current_limit_units,
        stall_torque_Nm=torque_12V_Nm,
        stall_current_A=current_12V_A,
        torque_table=((0.0, 0.0), *stall_points),
        gear_ratio=gear_ratio,
    )


DYNAMIXEL_MODELS: Mapping[str, DynamixelModel] = {
    model.name: model
    for model in (
        # Stall torque (N·m) at 11.1 / 12.0 / 14.8 V and its current (A), e-Manual x.md.
        _model("XM430-W350", 1020, 1193, ((2.1, 3.8), (2.3, 4.1), (2.7, 4.8)), 353.5),
        _model("XH430-W350", 1000, 648, ((1.2, 3.1), (1.3, 3.4), (1.5, 4.2)), 353.5),
        _model("XM540-W270", 1120, 2047, ((4.2, 10.0), (4.4, 10.6), (5.5, 12.9)), 272.5),
        _model("XH540-W270", 1100, 2047, ((4.5, 9.2), (4.9, 9.9), (5.9, 11.7)), 272.5),
    )
}
"""Supported servos by name (model numbers and Current Limit from their control tables)."""


def get_model(model: DynamixelModel | str) -> DynamixelModel:
    """The catalogue entry for a model name (a model passes through).

    Raises:
        CommandError: The name is not in :data:`DYNAMIXEL_MODELS`.
    """
    if isinstance(model, DynamixelModel):
        return model
    try:
        return DYNAMIXEL_MODELS[model]
    except KeyError:
        raise CommandError(
            -1, "model", f"{model!r} is not one of {sorted(DYNAMIXEL_MODELS)}"
        ) from None


def _interpolate(points: tuple[tuple[float, float], ...], x: float) -> float:
    """Piecewise-linear y(x) for increasing x ≥ 0, extrapolating the last segment."""
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        if x <= x1:
            return y0 + (y1 - y0) * (x - x0) / (x1 - x0)
    (x0, y0), (x1, y1) = points[-2], points[-1]
    return y1 + (y1 - y0) * (x - x1) / (x1 - x0)


def torque_from_current(model: DynamixelModel | str, current_A: float) -> float:
    """Output torque (N·m) the servo makes at ``current_A`` (odd: sign follows current)."""
    spec = get_model(model)
    magnitude = _interpolate(spec.torque_table, abs(current_A))
    return math.copysign(magnitude, current_A) if current_A else 0.0


def current_from_torque(model: DynamixelModel | str, torque_Nm: float) -> float:
    """Current (A) that makes ``torque_Nm`` (the inverse of :func:`torque_from_current`)."""
    spec = get_model(model)
    inverse = tuple((torque, current) for current, torque in spec.torque_table)
    magnitude = _interpolate(inverse, abs(torque_Nm))
    return math.copysign(magnitude, torque_Nm) if torque_Nm else 0.0


def goal_current_from_torque(model: DynamixelModel | str, torque_Nm: float) -> int:
    """Goal Current (102) in 2.69 mA units for an output torque.

    The torque is clamped to ± the stall torque at 12 V, mapped through the
    model's torque table, rounded to the unit and clamped to ± Current Limit.

    Raises:
        CommandError: ``torque_Nm`` is NaN or infinite (never sent).
    """
    spec = get_model(model)
    if not math.isfinite(torque_Nm):
        raise CommandError(-1, "torque_Nm", f"{torque_Nm=} is not finite; nothing was sent")
    torque_Nm = max(-spec.stall_torque_Nm, min(spec.stall_torque_Nm, torque_Nm))
    units = round(current_from_torque(spec, torque_Nm) / spec.current_unit_A)
    return max(-spec.current_limit_units, min(spec.current_limit_units, units))
