"""ODrive CANSimple frames: pure encoders and decoders of each message's payload.

Every frame has an 11-bit standard identifier (``odrive_codes.py``) and a
little-endian payload with IEEE 754 float32 values. Messages named ``Set_*``
go host → ODrive; ``Get_*`` go ODrive → host, either cyclically or in answer
to a remote-transmission-request (RTR) frame with the same identifier. Both
directions are here: the host's commands and requests and what it parses,
and the ODrive's answers and what its emulator parses. Imported through
:mod:`clients.bridge.protocols.odrive`; the bus that sends them is ``odrive_bus.py``.

Sources (checked for this module):

* ODrive CAN protocol reference, firmware 0.6 ("CAN Protocol",
  http://newdocs.odriverobotics.com/v/latest/manual/can-protocol.html): the
  message ids and signals, little endian, RTR requests.
* The open 0.5.x firmware, ``Firmware/communication/can/can_simple.cpp`` of
  github.com/odriverobotics/ODrive: the 0.5 heartbeat layout, that every frame
  addressed to an axis feeds its watchdog (``do_command`` calls
  ``axis.watchdog_feed()`` first), and that ``Get_*`` answer an RTR frame or
  an empty data frame.

Units: ODrive speaks turns and turns/s; the bus converts to rad and rad/s on
the motor side. Torques are N·m (the ODrive applies its own torque constant).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import can

from clients.bridge.protocols.odrive_codes import (
    AxisState,
    Command,
    ControlMode,
    Firmware,
    InputMode,
    InvalidCommand,
    MalformedFrame,
    SdoOpcode,
    arbitration_id,
)

__all__ = [
    "EncoderEstimates",
    "Heartbeat",
    "SdoRequest",
    "Temperature",
    "Torques",
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
]


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
