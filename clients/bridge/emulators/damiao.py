"""A Damiao DM-J motor in MIT mode on an emulated CAN bus.

It decodes commands with the protocol's own functions (the motor applies
the quantized command the real one would), answers on its master id with
the feedback frame (status nibble, MOSFET and rotor temperatures), keeps the
registers the bridge uses, and runs its CAN timeout: a motor whose TIMEOUT
register is set and that hears no command for that long disables itself and
reports status D (communication lost) until the error is cleared (``FB``).

Assumptions where the sources say nothing (see
:mod:`clients.bridge.protocols.damiao`): a disabled motor answers commands
with status 0 without applying them; clearing an error leaves the motor
disabled; a save (``0xAA``) is answered by echoing the request.
"""

from __future__ import annotations

from dataclasses import replace

import can

from clients.bridge.actuator import ZERO_COMMAND
from clients.bridge.emulators.motor import CanDevice, EmulatedMotor
from clients.bridge.protocols.damiao import (
    PARAMETER_CAN_ID,
    DamiaoRegister,
    DamiaoSpecial,
    DamiaoStatus,
    RegisterOp,
    make_feedback,
    make_register_frame,
    parse_register_frame,
    timeout_from_register,
)
from clients.bridge.protocols.mit import (
    MalformedFrame,
    MitRanges,
    command_codes,
    parse_command,
    parse_special,
    unpack_command_codes,
)

__all__ = ["EmulatedDamiao"]


class EmulatedDamiao(CanDevice):
    """One Damiao motor: MIT frames on its id, register frames on ``0x7FF``, replies on MST_ID.

    Special frames: ``FC`` enables, ``FD`` disables, ``FE`` makes the present
    position zero, ``FB`` clears ``motor.fault_code`` (and the motor stays
    disabled). An injected ``motor.fault_code`` (a :class:`DamiaoStatus`
    fault) is reported as the status nibble. A command is taken as
    ``"safe"`` when its kp and torque codes are those of zero. A silent motor
    neither hears nor answers.

    Args:
        motor_id: Its CAN id (``ESC_ID``).
        motor: The physics it drives.
        ranges: Its PMAX / VMAX / TMAX.
        master_id: Its ``MST_ID``: where it answers.
        rotor_temperature_offset_C: Rotor minus MOSFET temperature (the
            motor's ``temperature_C`` is the rotor's).
        malformed_reply: Fault injection: answer with a frame of this many
            bytes (not 8) instead of the feedback.
    """

    def __init__(
        self,
        motor_id: int,
        motor: EmulatedMotor,
        ranges: MitRanges,
        *,
        master_id: int,
        rotor_temperature_offset_C: float = 5.0,
        malformed_reply: int | None = None,
    ):
        self.motor_id = motor_id
        self.motor = motor
        self.ranges = ranges
        self.master_id = master_id
        self.rotor_temperature_offset_C = rotor_temperature_offset_C
        self.malformed_reply = malformed_reply
        self.zero_offset_rad = 0.0
        self.registers: dict[int, int | float] = {
            DamiaoRegister.MST_ID: master_id,
            DamiaoRegister.ESC_ID: motor_id,
            DamiaoRegister.TIMEOUT: 0,
            DamiaoRegister.CTRL_MODE: 1,
            DamiaoRegister.PMAX: ranges.position_max_rad,
            DamiaoRegister.VMAX: ranges.velocity_max_rad_s,
            DamiaoRegister.TMAX: ranges.torque_max_Nm,
        }
        self._zero_torque_code = command_codes(ZERO_COMMAND, ranges)[4]
        self._enabled = False  # what it was told; the motor's own watchdog may have stopped it

    def on_frame(self, message: can.Message) -> list[can.Message]:
        """Apply a frame addressed to this motor and return its reply."""
        if message.is_extended_id or message.is_remote_frame or self.motor.silent:
            return []
        data = bytes(message.data)
        if message.arbitration_id == PARAMETER_CAN_ID:
            return self._on_register(data)
        if message.arbitration_id != self.motor_id:
            return []
        self._check_watchdog()
        special = parse_special(data)
        if special == DamiaoSpecial.ENABLE:
            if not self.motor.fault_code:
                self.motor.set_enabled(True)
                self._enabled = True
        elif special == DamiaoSpecial.DISABLE:
            self.motor.set_enabled(False)
            self._enabled = False
        elif special == DamiaoSpecial.SAVE_ZERO:
            self.zero_offset_rad = self.motor.position_rad
        elif special == DamiaoSpecial.CLEAR_ERROR:
            if self.motor.fault_code:
                self.motor.fault_code = 0
                self.motor.set_enabled(False)
                self._enabled = False
        else:
            try:
                codes = unpack_command_codes(data)
            except MalformedFrame:
                return []
            if self.motor.enabled and not self.motor.fault_code:
                command = parse_command(data, self.ranges)
                command = replace(command, position_rad=command.position_rad + self.zero_offset_rad)
                safe = codes[2] == 0 and codes[4] == self._zero_torque_code
                self.motor.take(command, "safe" if safe else "command")
        return [self._feedback()]

    def _check_watchdog(self) -> None:
        """Latch status D once the motor's own watchdog stopped it (whoever noticed first)."""
        self.motor.watchdog_expired()
        if self._enabled and not self.motor.enabled:
            self._enabled = False
            if not self.motor.fault_code:
                self.motor.fault_code = DamiaoStatus.COMMUNICATION_LOST

    def _status(self) -> int:
        if self.motor.fault_code:
            return self.motor.fault_code & 0xF
        return DamiaoStatus.ENABLED if self.motor.enabled else DamiaoStatus.DISABLED

    def _feedback(self) -> can.Message:
        if self.malformed_reply is not None:
            data = bytes(self.malformed_reply)
        else:
            m = self.motor
            data = make_feedback(
                self.motor_id,
                self._status(),
                m.position_rad - self.zero_offset_rad,
                m.velocity_rad_s,
                m.torque_Nm(),
                m.temperature_C - self.rotor_temperature_offset_C,
                m.temperature_C,
                self.ranges,
            )
        return can.Message(arbitration_id=self.master_id, data=data, is_extended_id=False)

    def _on_register(self, data: bytes) -> list[can.Message]:
        try:
            frame = parse_register_frame(data)
        except MalformedFrame:
            return []
        if frame.motor_id != self.motor_id:
            return []
        if frame.op is RegisterOp.SAVE:
            reply = data
        elif frame.register not in self.registers:
            return []  # registers it does not model: no answer
        else:
            if frame.op is RegisterOp.WRITE:
                self._write(frame.register, frame.value)
            reply = make_register_frame(
                self.motor_id, frame.op, frame.register, self.registers[frame.register]
            )
        return [can.Message(arbitration_id=self.master_id, data=reply, is_extended_id=False)]

    def _write(self, register: int, value: int | float) -> None:
        if register in (DamiaoRegister.MST_ID, DamiaoRegister.ESC_ID):
            return  # read-back only here: re-addressing a live emulator helps no test
        self.registers[register] = value
        if register == DamiaoRegister.TIMEOUT:
            self.motor.watchdog_timeout_s = timeout_from_register(int(value))
