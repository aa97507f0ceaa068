"""Damiao DM-J joint motors (DM-J4310, 4340, 6006, 8006, 8009, 10010L…) over CAN, MIT mode.

Pure encode/decode functions (no I/O). Commands are MIT-mode frames packed
exactly as :func:`clients.bridge.protocols.mit.make_command` packs them, sent
on the motor's CAN id (``ESC_ID``); the motor answers on its master id
(``MST_ID``) with an 8-byte feedback frame::

    byte 0      status << 4 | motor id & 0xF
    bytes 1–5   p16 | v12 | τ12 (as the MIT reply)
    byte 6      MOSFET temperature, °C
    byte 7      rotor (coil) temperature, °C

Special frames ``FF…FC`` enable, ``…FD`` disable, ``…FE`` save the zero and
``…FB`` clear the error. Registers are read and written on CAN id ``0x7FF``
with ``[id_lo, id_hi, op, RID, 4 data bytes little-endian]`` (op ``0x33``
read, ``0x55`` write, ``0xAA`` save to flash); the motor answers on its
master id with the same layout (the register's value in the data bytes).

Sources:
    - jia-xie/python-damiao-driver, ``docs/concept/communication-protocol.md``
      and ``docs/concept/registers.md``
      (https://jia-xie.github.io/python-damiao-driver/dev/concept/communication-protocol,
      https://damiao-motor.jia-xie.com/api/registers): feedback layout, status
      codes 0, 1, 8–E (D: "communication timeout/loss", related to TIMEOUT),
      register table (ids, uint32/float types), default PMAX/VMAX/TMAX, and
      ``damiao_motor/core/motor.py``: "TIMEOUT … 1 register unit = 50
      microseconds".
    - cmjang/DM_Control_Python ``DM_CAN.py`` (Damiao's own Python example):
      the 0x7FF frames, that read and write both get a reply carrying the
      register's value (``0x33`` or ``0x55`` echoed), uint32 registers
      7–10, 13–16, 35–36 (others float), the same default ranges.
    - Damiao DM-J4310-2EC V1.1 manual (Chinese,
      https://gitee.com/kit-miao/DM-J4310-2EC), cited by the two above; not
      read directly here. The TIMEOUT unit (50 µs) is from python-damiao-driver
      only: check it on a motor (write 20 000 = 1 s, and time the stop).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum

from clients.bridge.actuator import MotorFeedback
from clients.bridge.protocols.mit import (
    MalformedFrame,
    MitRanges,
    NonFiniteValue,
    float_to_uint,
    uint_to_float,
)

__all__ = [
    "DAMIAO_MOTOR_MODELS",
    "FEEDBACK_LENGTH",
    "PARAMETER_CAN_ID",
    "TIMEOUT_UNIT_S",
    "DamiaoFeedback",
    "DamiaoMotor",
    "DamiaoRegister",
    "DamiaoSpecial",
    "DamiaoStatus",
    "RegisterFrame",
    "RegisterOp",
    "make_feedback",
    "make_register_frame",
    "make_register_read",
    "make_register_write",
    "make_save_parameters",
    "parse_feedback",
    "parse_register_frame",
    "register_is_uint32",
    "timeout_from_register",
    "timeout_to_register",
]

FEEDBACK_LENGTH = 8
"""Bytes in a feedback frame (and in every register frame)."""

PARAMETER_CAN_ID = 0x7FF
"""CAN id every motor listens on for register reads, writes and saves."""

TIMEOUT_UNIT_S = 50e-6
"""One unit of the TIMEOUT register (python-damiao-driver; unverified on hardware)."""


class DamiaoStatus(IntEnum):
    """The status nibble of a feedback frame: 0 and 1 are states, the rest faults."""

    description: str

    def __new__(cls, value: int, description: str) -> DamiaoStatus:  # noqa: D102
        member = int.__new__(cls, value)
        member._value_ = value
        member.description = description
        return member

    DISABLED = 0x0, ""
    ENABLED = 0x1, ""
    OVER_VOLTAGE = 0x8, "over-voltage"
    UNDER_VOLTAGE = 0x9, "under-voltage"
    OVER_CURRENT = 0xA, "over-current"
    MOS_OVER_TEMPERATURE = 0xB, "MOSFET over-temperature"
    ROTOR_OVER_TEMPERATURE = 0xC, "rotor (coil) over-temperature"
    COMMUNICATION_LOST = 0xD, "communication lost (its CAN timeout expired)"
    OVERLOAD = 0xE, "overload"

    @property
    def is_fault(self) -> bool:
        """Whether the code is a fault (not disabled or enabled)."""
        return self not in (DamiaoStatus.DISABLED, DamiaoStatus.ENABLED)


_STATUSES = {int(status): status for status in DamiaoStatus}


class DamiaoSpecial(IntEnum):
    """Last byte of the special frames ``FF FF FF FF FF FF FF xx`` Damiao motors take."""

    ENABLE = 0xFC
    DISABLE = 0xFD
    SAVE_ZERO = 0xFE
    CLEAR_ERROR = 0xFB


class RegisterOp(IntEnum):
    """Byte 2 of a register frame on ``0x7FF`` (and of its reply)."""

    READ = 0x33
    WRITE = 0x55
    SAVE = 0xAA
    """Store every register to flash (the motor must be disabled)."""


class DamiaoRegister(IntEnum):
    """Register ids (RID) of DM-J motors (python-damiao-driver's table, DM_CAN.py)."""

    UV_VALUE = 0
    KT_VALUE = 1
    OT_VALUE = 2
    OC_VALUE = 3
    ACC = 4
    DEC = 5
    MAX_SPD = 6
    MST_ID = 7
    """Master (feedback) CAN id; uint32."""
    ESC_ID = 8
    """The motor's own (command) CAN id; uint32."""
    TIMEOUT = 9
    """CAN timeout in units of 50 µs (0: off); after it the motor reports status D; uint32."""
    CTRL_MODE = 10
    """1 MIT, 2 position-velocity, 3 velocity, 4 force-position; uint32."""
    DAMP = 11
    INERTIA = 12
    HW_VER = 13
    SW_VER = 14
    SN = 15
    NPP = 16
    RS = 17
    LS = 18
    FLUX = 19
    GR = 20
    PMAX = 21
    """Position mapping range (rad); float."""
    VMAX = 22
    """Velocity mapping range (rad/s); float."""
    TMAX = 23
    """Torque mapping range (N·m); float."""
    I_BW = 24
    KP_ASR = 25
    KI_ASR = 26
    KP_APR = 27
    KI_APR = 28
    OV_VALUE = 29
    GREF = 30
    DETA = 31
    V_BW = 32
    IQ_C1 = 33
    VL_C1 = 34
    CAN_BR = 35
    SUB_VER = 36


_UINT32_REGISTERS = frozenset({7, 8, 9, 10, 13, 14, 15, 16, 35, 36})


def register_is_uint32(register: int) -> bool:
    """Whether a register holds a uint32 (ids, timeout, mode, versions); else a float32."""
    return register in _UINT32_REGISTERS


DAMIAO_MOTOR_MODELS: dict[str, MitRanges] = {
    # Factory PMAX / VMAX / TMAX (registers 21–23), from Damiao's DM_CAN.py Limit_Param and
    # python-damiao-driver's _MOTOR_LIMIT_PARAM (they agree, except DM-J4340: DM_CAN.py has
    # VMAX 8 for the 24 V version, 10 for 48 V; python-damiao-driver 10). kp 0–500, kd 0–5
    # are fixed in the firmware. A motor may have been reconfigured: read PMAX/VMAX/TMAX.
    "DM-J4310": MitRanges(12.5, 30.0, 10.0),
    "DM-J4310-48V": MitRanges(12.5, 50.0, 10.0),
    "DM-J4340": MitRanges(12.5, 10.0, 28.0),
    "DM-J6006": MitRanges(12.5, 45.0, 20.0),
    "DM-J8006": MitRanges(12.5, 45.0, 40.0),
    "DM-J8009": MitRanges(12.5, 45.0, 54.0),
    "DM-J10010L": MitRanges(12.5, 25.0, 200.0),
    "DM-J10010": MitRanges(12.5, 20.0, 200.0),
}
"""Factory MIT-mode ranges of Damiao DM-J motors, by model."""


@dataclass(frozen=True)
class DamiaoMotor:
    """One Damiao motor on a bus: the ranges it maps values with, and where it answers.

    Attributes:
        ranges: Its PMAX / VMAX / TMAX (and kp 0–500, kd 0–5).
        master_id: Its ``MST_ID``: the CAN id its feedback and register replies come on.
    """

    ranges: MitRanges
    master_id: int

    def __post_init__(self) -> None:
        if not 0 <= self.master_id <= 0x7FF:
            raise ValueError(f"master_id={self.master_id:#x}: expected a standard id 0–0x7FF")


@dataclass(frozen=True)
class DamiaoFeedback:
    """One decoded feedback frame.

    Attributes:
        motor_id_low: The low nibble of the motor's id (byte 0's low 4 bits).
        status: The status nibble (a :class:`DamiaoStatus` value, or another int if unknown).
        feedback: Its state, with the hotter of MOSFET and rotor as the temperature.
        mos_temperature_C: MOSFET temperature.
        rotor_temperature_C: Rotor (coil) temperature.
    """

    motor_id_low: int
    status: int
    feedback: MotorFeedback
    mos_temperature_C: float
    rotor_temperature_C: float


def make_feedback(
    motor_id: int,
    status: int,
    position_rad: float,
    velocity_rad_s: float,
    torque_Nm: float,
    mos_temperature_C: float,
    rotor_temperature_C: float,
    ranges: MitRanges,
) -> bytes:
    """The 8-byte feedback frame a motor sends on its master id (values clamped to range).

    Raises:
        NonFiniteValue: A value is NaN or infinite.
    """
    r = ranges
    p = float_to_uint(position_rad, -r.position_max_rad, r.position_max_rad, 16, "position_rad")
    v = float_to_uint(
        velocity_rad_s, -r.velocity_max_rad_s, r.velocity_max_rad_s, 12, "velocity_rad_s"
    )
    t = float_to_uint(torque_Nm, -r.torque_max_Nm, r.torque_max_Nm, 12, "torque_Nm")
    temperatures = []
    for name, value in (
        ("mos_temperature_C", mos_temperature_C),
        ("rotor_temperature_C", rotor_temperature_C),
    ):
        if not math.isfinite(value):
            raise NonFiniteValue(name, value)
        temperatures.append(min(255, max(0, round(value))))
    return bytes(
        (
            ((status & 0xF) << 4) | (motor_id & 0xF),
            p >> 8,
            p & 0xFF,
            v >> 4,
            ((v & 0xF) << 4) | (t >> 8),
            t & 0xFF,
            *temperatures,
        )
    )


def parse_feedback(data: bytes, ranges: MitRanges) -> DamiaoFeedback:
    """Decode a feedback frame to motor-side SI units and the status as a fault.

    Status 0 (disabled) and 1 (enabled) are not faults (``fault_code`` 0);
    any other nibble is reported as ``fault_code`` with its description.

    Raises:
        MalformedFrame: ``data`` is not 8 bytes.
    """
    if len(data) != FEEDBACK_LENGTH:
        raise MalformedFrame("Damiao feedback", data, f"{len(data)} bytes, expected 8")
    status = data[0] >> 4
    p = (data[1] << 8) | data[2]
    v = (data[3] << 4) | (data[4] >> 4)
    t = ((data[4] & 0xF) << 8) | data[5]
    known = _STATUSES.get(status)
    if known is None:
        fault_code, fault = status, f"unknown fault code {status:#x}"
    elif known.is_fault:
        fault_code, fault = int(known), known.description
    else:
        fault_code, fault = 0, ""
    r = ranges
    mos_C, rotor_C = float(data[6]), float(data[7])
    return DamiaoFeedback(
        motor_id_low=data[0] & 0xF,
        status=status,
        feedback=MotorFeedback(
            position_rad=uint_to_float(p, -r.position_max_rad, r.position_max_rad, 16),
            velocity_rad_s=uint_to_float(v, -r.velocity_max_rad_s, r.velocity_max_rad_s, 12),
            torque_Nm=uint_to_float(t, -r.torque_max_Nm, r.torque_max_Nm, 12),
            temperature_C=max(mos_C, rotor_C),
            fault=fault,
            fault_code=fault_code,
        ),
        mos_temperature_C=mos_C,
        rotor_temperature_C=rotor_C,
    )


@dataclass(frozen=True)
class RegisterFrame:
    """A register request on ``0x7FF``, or its reply on the master id (same layout).

    Attributes:
        motor_id: The motor's CAN id (``ESC_ID``), bytes 0–1 little-endian.
        op: Read, write or save.
        register: The register id (byte 3); for a save, whatever the frame carries.
        value: The 4 data bytes as the register's type (int for uint32, float for
            float32); for a read request and a save, what the frame carries.
    """

    motor_id: int
    op: RegisterOp
    register: int
    value: int | float


def make_register_frame(motor_id: int, op: RegisterOp, register: int, value: int | float) -> bytes:
    """``[id_lo, id_hi, op, RID, value as 4 bytes LE]``, value packed by the register's type.

    Raises:
        NonFiniteValue: A float register's value is NaN or infinite.
        ValueError: A uint32 register's value is not an integer in 0…2³²−1.
    """
    if not 0 <= motor_id <= 0x7FF:
        raise ValueError(f"motor_id={motor_id:#x}: expected a standard id 0–0x7FF")
    if register_is_uint32(register):
        if isinstance(value, float) and not value.is_integer():
            raise ValueError(f"register {register} is uint32: {value=} is not an integer")
        if not 0 <= int(value) <= 0xFFFF_FFFF:
            raise ValueError(f"register {register} is uint32: {value=} out of 0…2³²−1")
        payload = struct.pack("<I", int(value))
    else:
        if not math.isfinite(value):
            raise NonFiniteValue(f"register {register}", float(value))
        payload = struct.pack("<f", float(value))
    return bytes((motor_id & 0xFF, motor_id >> 8, int(op), register & 0xFF)) + payload


def make_register_read(motor_id: int, register: int) -> bytes:
    """Read request: ``[id_lo, id_hi, 0x33, RID, 00 00 00 00]`` (send on ``0x7FF``)."""
    return make_register_frame(motor_id, RegisterOp.READ, register, 0)


def make_register_write(motor_id: int, register: int, value: int | float) -> bytes:
    """Write request: ``[id_lo, id_hi, 0x55, RID, value LE]`` (send on ``0x7FF``; RAM only)."""
    return make_register_frame(motor_id, RegisterOp.WRITE, register, value)


def make_save_parameters(motor_id: int) -> bytes:
    """Save request: ``[id_lo, id_hi, 0xAA, 01, 00 00 00 00]`` (every register to flash).

    Byte 3 is ``0x01`` as python-damiao-driver sends it (DM_CAN.py sends 0);
    disable the motor first.
    """
    return bytes((motor_id & 0xFF, motor_id >> 8, int(RegisterOp.SAVE), 0x01, 0, 0, 0, 0))


def parse_register_frame(data: bytes) -> RegisterFrame:
    """Decode a register request or reply (value by the register's type).

    Raises:
        MalformedFrame: Not 8 bytes, or byte 2 is not a :class:`RegisterOp`.
    """
    if len(data) != FEEDBACK_LENGTH:
        raise MalformedFrame("Damiao register frame", data, f"{len(data)} bytes, expected 8")
    try:
        op = RegisterOp(data[2])
    except ValueError:
        raise MalformedFrame(
            "Damiao register frame", data, f"byte 2 = {data[2]:#04x} is not 0x33, 0x55 or 0xAA"
        ) from None
    register = data[3]
    payload = bytes(data[4:8])
    value: int | float
    if register_is_uint32(register) or op is RegisterOp.SAVE:
        value = struct.unpack("<I", payload)[0]
    else:
        value = struct.unpack("<f", payload)[0]
    return RegisterFrame(data[0] | (data[1] << 8), op, register, value)


def timeout_to_register(timeout_s: float) -> int:
    """The TIMEOUT register value for a timeout: units of 50 µs, rounded, at least 1 (0: off).

    Raises:
        ValueError: ``timeout_s`` is negative, not finite, or beyond the register.
    """
    if not (math.isfinite(timeout_s) and timeout_s >= 0.0):
        raise ValueError(f"{timeout_s=}: expected a finite timeout ≥ 0 (0 turns it off)")
    if timeout_s == 0.0:
        return 0
    units = max(1, round(timeout_s / TIMEOUT_UNIT_S))
    if units > 0xFFFF_FFFF:
        raise ValueError(f"{timeout_s=}: beyond the TIMEOUT register (2³² × 50 µs)")
    return units


def timeout_from_register(units: int) -> float:
    """The timeout (s) a TIMEOUT register value stands for (0: off)."""
    return units * TIMEOUT_UNIT_S
