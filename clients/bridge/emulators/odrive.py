"""An emulated ODrive axis that speaks CANSimple, frame for frame.

It decodes frames with the parse functions of
:mod:`clients.bridge.protocols.odrive` and drives an :class:`EmulatedMotor`:

* Set_Controller_Mode sets the control and input modes (the ODrive's default
  is position control, so a host that forgets to switch gets no torque).
* Set_Axis_State CLOSED_LOOP_CONTROL arms the axis (refused while an axis
  error is latched, as the firmware does); IDLE disarms it.
* Set_Input_Torque stores the float32 torque; armed in torque control, the
  motor takes it (``"safe"`` if it is zero) and its watchdog is fed. On arming,
  the stored torque applies at once, as in the firmware (passthrough input).
* Estop latches ESTOP_REQUESTED and disarms; Clear_Errors clears the axis
  errors and the motor's injected ``fault_code``.
* RxSdo writes to the watchdog endpoints set ``motor.watchdog_timeout_s``.
  When the motor's watchdog stops it, the axis latches WATCHDOG_TIMER_EXPIRED
  and goes IDLE; an injected ``motor.fault_code`` is reported as axis error
  bits and disarms the axis too.
* RTR (or empty data) frames for Heartbeat, Get_Encoder_Estimates,
  Get_Torques, Get_Temperature and Get_Iq are answered with float32 data.
  A heartbeat also goes out after each Set_Axis_State (granted or refused),
  whenever the axis state or error changes and, standing in for the cyclic
  one, with the first reply after ``heartbeat_period_s``.
* ``motor.silent``: it neither hears nor answers.

The emulator is stricter than the firmware on one point: 0.5.x feeds the
watchdog on every frame addressed to the axis, the emulator only on
Set_Input_Torque (the shared :class:`EmulatedMotor` is fed by ``take``).
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable

import can

from clients.bridge.actuator import MotorCommand
from clients.bridge.emulators.motor import CanDevice, EmulatedMotor
from clients.bridge.protocols.odrive import (
    DEFAULT_WATCHDOG_ENDPOINTS,
    AxisState,
    Command,
    ControlMode,
    Firmware,
    Heartbeat,
    InputMode,
    MalformedFrame,
    SdoOpcode,
    WatchdogEndpoints,
    arbitration_id,
    make_encoder_estimates,
    make_heartbeat,
    make_temperature,
    make_torques,
    parse_rx_sdo,
    parse_set_axis_state,
    parse_set_controller_mode,
    parse_set_input_torque,
    split_arbitration_id,
)

__all__ = ["EmulatedODrive"]

_TURN_RAD = 2.0 * math.pi


def _f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


class EmulatedODrive(CanDevice):
    """One ODrive axis (one CANSimple node) holding an :class:`EmulatedMotor`.

    Args:
        node_id: Its CAN node id.
        motor: The motor it drives (position and velocity come from
            ``motor.sense``; its torque limit is the ODrive's).
        firmware: Heartbeat layout and axis error bits to speak.
        watchdog_endpoints: Endpoint ids its RxSdo accepts for the watchdog.
        heartbeat_period_s: Period of the (emulated) cyclic heartbeat.
        clock: Time source of the heartbeat period.

    Attributes:
        axis_state: Current axis state.
        axis_error: Latched axis errors (the motor's ``fault_code`` is added
            when reported).
        control_mode / input_mode: The controller's modes.
        input_torque_Nm: The last Set_Input_Torque (float32).
        watchdog_enabled / watchdog_timeout_s: As written over RxSdo.
    """

    def __init__(
        self,
        node_id: int,
        motor: EmulatedMotor,
        *,
        firmware: Firmware = Firmware.V0_6,
        watchdog_endpoints: WatchdogEndpoints = DEFAULT_WATCHDOG_ENDPOINTS,
        heartbeat_period_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.node_id = node_id
        self.motor = motor
        self.firmware = firmware
        self.watchdog_endpoints = watchdog_endpoints
        self.heartbeat_period_s = heartbeat_period_s
        self.clock = clock
        self.axis_state = AxisState.IDLE
        self.axis_error = 0
        self.control_mode = ControlMode.POSITION_CONTROL
        self.input_mode = InputMode.PASSTHROUGH
        self.input_torque_Nm = 0.0
        self.watchdog_enabled = False
        self.watchdog_timeout_s = 0.0
        self._last_heartbeat_s = -math.inf
        self._reported: tuple[int, int] | None = None

    # ------------------------------------------------------------ state

    @property
    def _watchdog_bit(self) -> int:
        return self.firmware.axis_error.WATCHDOG_TIMER_EXPIRED

    @property
    def _estop_bit(self) -> int:
        return self.firmware.axis_error.ESTOP_REQUESTED

    def reported_error(self) -> int:
        """The axis error it reports: latched errors and the motor's injected fault."""
        return self.axis_error | self.motor.fault_code

    def _disarm(self) -> None:
        if self.axis_state == AxisState.CLOSED_LOOP_CONTROL:
            self.motor.set_enabled(False)
        self.axis_state = AxisState.IDLE

    def _check_faults(self) -> None:
        """Latch what happened since the last frame: watchdog expiry, injected faults."""
        if self.axis_state != AxisState.CLOSED_LOOP_CONTROL:
            return
        # The motor's watchdog disables it (possibly inside a torque_Nm() call of
        # the plant, so expired() may already have fired): armed but not enabled.
        if self.motor.watchdog_expired() or not self.motor.enabled:
            self.axis_error |= self._watchdog_bit
            self.axis_state = AxisState.IDLE
        if self.motor.fault_code:
            self._disarm()

    def _apply_torque(self) -> None:
        if (
            self.axis_state == AxisState.CLOSED_LOOP_CONTROL
            and self.control_mode == ControlMode.TORQUE_CONTROL
        ):
            kind = "safe" if self.input_torque_Nm == 0.0 else "command"
            self.motor.take(MotorCommand(torque_Nm=self.input_torque_Nm), kind)

    def _request_state(self, state: AxisState) -> None:
        if state == AxisState.CLOSED_LOOP_CONTROL:
            if self.reported_error() or self.axis_state == state:
                return  # the firmware refuses to arm with errors latched
            self.axis_state = state
            self.motor.set_enabled(True)
            self._apply_torque()
        elif state == AxisState.IDLE:
            self._disarm()
        # Calibration and the other procedures are not emulated.

    def _write_sdo(self, endpoint_id: int, value: bytes) -> None:
        ids = self.watchdog_endpoints
        if endpoint_id == ids.watchdog_timeout and len(value) >= 4:
            timeout_s = struct.unpack_from("<f", value)[0]
            if math.isfinite(timeout_s) and timeout_s >= 0.0:
                self.watchdog_timeout_s = timeout_s
        elif endpoint_id == ids.enable_watchdog and len(value) >= 1:
            self.watchdog_enabled = bool(value[0])
        else:
            return
        self.motor.watchdog_timeout_s = self.watchdog_timeout_s if self.watchdog_enabled else 0.0

    # ------------------------------------------------------------ frames

    def heartbeat(self) -> can.Message:
        """Its heartbeat frame now."""
        self._last_heartbeat_s = self.clock()
        self._reported = (self.axis_state, self.reported_error())
        return make_heartbeat(
            self.node_id,
            Heartbeat(axis_error=self.reported_error(), axis_state=self.axis_state),
            firmware=self.firmware,
        )

    def _answer(self, command: int) -> can.Message | None:
        motor = self.motor
        if command == Command.HEARTBEAT:
            return self.heartbeat()
        if command == Command.GET_ENCODER_ESTIMATES:
            return make_encoder_estimates(
                self.node_id,
                _f32(motor.position_rad / _TURN_RAD),
                _f32(motor.velocity_rad_s / _TURN_RAD),
            )
        if self.firmware is Firmware.V0_5:
            return None  # 0.5 has none of the messages below under these ids
        armed = self.axis_state == AxisState.CLOSED_LOOP_CONTROL
        target_Nm = (
            self.input_torque_Nm if armed and self.control_mode == ControlMode.TORQUE_CONTROL else 0
        )
        if command == Command.GET_TORQUES:
            return make_torques(self.node_id, target_Nm, _f32(motor.torque_Nm()))
        if command == Command.GET_TEMPERATURE:
            return make_temperature(self.node_id, motor.ambient_C, _f32(motor.temperature_C))
        if command == Command.GET_IQ:
            iq_A = motor.torque_Nm() / motor.torque_constant_Nm_per_A
            return can.Message(
                arbitration_id=arbitration_id(self.node_id, Command.GET_IQ),
                is_extended_id=False,
                data=struct.pack("<ff", target_Nm / motor.torque_constant_Nm_per_A, iq_A),
            )
        return None

    def on_frame(self, message: can.Message) -> list[can.Message]:
        """Handle one frame; returns the frames it sends in reply."""
        if self.motor.silent or message.is_extended_id or message.is_error_frame:
            return []
        node_id, command = split_arbitration_id(message.arbitration_id)
        if node_id != self.node_id:
            return []
        self._check_faults()
        replies: list[can.Message] = []
        data = bytes(message.data)
        is_request = message.is_remote_frame or not data
        try:
            if is_request and command in (
                Command.HEARTBEAT,
                Command.GET_ENCODER_ESTIMATES,
                Command.GET_TORQUES,
                Command.GET_TEMPERATURE,
                Command.GET_IQ,
            ):
                reply = self._answer(command)
                if reply is not None:
                    replies.append(reply)
            elif command == Command.SET_INPUT_TORQUE:
                self.input_torque_Nm = _f32(parse_set_input_torque(data))
                self._apply_torque()
            elif command == Command.SET_AXIS_STATE:
                self._request_state(parse_set_axis_state(data))
                self._reported = None  # report the outcome, refused or not
            elif command == Command.SET_CONTROLLER_MODE:
                self.control_mode, self.input_mode = parse_set_controller_mode(data)
            elif command == Command.ESTOP:
                self.axis_error |= self._estop_bit
                self._disarm()
            elif command == Command.CLEAR_ERRORS:
                self.axis_error = 0
                self.motor.fault_code = 0
            elif command == Command.RX_SDO and self.firmware is Firmware.V0_6:
                request = parse_rx_sdo(data)
                if request.opcode == SdoOpcode.WRITE:
                    self._write_sdo(request.endpoint_id, request.value)
        except MalformedFrame:
            return []  # the firmware would read garbage; the emulator drops it
        sent_heartbeat = any(
            split_arbitration_id(reply.arbitration_id)[1] == Command.HEARTBEAT for reply in replies
        )
        if not sent_heartbeat and (
            self._reported != (self.axis_state, self.reported_error())
            or self.clock() - self._last_heartbeat_s >= self.heartbeat_period_s
        ):
            replies.insert(0, self.heartbeat())
        return replies
