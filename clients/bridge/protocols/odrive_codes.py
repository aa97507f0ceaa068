"""ODrive CANSimple codes: identifiers, command ids, states, modes and error bits per firmware.

CANSimple is the ODrive's own CAN protocol (firmware 0.5.x on ODrive v3.6,
0.6.x on ODrive Pro / S1 / Micro). Every frame has an 11-bit standard
identifier ``node_id << 5 | cmd_id`` (6 bits of node, 5 of command). This
module holds what the numbers in a frame mean: the identifier layout, the
command ids, the axis states, control and input modes, the axis error bits of
each firmware generation (:class:`Firmware`) and their names, the watchdog's
endpoint ids, and the errors of the ODrive protocol layer. The frames
themselves are encoded and decoded in ``odrive_frames.py``; both are imported
through :mod:`clients.bridge.protocols.odrive`.

Sources (checked for this module):

* ODrive CAN protocol reference, firmware 0.6 ("CAN Protocol",
  http://newdocs.odriverobotics.com/v/latest/manual/can-protocol.html): the
  identifier layout and the message ids.
* The 0.6.10 and 0.5.6 CANSimple DBC files as rendered at
  https://odrive-can-roxautomation-components-9f5f4b809336bc0ecbd5b8cd8e4.gitlab.io/can_interface_pro
  and ``.../can_interface/``: axis error bits and axis states of both.
* ``flat_endpoints.json`` endpoint ids for ``axis0.config.watchdog_timeout``
  (200, float) and ``axis0.config.enable_watchdog`` (201, bool) as listed in a
  generated CANSimple binding for 0.6.x (endpoint map next to the RxSdo
  encoder); they change between firmware releases, so :class:`WatchdogEndpoints`
  is a parameter — check them against the ``flat_endpoints.json`` of the
  firmware you flash.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum, IntEnum, IntFlag

from protocol.errors import PoiseError

__all__ = [
    "DEFAULT_WATCHDOG_ENDPOINTS",
    "NODE_ID_MAX",
    "TURN_RAD",
    "AxisError",
    "AxisError05",
    "AxisState",
    "Command",
    "ControlMode",
    "Firmware",
    "InputMode",
    "InvalidCommand",
    "MalformedFrame",
    "ODriveError",
    "SdoOpcode",
    "WatchdogEndpoints",
    "arbitration_id",
    "axis_state_name",
    "describe_axis_error",
    "split_arbitration_id",
]


NODE_ID_MAX = 0x3F
"""Largest node id of an 11-bit CANSimple identifier (6 bits)."""

_CMD_BITS = 5
_CMD_MASK = (1 << _CMD_BITS) - 1
TURN_RAD = 2.0 * math.pi


class Command(IntEnum):
    """CANSimple command ids (the low 5 bits of the identifier), firmware 0.6.

    0.5.x shares 0x01, 0x02, 0x07, 0x09, 0x0B–0x0F and 0x18; its 0x03–0x06
    are Get_Motor_Error, Get_Encoder_Error, Get_Sensorless_Error and
    Set_Axis_Node_ID, 0x15 is Get_Sensorless_Estimates, 0x1C Get_ADC_Voltage,
    and it has no SDO, Get_Temperature or Get_Torques.
    """

    GET_VERSION = 0x00
    HEARTBEAT = 0x01
    ESTOP = 0x02
    GET_ERROR = 0x03
    RX_SDO = 0x04
    TX_SDO = 0x05
    ADDRESS = 0x06
    SET_AXIS_STATE = 0x07
    GET_ENCODER_ESTIMATES = 0x09
    SET_CONTROLLER_MODE = 0x0B
    SET_INPUT_POS = 0x0C
    SET_INPUT_VEL = 0x0D
    SET_INPUT_TORQUE = 0x0E
    SET_LIMITS = 0x0F
    SET_TRAJ_VEL_LIMIT = 0x11
    SET_TRAJ_ACCEL_LIMITS = 0x12
    SET_TRAJ_INERTIA = 0x13
    GET_IQ = 0x14
    GET_TEMPERATURE = 0x15
    REBOOT = 0x16
    GET_BUS_VOLTAGE_CURRENT = 0x17
    CLEAR_ERRORS = 0x18
    SET_ABSOLUTE_POSITION = 0x19
    SET_POS_GAIN = 0x1A
    SET_VEL_GAINS = 0x1B
    GET_TORQUES = 0x1C
    GET_POWERS = 0x1D
    ENTER_DFU_MODE = 0x1F


class AxisState(IntEnum):
    """``Axis.AxisState`` (same values in 0.5 and 0.6)."""

    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    SENSORLESS_CONTROL = 5
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8
    LOCKIN_SPIN = 9
    ENCODER_DIR_FIND = 10
    HOMING = 11
    ENCODER_HALL_POLARITY_CALIBRATION = 12
    ENCODER_HALL_PHASE_CALIBRATION = 13
    ANTICOGGING_CALIBRATION = 14


class ControlMode(IntEnum):
    """``Controller.ControlMode``."""

    VOLTAGE_CONTROL = 0
    TORQUE_CONTROL = 1
    VELOCITY_CONTROL = 2
    POSITION_CONTROL = 3


class InputMode(IntEnum):
    """``Controller.InputMode``."""

    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2
    POS_FILTER = 3
    MIX_CHANNELS = 4
    TRAP_TRAJ = 5
    TORQUE_RAMP = 6
    MIRROR = 7
    TUNING = 8


class SdoOpcode(IntEnum):
    """RxSdo opcode (0.6)."""

    READ = 0
    WRITE = 1


class AxisError(IntFlag):
    """Axis error bits of firmware 0.6 (heartbeat ``Axis_Error``, ``Get_Error``)."""

    INITIALIZING = 0x1
    SYSTEM_LEVEL = 0x2
    TIMING_ERROR = 0x4
    MISSING_ESTIMATE = 0x8
    BAD_CONFIG = 0x10
    DRV_FAULT = 0x20
    MISSING_INPUT = 0x40
    DC_BUS_OVER_VOLTAGE = 0x100
    DC_BUS_UNDER_VOLTAGE = 0x200
    DC_BUS_OVER_CURRENT = 0x400
    DC_BUS_OVER_REGEN_CURRENT = 0x800
    CURRENT_LIMIT_VIOLATION = 0x1000
    MOTOR_OVER_TEMP = 0x2000
    INVERTER_OVER_TEMP = 0x4000
    VELOCITY_LIMIT_VIOLATION = 0x8000
    POSITION_LIMIT_VIOLATION = 0x10000
    WATCHDOG_TIMER_EXPIRED = 0x1000000
    ESTOP_REQUESTED = 0x2000000
    SPINOUT_DETECTED = 0x4000000
    BRAKE_RESISTOR_DISARMED = 0x8000000
    THERMISTOR_DISCONNECTED = 0x10000000
    CALIBRATION_ERROR = 0x40000000


class AxisError05(IntFlag):
    """Axis error bits of firmware 0.5.x (ODrive v3.6; 0.5.6 DBC)."""

    INVALID_STATE = 0x1
    MOTOR_FAILED = 0x40
    SENSORLESS_ESTIMATOR_FAILED = 0x80
    ENCODER_FAILED = 0x100
    CONTROLLER_FAILED = 0x200
    WATCHDOG_TIMER_EXPIRED = 0x800
    MIN_ENDSTOP_PRESSED = 0x1000
    MAX_ENDSTOP_PRESSED = 0x2000
    ESTOP_REQUESTED = 0x4000
    HOMING_WITHOUT_ENDSTOP = 0x20000
    OVER_TEMP = 0x40000
    UNKNOWN_POSITION = 0x80000


class Firmware(Enum):
    """Which CANSimple generation the ODrive runs (heartbeat layout, error bits)."""

    V0_5 = "0.5"
    V0_6 = "0.6"

    @property
    def axis_error(self) -> type[AxisError] | type[AxisError05]:
        """The axis error flags of this firmware."""
        return AxisError05 if self is Firmware.V0_5 else AxisError


@dataclass(frozen=True)
class WatchdogEndpoints:
    """``flat_endpoints.json`` ids of the axis watchdog settings (one firmware build).

    Defaults: ``axis0.config.watchdog_timeout`` = 200 (float),
    ``axis0.config.enable_watchdog`` = 201 (bool), as listed for a 0.6.x build
    (see the module docstring). Ids move between releases: read them from the
    ``flat_endpoints.json`` of the flashed firmware.
    """

    watchdog_timeout: int = 200
    enable_watchdog: int = 201


DEFAULT_WATCHDOG_ENDPOINTS = WatchdogEndpoints()
"""The default endpoint ids (see :class:`WatchdogEndpoints`)."""


# ---------------------------------------------------------------- errors


class ODriveError(PoiseError):
    """Base class of the errors of the ODrive protocol layer."""


class InvalidCommand(ODriveError, ValueError):
    """A command that must not be put on the wire (NaN torque, gains, bad ids).

    Attributes:
        node_id: The node it was for (-1 if not yet known).
        field: Which value is wrong.
        detail: What is wrong and what to do instead.
    """

    def __init__(self, node_id: int, field: str, detail: str):
        self.node_id = node_id
        self.field = field
        self.detail = detail
        super().__init__(f"node {node_id}, {field}: {detail}")


class MalformedFrame(ODriveError, ValueError):
    """A frame whose payload does not decode (too short, NaN, unknown enum).

    Attributes:
        command: The command id it claims to be.
        data: Its payload.
        detail: What is wrong with it.
    """

    def __init__(self, command: int, data: bytes, detail: str):
        self.command = command
        self.data = bytes(data)
        self.detail = detail
        super().__init__(f"cmd 0x{command:02X} data {self.data.hex(' ')}: {detail}")


# ---------------------------------------------------------------- identifiers


def arbitration_id(node_id: int, command: int) -> int:
    """The 11-bit identifier ``node_id << 5 | cmd_id``.

    Raises:
        InvalidCommand: ``node_id`` outside 0…63 or ``command`` outside 0…31.
    """
    if not 0 <= node_id <= NODE_ID_MAX:
        raise InvalidCommand(node_id, "node_id", f"{node_id=} must be in 0…{NODE_ID_MAX}")
    if not 0 <= command <= _CMD_MASK:
        raise InvalidCommand(node_id, "command", f"{command=} must be in 0…{_CMD_MASK}")
    return node_id << _CMD_BITS | command


def split_arbitration_id(arbitration_id: int) -> tuple[int, int]:
    """``(node_id, cmd_id)`` of an 11-bit identifier."""
    return (arbitration_id >> _CMD_BITS) & NODE_ID_MAX, arbitration_id & _CMD_MASK


# ---------------------------------------------------------------- names


def describe_axis_error(axis_error: int, firmware: Firmware = Firmware.V0_6) -> str:
    """The names of the error bits set, ``|``-joined; unknown bits in hex (``""``: none)."""
    flags = firmware.axis_error
    names = [flag.name for flag in flags if flag & axis_error and flag.name]
    unknown = axis_error & ~sum(flags)
    if unknown:
        names.append(f"0x{unknown:X}")
    return "|".join(names)


def axis_state_name(state: int) -> str:
    """An axis state's name (e.g. ``IDLE``), or its number if unknown."""
    try:
        return AxisState(state).name
    except ValueError:
        return f"state {state}"
