"""ODrive CANSimple: pure frame encoders and decoders (the bus: ``odrive_bus.py``).

CANSimple is the ODrive's own CAN protocol (firmware 0.5.x on ODrive v3.6,
0.6.x on ODrive Pro / S1 / Micro). Every frame has an 11-bit standard
identifier ``node_id << 5 | cmd_id`` (6 bits of node, 5 of command) and a
little-endian payload with IEEE 754 float32 values. Messages named ``Set_*``
go host → ODrive; ``Get_*`` go ODrive → host, either cyclically or in answer
to a remote-transmission-request (RTR) frame with the same identifier.

Sources (checked for this module):

* ODrive CAN protocol reference, firmware 0.6 ("CAN Protocol",
  http://newdocs.odriverobotics.com/v/latest/manual/can-protocol.html): the
  identifier layout, message ids and signals, little endian, RTR requests.
* The 0.6.10 and 0.5.6 CANSimple DBC files as rendered at
  https://odrive-can-roxautomation-components-9f5f4b809336bc0ecbd5b8cd8e4.gitlab.io/can_interface_pro
  and ``.../can_interface/``: axis error bits and axis states of both.
* The open 0.5.x firmware, ``Firmware/communication/can/can_simple.cpp`` of
  github.com/odriverobotics/ODrive: the 0.5 heartbeat layout, that every frame
  addressed to an axis feeds its watchdog (``do_command`` calls
  ``axis.watchdog_feed()`` first), and that ``Get_*`` answer an RTR frame or
  an empty data frame.
* ``flat_endpoints.json`` endpoint ids for ``axis0.config.watchdog_timeout``
  (200, float) and ``axis0.config.enable_watchdog`` (201, bool) as listed in a
  generated CANSimple binding for 0.6.x (endpoint map next to the RxSdo
  encoder); they change between firmware releases, so :class:`WatchdogEndpoints`
  is a parameter — check them against the ``flat_endpoints.json`` of the
  firmware you flash.

Units: ODrive speaks turns and turns/s; the bus converts to rad and rad/s on
the motor side. Torques are N·m (the ODrive applies its own torque constant).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import Enum, IntEnum, IntFlag

import can

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
    "EncoderEstimates",
    "Firmware",
    "Heartbeat",
    "InputMode",
    "InvalidCommand",
    "MalformedFrame",
    "ODriveError",
    "SdoOpcode",
    "SdoRequest",
    "Temperature",
    "Torques",
    "WatchdogEndpoints",
    "arbitration_id",
    "axis_state_name",
    "describe_axis_error",
    "make_clear_errors",
    "make_encoder_estimates",
    "make_estop",
    "make_heartbeat",
    "make_request",
    "make_rx_sdo_read",
    "make_rx_sdo_write",
    "make_set_axis_state",
    "make_set_controller_mode",
    "make_set_input_torque",
    "make_temperature",
    "make_torques",
    "parse_clear_errors",
    "parse_encoder_estimates",
    "parse_heartbeat",
    "parse_rx_sdo",
    "parse_set_axis_state",
    "parse_set_controller_mode",
    "parse_set_input_torque",
    "parse_temperature",
    "parse_torques",
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


_REQUESTABLE = frozenset(
    {
        Command.GET_VERSION,
        Command.HEARTBEAT,
        Command.GET_ERROR,
        Command.GET_ENCODER_ESTIMATES,
        Command.GET_IQ,
        Command.GET_TEMPERATURE,
        Command.GET_BUS_VOLTAGE_CURRENT,
        Command.GET_TORQUES,
        Command.GET_POWERS,
    }
)


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


def _frame(node_id: int, command: Command, data: bytes) -> can.Message:
    return can.Message(
        arbitration_id=arbitration_id(node_id, command), is_extended_id=False, data=data
    )


# ---------------------------------------------------------------- host → ODrive


def make_set_input_torque(
    node_id: int, torque_Nm: float, *, torque_limit_Nm: float | None = None
) -> can.Message:
    """Set_Input_Torque (0x0E): float32 ``Input_Torque`` in N·m.

    The torque is clamped to ``±torque_limit_Nm`` first, so an infinite
    request becomes the limit.

    Raises:
        InvalidCommand: The torque is NaN (the ODrive would take NaN as a
            valid input and its behaviour then depends on firmware and input
            mode), or infinite with no limit to clamp it to, or it overflows
            float32.
    """
    if math.isnan(torque_Nm):
        raise InvalidCommand(node_id, "torque_Nm", f"{torque_Nm=} is NaN; send a number")
    if torque_limit_Nm is not None:
        torque_Nm = max(-torque_limit_Nm, min(torque_limit_Nm, torque_Nm))
    try:
        if not math.isfinite(torque_Nm):
            raise OverflowError
        data = struct.pack("<f", torque_Nm)
    except OverflowError:
        raise InvalidCommand(
            node_id, "torque_Nm", f"{torque_Nm=} is not a finite float32; configure a torque limit"
        ) from None
    return _frame(node_id, Command.SET_INPUT_TORQUE, data)


def make_set_axis_state(node_id: int, state: AxisState) -> can.Message:
    """Set_Axis_State (0x07): uint32 ``Axis_Requested_State``."""
    return _frame(node_id, Command.SET_AXIS_STATE, struct.pack("<I", AxisState(state)))


def make_set_controller_mode(
    node_id: int, control_mode: ControlMode, input_mode: InputMode
) -> can.Message:
    """Set_Controller_Mode (0x0B): uint32 ``Control_Mode``, uint32 ``Input_Mode``."""
    data = struct.pack("<II", ControlMode(control_mode), InputMode(input_mode))
    return _frame(node_id, Command.SET_CONTROLLER_MODE, data)


def make_estop(node_id: int) -> can.Message:
    """Estop (0x02), no payload: the axis latches ESTOP_REQUESTED and disarms."""
    return _frame(node_id, Command.ESTOP, b"")


def make_clear_errors(node_id: int, *, identify: bool = False) -> can.Message:
    """Clear_Errors (0x18): uint8 ``Identify`` (0.6.9+; older firmware ignores the byte)."""
    return _frame(node_id, Command.CLEAR_ERRORS, bytes([int(identify)]))


def make_request(node_id: int, command: Command) -> can.Message:
    """A remote-transmission request for a ``Get_*`` message (or the heartbeat).

    The ODrive answers with the data frame of the same identifier. (An empty
    data frame works too but can collide with the answer, says the reference.)

    Raises:
        InvalidCommand: ``command`` is not one the ODrive sends.
    """
    command = Command(command)
    if command not in _REQUESTABLE:
        raise InvalidCommand(node_id, "command", f"{command.name} is not a message to request")
    return can.Message(
        arbitration_id=arbitration_id(node_id, command),
        is_extended_id=False,
        is_remote_frame=True,
        dlc=8,
    )


_SDO_FORMATS = {
    "bool": "?",
    "uint8": "B",
    "int8": "b",
    "uint16": "H",
    "int16": "h",
    "uint32": "I",
    "int32": "i",
    "float": "f",
}


def make_rx_sdo_write(
    node_id: int, endpoint_id: int, value: float | bool, value_type: str
) -> can.Message:
    """RxSdo (0x04) write: uint8 opcode 1, uint16 endpoint id, uint8 reserved, value.

    The value is packed little-endian at its natural size (``bool`` one byte,
    ``float`` four), as ``struct.pack('<BHB' + fmt, ...)`` in the flat_endpoints
    scripts does (e.g. github.com/Trana/ros_odrive, ``odrive_config_setter/set_config.py``).

    Raises:
        InvalidCommand: Unknown ``value_type`` (one of ``bool``, ``uint8``,
            ``int8``, ``uint16``, ``int16``, ``uint32``, ``int32``, ``float``),
            an endpoint id that is not 16-bit, or a NaN float.
    """
    if value_type not in _SDO_FORMATS:
        raise InvalidCommand(node_id, "value_type", f"{value_type=} not in {sorted(_SDO_FORMATS)}")
    if not 0 <= endpoint_id <= 0xFFFF:
        raise InvalidCommand(node_id, "endpoint_id", f"{endpoint_id=} is not a uint16")
    if value_type == "float" and math.isnan(value):
        raise InvalidCommand(node_id, "value", f"{value=} is NaN")
    try:
        value_bytes = struct.pack("<" + _SDO_FORMATS[value_type], value)
    except (struct.error, OverflowError) as error:
        raise InvalidCommand(
            node_id, "value", f"{value=} does not fit {value_type}: {error}"
        ) from error
    payload = struct.pack("<BHB", SdoOpcode.WRITE, endpoint_id, 0) + value_bytes
    return _frame(node_id, Command.RX_SDO, payload)


def make_rx_sdo_read(node_id: int, endpoint_id: int) -> can.Message:
    """RxSdo (0x04) read: the ODrive answers TxSdo (0x05) with the value."""
    if not 0 <= endpoint_id <= 0xFFFF:
        raise InvalidCommand(node_id, "endpoint_id", f"{endpoint_id=} is not a uint16")
    return _frame(node_id, Command.RX_SDO, struct.pack("<BHB", SdoOpcode.READ, endpoint_id, 0))


# ---------------------------------------------------------------- ODrive → host


@dataclass(frozen=True)
class Heartbeat:
    """Heartbeat (0x01).

    0.6 layout: uint32 ``Axis_Error``, uint8 ``Axis_State``, uint8
    ``Procedure_Result``, uint8 ``Trajectory_Done_Flag`` (bit 0), a reserved
    byte. 0.5 layout: the same error and state, then uint8 motor, encoder
    and controller error flags, the trajectory-done flag in bit 7 of the last
    byte (``send_heartbeat`` in 0.5's ``can_simple.cpp``).
    """

    axis_error: int
    axis_state: int
    procedure_result: int = 0
    trajectory_done: bool = False
    motor_error_flag: bool = False
    encoder_error_flag: bool = False
    controller_error_flag: bool = False


@dataclass(frozen=True)
class EncoderEstimates:
    """Get_Encoder_Estimates (0x09): float32 position (turns), velocity (turns/s)."""

    position_turns: float
    velocity_turns_s: float


@dataclass(frozen=True)
class Torques:
    """Get_Torques (0x1C): float32 ``Torque_Target``, ``Torque_Estimate`` (N·m)."""

    target_Nm: float
    estimate_Nm: float


@dataclass(frozen=True)
class Temperature:
    """Get_Temperature (0x15): float32 ``FET_Temperature``, ``Motor_Temperature`` (°C).

    The ODrive reports NaN for a thermistor it does not have.
    """

    fet_C: float
    motor_C: float


@dataclass(frozen=True)
class SdoRequest:
    """A decoded RxSdo frame: opcode, endpoint id and the raw value bytes."""

    opcode: int
    endpoint_id: int
    value: bytes


def make_heartbeat(
    node_id: int, heartbeat: Heartbeat, *, firmware: Firmware = Firmware.V0_6
) -> can.Message:
    """The heartbeat data frame, in the layout of ``firmware``."""
    if firmware is Firmware.V0_5:
        tail = bytes(
            [
                int(heartbeat.motor_error_flag),
                int(heartbeat.encoder_error_flag),
                int(heartbeat.controller_error_flag) | int(heartbeat.trajectory_done) << 7,
            ]
        )
    else:
        tail = bytes([heartbeat.procedure_result, int(heartbeat.trajectory_done), 0])
    data = struct.pack("<IB", heartbeat.axis_error, heartbeat.axis_state) + tail
    return _frame(node_id, Command.HEARTBEAT, data)


def make_encoder_estimates(
    node_id: int, position_turns: float, velocity_turns_s: float
) -> can.Message:
    """Get_Encoder_Estimates data frame (what the ODrive answers)."""
    data = struct.pack("<ff", position_turns, velocity_turns_s)
    return _frame(node_id, Command.GET_ENCODER_ESTIMATES, data)


def make_torques(node_id: int, target_Nm: float, estimate_Nm: float) -> can.Message:
    """Get_Torques data frame."""
    return _frame(node_id, Command.GET_TORQUES, struct.pack("<ff", target_Nm, estimate_Nm))


def make_temperature(node_id: int, fet_C: float, motor_C: float) -> can.Message:
    """Get_Temperature data frame."""
    return _frame(node_id, Command.GET_TEMPERATURE, struct.pack("<ff", fet_C, motor_C))


def _need(command: Command, data: bytes, size: int) -> None:
    if len(data) < size:
        raise MalformedFrame(command, data, f"{len(data)} bytes, need {size}")


def parse_set_input_torque(data: bytes) -> float:
    """``Input_Torque`` (N·m) of a Set_Input_Torque payload."""
    _need(Command.SET_INPUT_TORQUE, data, 4)
    return struct.unpack_from("<f", data)[0]


def parse_set_axis_state(data: bytes) -> AxisState:
    """The requested state of a Set_Axis_State payload."""
    _need(Command.SET_AXIS_STATE, data, 4)
    (value,) = struct.unpack_from("<I", data)
    try:
        return AxisState(value)
    except ValueError:
        raise MalformedFrame(Command.SET_AXIS_STATE, data, f"no axis state {value}") from None


def parse_set_controller_mode(data: bytes) -> tuple[ControlMode, InputMode]:
    """``(control_mode, input_mode)`` of a Set_Controller_Mode payload."""
    _need(Command.SET_CONTROLLER_MODE, data, 8)
    control, input_ = struct.unpack_from("<II", data)
    try:
        return ControlMode(control), InputMode(input_)
    except ValueError as error:
        raise MalformedFrame(Command.SET_CONTROLLER_MODE, data, str(error)) from None


def parse_clear_errors(data: bytes) -> bool:
    """The ``Identify`` flag of a Clear_Errors payload (absent: False)."""
    return bool(data[0] & 1) if data else False


def parse_heartbeat(data: bytes, *, firmware: Firmware = Firmware.V0_6) -> Heartbeat:
    """A heartbeat payload in the layout of ``firmware`` (see :class:`Heartbeat`)."""
    _need(Command.HEARTBEAT, data, 8)
    axis_error, axis_state, b5, b6, b7 = struct.unpack_from("<IBBBB", data)
    if firmware is Firmware.V0_5:
        return Heartbeat(
            axis_error,
            axis_state,
            trajectory_done=bool(b7 & 0x80),
            motor_error_flag=bool(b5),
            encoder_error_flag=bool(b6),
            controller_error_flag=bool(b7 & 0x7F),
        )
    return Heartbeat(axis_error, axis_state, procedure_result=b5, trajectory_done=bool(b6 & 1))


def _two_floats(command: Command, data: bytes) -> tuple[float, float]:
    _need(command, data, 8)
    return struct.unpack_from("<ff", data)


def parse_encoder_estimates(data: bytes) -> EncoderEstimates:
    """A Get_Encoder_Estimates payload.

    Raises:
        MalformedFrame: Too short, or a NaN estimate.
    """
    position, velocity = _two_floats(Command.GET_ENCODER_ESTIMATES, data)
    if math.isnan(position) or math.isnan(velocity):
        raise MalformedFrame(Command.GET_ENCODER_ESTIMATES, data, "NaN estimate")
    return EncoderEstimates(position, velocity)


def parse_torques(data: bytes) -> Torques:
    """A Get_Torques payload."""
    return Torques(*_two_floats(Command.GET_TORQUES, data))


def parse_temperature(data: bytes) -> Temperature:
    """A Get_Temperature payload."""
    return Temperature(*_two_floats(Command.GET_TEMPERATURE, data))


def parse_rx_sdo(data: bytes) -> SdoRequest:
    """An RxSdo payload: opcode, endpoint id, then the value bytes (after the reserved byte)."""
    _need(Command.RX_SDO, data, 4)
    opcode, endpoint_id, _reserved = struct.unpack_from("<BHB", data)
    return SdoRequest(opcode, endpoint_id, bytes(data[4:]))


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
