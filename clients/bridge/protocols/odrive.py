"""ODrive CANSimple: pure frame encoders and decoders (the bus: ``odrive_bus.py``).

CANSimple is the ODrive's own CAN protocol (firmware 0.5.x on ODrive v3.6,
0.6.x on ODrive Pro / S1 / Micro). Every frame has an 11-bit standard
identifier ``node_id << 5 | cmd_id`` (6 bits of node, 5 of command) and a
little-endian payload with IEEE 754 float32 values. Messages named ``Set_*``
go host → ODrive; ``Get_*`` go ODrive → host, either cyclically or in answer
to a remote-transmission-request (RTR) frame with the same identifier.

This module is the protocol's one import: it re-exports the names of two
modules, the second importing the first:

* ``odrive_codes``: what the numbers in a frame mean (identifier layout,
  command ids, axis states, control and input modes, the axis error bits of
  firmware 0.5 and 0.6, the watchdog's endpoint ids) and the errors;
* ``odrive_frames``: the encoders and decoders of each message's payload,
  both directions.

Sources (checked for these modules):

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

from clients.bridge.protocols.odrive_codes import (
    DEFAULT_WATCHDOG_ENDPOINTS,
    NODE_ID_MAX,
    TURN_RAD,
    AxisError,
    AxisError05,
    AxisState,
    Command,
    ControlMode,
    Firmware,
    InputMode,
    InvalidCommand,
    MalformedFrame,
    ODriveError,
    SdoOpcode,
    WatchdogEndpoints,
    arbitration_id,
    axis_state_name,
    describe_axis_error,
    split_arbitration_id,
)
from clients.bridge.protocols.odrive_frames import (
    EncoderEstimates,
    Heartbeat,
    SdoRequest,
    Temperature,
    Torques,
    make_clear_errors,
    make_encoder_estimates,
    make_estop,
    make_heartbeat,
    make_request,
    make_rx_sdo_read,
    make_rx_sdo_write,
    make_set_axis_state,
    make_set_controller_mode,
    make_set_input_torque,
    make_temperature,
    make_torques,
    parse_clear_errors,
    parse_encoder_estimates,
    parse_heartbeat,
    parse_rx_sdo,
    parse_set_axis_state,
    parse_set_controller_mode,
    parse_set_input_torque,
    parse_temperature,
    parse_torques,
)

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
