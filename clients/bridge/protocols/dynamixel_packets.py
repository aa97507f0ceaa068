"""Dynamixel Protocol 2.0 packet framing: header, byte stuffing, CRC-16, packets, errors.

Builds and parses packets byte for byte as the ROBOTIS e-Manual specifies them
(https://emanual.robotis.com/docs/en/dxl/protocol2/, source
``ROBOTIS-GIT/emanual`` ``docs/en/dxl/protocol2.md``)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM … | CRC_L CRC_H

``LEN`` counts the instruction, the parameters (after byte stuffing) and the
CRC; a status packet's first parameter is its error byte. The CRC is CRC-16
with polynomial 0x8005 (x¹⁶ + x¹⁵ + x² + 1), initial value 0, not reflected,
over every byte from the header to the last parameter (CRC-16/BUYPASS). Byte
stuffing inserts ``FD`` after each ``FF FF FD`` in the instruction and
parameters, so that a header never appears inside a packet.

Here are the instruction and status error codes, instruction packets (PING,
READ, WRITE, REBOOT, SYNC READ, SYNC WRITE) and status packets, a stream
reader that splits received bytes into packets, and the errors of the whole
Dynamixel protocol layer (:class:`DynamixelError`, :class:`PacketError`,
:class:`CommandError`), which ``dynamixel_registers.py`` and
``dynamixel_models.py`` raise too. Imported through
:mod:`clients.bridge.protocols.dynamixel`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import IntEnum

from protocol.errors import PoiseError

__all__ = [
    "ALERT_BIT",
    "BROADCAST_ID",
    "HEADER",
    "MAX_ID",
    "CommandError",
    "DynamixelError",
    "Instruction",
    "Packet",
    "PacketError",
    "PacketReader",
    "StatusError",
    "crc16",
    "make_packet",
    "make_ping",
    "make_read",
    "make_reboot",
    "make_status",
    "make_sync_read",
    "make_sync_write",
    "make_write",
    "parse_packet",
    "stuff",
    "unstuff",
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
