"""MIT mode over CAN: Ben Katz's motorcontrol firmware and the CubeMars AK family.

Pure encode/decode functions (no I/O): the 8-byte impedance command
``p16 | v12 | kp12 | kd12 | τ12`` (MSB first), the special frames that enter
and leave motor mode or set the zero, and the two reply layouts (the 6-byte
bgkatz reply, the 8-byte CubeMars reply that adds temperature and an error
code). Damiao DM-J motors pack their commands the same way
(:mod:`clients.bridge.protocols.damiao`). The I/O layer is :class:`MitBus`
in :mod:`clients.bridge.protocols.can_io`.

Sources:
    - B. Katz, *motorcontrol* firmware (``float_to_uint`` / ``uint_to_float``,
      ``pack_reply`` / ``unpack_cmd``), as reproduced in the CubeMars manual's
      example code (the firmware repository itself was not consulted): field
      packing, truncating conversion, special frames.
    - CubeMars, *AK Series Actuator Driver Manual* V1.0.8, §5.3 "MIT power
      mode communication protocol" (pp. 48–50,
      https://www.manualshelf.com/manual/cubemars/ak80-64-kv80/ak80-64-ak-series-actuator-driver-manual-v1-0-8-english-somali/page-49.html
      and page-50.html): command and reply byte maps, special frames, and the
      per-model range table used for :data:`MIT_MOTOR_MODELS`.
    - neurobionics/TMotorCANControl ``mit_can.py``: the same ranges (except
      AK60-6 speed, see the catalogue), the 8-byte reply read as
      ``temperature = data[6]``, ``error = data[7]``, and error codes 0–6.

The firmware converts with ``(int)((x - min) * (2^bits - 1) / span)`` and does
*not* clamp: a value beyond its range overflows into the neighbouring field.
:func:`make_command` therefore clamps every field first, and refuses NaN and
±inf (:class:`NonFiniteValue`): the bridge never sends them, so one reaching
the wire is a bug upstream, and there is no safe value to send instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from clients.bridge.actuator import MotorCommand, MotorFeedback
from protocol.errors import PoiseError

__all__ = [
    "COMMAND_LENGTH",
    "MIT_MOTOR_MODELS",
    "CubeMarsFault",
    "MalformedFrame",
    "MitRanges",
    "MitReply",
    "MitSpecial",
    "NonFiniteValue",
    "clamp_command",
    "command_codes",
    "float_to_uint",
    "make_command",
    "make_reply",
    "make_special",
    "parse_command",
    "parse_reply",
    "parse_special",
    "quantum",
    "uint_to_float",
    "unpack_command_codes",
]

COMMAND_LENGTH = 8
"""Bytes in a command frame (and in every special frame)."""

_POSITION_BITS = 16
_FIELD_BITS = 12  # velocity, kp, kd, torque


class NonFiniteValue(PoiseError, ValueError):
    """A NaN or infinite value was to be packed into a frame.

    Attributes:
        field: Which field (``"position_rad"``, ``"torque_Nm"``, register name…).
        value: The value.
    """

    def __init__(self, field: str, value: float):
        self.field = field
        self.value = value
        super().__init__(
            f"{field}={value!r} cannot be packed: the bridge sends finite values only "
            "(check what computed this command)"
        )


class MalformedFrame(PoiseError, ValueError):
    """A received frame does not have the layout its protocol specifies.

    Attributes:
        kind: What it was parsed as (``"MIT reply"``, ``"Damiao feedback"``…).
        data: Its bytes.
        detail: What is wrong.
    """

    def __init__(self, kind: str, data: bytes, detail: str):
        self.kind = kind
        self.data = bytes(data)
        self.detail = detail
        super().__init__(f"malformed {kind} {self.data.hex(' ')}: {detail}")


@dataclass(frozen=True)
class MitRanges:
    """The ranges one motor model maps onto the wire's integers (symmetric, SI).

    Position, velocity and torque span ``[-max, max]``; the gains ``[0, max]``.
    They must match what the motor's firmware was built or configured with,
    else every value is scaled wrong.

    Attributes:
        position_max_rad: ``P_MAX`` (rad).
        velocity_max_rad_s: ``V_MAX`` (rad/s).
        torque_max_Nm: ``T_MAX`` (N·m), also the range of the torque reply.
        kp_max_Nm_per_rad: ``KP_MAX``.
        kd_max_Nm_s_per_rad: ``KD_MAX``.
    """

    position_max_rad: float
    velocity_max_rad_s: float
    torque_max_Nm: float
    kp_max_Nm_per_rad: float = 500.0
    kd_max_Nm_s_per_rad: float = 5.0

    def __post_init__(self) -> None:
        for name in (
            "position_max_rad",
            "velocity_max_rad_s",
            "torque_max_Nm",
            "kp_max_Nm_per_rad",
            "kd_max_Nm_s_per_rad",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"MitRanges.{name}={value!r}: must be finite and > 0")


MIT_MOTOR_MODELS: dict[str, MitRanges] = {
    # CubeMars AK Series Actuator Driver Manual V1.0.8, p. 50 (table "Module / Position /
    # Speed / Torque / Kp range / Kd range"); the same values are in TMotorCANControl's
    # MIT_Params, except AK60-6 speed, which it gives as ±50 rad/s against the manual's ±45.
    # Firmware built by others (or reconfigured over the serial menu) may differ: read the
    # motor's own settings before trusting these.
    "AK10-9": MitRanges(12.5, 50.0, 65.0),
    "AK60-6": MitRanges(12.5, 45.0, 15.0),
    "AK70-10": MitRanges(12.5, 50.0, 25.0),
    "AK80-6": MitRanges(12.5, 76.0, 12.0),
    "AK80-9": MitRanges(12.5, 50.0, 18.0),
    "AK80-64": MitRanges(12.5, 8.0, 144.0),
}
"""Published MIT-mode ranges of CubeMars AK actuators, by model."""


class MitSpecial(IntEnum):
    """Last byte of the special frames ``FF FF FF FF FF FF FF xx`` (bgkatz, CubeMars)."""

    ENTER_MOTOR_MODE = 0xFC
    """Start applying commands; also a harmless way to read the state."""
    EXIT_MOTOR_MODE = 0xFD
    """Stop applying commands (the motor goes limp)."""
    SET_ZERO = 0xFE
    """Make the present position zero (the motor may not answer for ~1 s after)."""


_SPECIAL_PREFIX = b"\xff" * 7
_SPECIAL_CODES = frozenset({0xFB, 0xFC, 0xFD, 0xFE})  # FB: Damiao clear error


class CubeMarsFault(IntEnum):
    """Error byte of the 8-byte CubeMars MIT reply (0: none).

    Codes 0–5 as TMotorCANControl's ``ERROR_CODES``; sources disagree on 6
    (TMotorCANControl: phase-current unbalance; later CubeMars manuals:
    MOSFET over-temperature) and only later manuals list 7 (motor stall):
    both are unverified.
    """

    description: str

    def __new__(cls, value: int, description: str) -> CubeMarsFault:  # noqa: D102
        member = int.__new__(cls, value)
        member._value_ = value
        member.description = description
        return member

    NONE = 0, ""
    MOTOR_OVER_TEMPERATURE = 1, "motor over-temperature"
    OVER_CURRENT = 2, "over-current"
    OVER_VOLTAGE = 3, "over-voltage"
    UNDER_VOLTAGE = 4, "under-voltage"
    ENCODER = 5, "encoder fault"
    PHASE_UNBALANCE_OR_MOSFET_OVER_TEMPERATURE = (
        6,
        "phase-current unbalance or MOSFET over-temperature (by firmware version)",
    )
    MOTOR_STALL = 7, "motor stall"


_CUBEMARS_FAULTS = {int(fault): fault for fault in CubeMarsFault}


def quantum(x_min: float, x_max: float, bits: int) -> float:
    """One step of the wire's integer, in the field's unit: ``span / (2^bits − 1)``."""
    return (x_max - x_min) / ((1 << bits) - 1)


def float_to_uint(x: float, x_min: float, x_max: float, bits: int, field: str = "value") -> int:
    """The firmware's ``float_to_uint``, clamped first: ``⌊(x − min)(2^bits − 1)/span⌋``.

    Truncates like the C cast (so 0 on ``[−12.5, 12.5]`` in 16 bits is
    ``0x7FFF``, not ``0x8000``), after clamping ``x`` to ``[x_min, x_max]``.

    Raises:
        NonFiniteValue: ``x`` is NaN or infinite.
    """
    if not math.isfinite(x):
        raise NonFiniteValue(field, x)
    top = (1 << bits) - 1
    clamped = min(max(x, x_min), x_max)
    return min(top, max(0, int((clamped - x_min) * top / (x_max - x_min))))


def uint_to_float(x_int: int, x_min: float, x_max: float, bits: int) -> float:
    """The firmware's ``uint_to_float``: ``x_int · span / (2^bits − 1) + min``."""
    return x_int * (x_max - x_min) / ((1 << bits) - 1) + x_min


def command_codes(command: MotorCommand, ranges: MitRanges) -> tuple[int, int, int, int, int]:
    """The five wire integers of a command (position, velocity, kp, kd, torque), clamped.

    Raises:
        NonFiniteValue: A field is NaN or infinite.
    """
    r = ranges
    return (
        float_to_uint(
            command.position_rad,
            -r.position_max_rad,
            r.position_max_rad,
            _POSITION_BITS,
            "position_rad",
        ),
        float_to_uint(
            command.velocity_rad_s,
            -r.velocity_max_rad_s,
            r.velocity_max_rad_s,
            _FIELD_BITS,
            "velocity_rad_s",
        ),
        float_to_uint(
            command.kp_Nm_per_rad, 0.0, r.kp_max_Nm_per_rad, _FIELD_BITS, "kp_Nm_per_rad"
        ),
        float_to_uint(
            command.kd_Nm_s_per_rad, 0.0, r.kd_max_Nm_s_per_rad, _FIELD_BITS, "kd_Nm_s_per_rad"
        ),
        float_to_uint(
            command.torque_Nm, -r.torque_max_Nm, r.torque_max_Nm, _FIELD_BITS, "torque_Nm"
        ),
    )


def make_command(command: MotorCommand, ranges: MitRanges) -> bytes:
    """The 8-byte MIT command ``p16 | v12 | kp12 | kd12 | τ12``, MSB first, every field clamped.

    One command would read as a special frame (every field at its maximum and
    the torque code ``0xFFB``–``0xFFE``): the position code is then lowered by
    one step, so the frame stays a command. With symmetric ranges the
    all-zero command is ``7F FF 7F F0 00 00 07 FF``.

    Raises:
        NonFiniteValue: A field is NaN or infinite.
    """
    p, v, kp, kd, t = command_codes(command, ranges)
    data = _pack(p, v, kp, kd, t)
    if data[:7] == _SPECIAL_PREFIX and data[7] in _SPECIAL_CODES:
        data = _pack(p - 1, v, kp, kd, t)
    return data


def _pack(p: int, v: int, kp: int, kd: int, t: int) -> bytes:
    return bytes(
        (
            p >> 8,
            p & 0xFF,
            v >> 4,
            ((v & 0xF) << 4) | (kp >> 8),
            kp & 0xFF,
            kd >> 4,
            ((kd & 0xF) << 4) | (t >> 8),
            t & 0xFF,
        )
    )


def parse_command(data: bytes, ranges: MitRanges) -> MotorCommand:
    """The command an MIT motor applies from a frame: :func:`make_command`'s inverse.

    Decoded as the firmware decodes it (``uint_to_float``), so the values are
    the quantized ones: a torque of 0 comes back as ``−T_MAX/4095``.

    Raises:
        MalformedFrame: ``data`` is not 8 bytes, or is a special frame.
    """
    p, v, kp, kd, t = unpack_command_codes(data)
    r = ranges
    return MotorCommand(
        position_rad=uint_to_float(p, -r.position_max_rad, r.position_max_rad, _POSITION_BITS),
        velocity_rad_s=uint_to_float(v, -r.velocity_max_rad_s, r.velocity_max_rad_s, _FIELD_BITS),
        kp_Nm_per_rad=uint_to_float(kp, 0.0, r.kp_max_Nm_per_rad, _FIELD_BITS),
        kd_Nm_s_per_rad=uint_to_float(kd, 0.0, r.kd_max_Nm_s_per_rad, _FIELD_BITS),
        torque_Nm=uint_to_float(t, -r.torque_max_Nm, r.torque_max_Nm, _FIELD_BITS),
    )


def unpack_command_codes(data: bytes) -> tuple[int, int, int, int, int]:
    """The five wire integers of a command frame (position, velocity, kp, kd, torque).

    Raises:
        MalformedFrame: ``data`` is not 8 bytes, or is a special frame.
    """
    if len(data) != COMMAND_LENGTH:
        raise MalformedFrame("MIT command", data, f"{len(data)} bytes, expected 8")
    if parse_special(data) is not None:
        raise MalformedFrame("MIT command", data, "a special frame, not a command")
    return (
        (data[0] << 8) | data[1],
        (data[2] << 4) | (data[3] >> 4),
        ((data[3] & 0xF) << 8) | data[4],
        (data[5] << 4) | (data[6] >> 4),
        ((data[6] & 0xF) << 8) | data[7],
    )


def clamp_command(command: MotorCommand, ranges: MitRanges) -> MotorCommand:
    """The command with every field clamped to its range (what :func:`make_command` packs)."""
    r = ranges

    def clamp(x: float, lo: float, hi: float) -> float:
        return min(max(x, lo), hi)

    return MotorCommand(
        position_rad=clamp(command.position_rad, -r.position_max_rad, r.position_max_rad),
        velocity_rad_s=clamp(command.velocity_rad_s, -r.velocity_max_rad_s, r.velocity_max_rad_s),
        kp_Nm_per_rad=clamp(command.kp_Nm_per_rad, 0.0, r.kp_max_Nm_per_rad),
        kd_Nm_s_per_rad=clamp(command.kd_Nm_s_per_rad, 0.0, r.kd_max_Nm_s_per_rad),
        torque_Nm=clamp(command.torque_Nm, -r.torque_max_Nm, r.torque_max_Nm),
    )


def make_special(code: int) -> bytes:
    """The special frame ``FF FF FF FF FF FF FF code`` (a :class:`MitSpecial`, or Damiao's)."""
    if code not in _SPECIAL_CODES:
        raise ValueError(f"special code {code:#04x}: expected one of FB, FC, FD, FE")
    return _SPECIAL_PREFIX + bytes((code,))


def parse_special(data: bytes) -> int | None:
    """The code of a special frame (``0xFB``–``0xFE``), ``None`` if ``data`` is not one."""
    if len(data) == COMMAND_LENGTH and data[:7] == _SPECIAL_PREFIX and data[7] in _SPECIAL_CODES:
        return data[7]
    return None


@dataclass(frozen=True)
class MitReply:
    """One decoded MIT reply.

    Attributes:
        motor_id: The id byte (``data[0]``): which motor answered.
        feedback: Its state; temperature and fault only from 8-byte replies.
    """

    motor_id: int
    feedback: MotorFeedback


def make_reply(
    motor_id: int,
    position_rad: float,
    velocity_rad_s: float,
    torque_Nm: float,
    ranges: MitRanges,
    *,
    temperature_C: float | None = None,
    fault_code: int = 0,
) -> bytes:
    """A motor's reply: 6 bytes ``id | p16 | v12 | τ12``; 8 with ``temperature_C`` given.

    The 8-byte (CubeMars) form appends the temperature (°C, one signed byte,
    clamped to −128…127) and the error byte (:class:`CubeMarsFault`). Values
    are clamped to the ranges like the firmware's reply (which wraps instead:
    the emulator never goes that far).

    Raises:
        NonFiniteValue: A value is NaN or infinite.
    """
    r = ranges
    p = float_to_uint(
        position_rad, -r.position_max_rad, r.position_max_rad, _POSITION_BITS, "position_rad"
    )
    v = float_to_uint(
        velocity_rad_s,
        -r.velocity_max_rad_s,
        r.velocity_max_rad_s,
        _FIELD_BITS,
        "velocity_rad_s",
    )
    t = float_to_uint(torque_Nm, -r.torque_max_Nm, r.torque_max_Nm, _FIELD_BITS, "torque_Nm")
    data = bytes((motor_id & 0xFF, p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (t >> 8), t & 0xFF))
    if temperature_C is None:
        return data
    if not math.isfinite(temperature_C):
        raise NonFiniteValue("temperature_C", temperature_C)
    temperature = min(127, max(-128, round(temperature_C)))
    return data + bytes((temperature & 0xFF, fault_code & 0xFF))


def parse_reply(data: bytes, ranges: MitRanges) -> MitReply:
    """Decode a 6-byte bgkatz or 8-byte CubeMars MIT reply (motor-side SI units).

    The torque field is the firmware's torque estimate (``i_q · k_t`` times
    the gear ratio), on the ``±T_MAX`` range. In the 8-byte form, ``data[6]``
    is the temperature in °C (read as a signed byte; the manual gives no
    offset) and ``data[7]`` the :class:`CubeMarsFault` code.

    Raises:
        MalformedFrame: ``data`` is neither 6 nor 8 bytes.
    """
    if len(data) not in (6, 8):
        raise MalformedFrame("MIT reply", data, f"{len(data)} bytes, expected 6 or 8")
    p = (data[1] << 8) | data[2]
    v = (data[3] << 4) | (data[4] >> 4)
    t = ((data[4] & 0xF) << 8) | data[5]
    r = ranges
    temperature_C: float | None = None
    fault_code = 0
    fault = ""
    if len(data) == 8:
        temperature_C = float(data[6] - 256 if data[6] > 127 else data[6])
        fault_code = data[7]
        known = _CUBEMARS_FAULTS.get(fault_code)
        fault = known.description if known is not None else f"unknown fault code {fault_code}"
    return MitReply(
        motor_id=data[0],
        feedback=MotorFeedback(
            position_rad=uint_to_float(p, -r.position_max_rad, r.position_max_rad, _POSITION_BITS),
            velocity_rad_s=uint_to_float(
                v, -r.velocity_max_rad_s, r.velocity_max_rad_s, _FIELD_BITS
            ),
            torque_Nm=uint_to_float(t, -r.torque_max_Nm, r.torque_max_Nm, _FIELD_BITS),
            temperature_C=temperature_C,
            fault=fault,
            fault_code=fault_code,
        ),
    )
