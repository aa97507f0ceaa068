"""An MIT-mode actuator (bgkatz motorcontrol firmware, CubeMars AK) on an emulated CAN bus.

It reads frames with the protocol's own decoder
(:func:`clients.bridge.protocols.mit.parse_command`), so the command its
:class:`~clients.bridge.emulators.motor.EmulatedMotor` applies is the
quantized one the real firmware would apply, and it answers every frame
addressed to it like the firmware: in motor mode or not (a command outside
motor mode is ignored but answered), with the 6-byte bgkatz reply or the
8-byte CubeMars one (temperature, error code).
"""

from __future__ import annotations

from dataclasses import replace

import can

from clients.bridge.actuator import ZERO_COMMAND
from clients.bridge.emulators.motor import CanDevice, EmulatedMotor
from clients.bridge.protocols.mit import (
    MalformedFrame,
    MitRanges,
    MitSpecial,
    command_codes,
    make_reply,
    parse_command,
    parse_special,
    unpack_command_codes,
)

__all__ = ["EmulatedMitActuator"]


class EmulatedMitActuator(CanDevice):
    """One MIT-mode actuator: frames on its CAN id in, replies on the master id out.

    Special frames: ``FC`` enables the motor, ``FD`` disables it, ``FE``
    makes the present position zero (an offset the emulator applies both
    ways). A command is taken as ``"safe"`` when its kp and torque codes are
    those of zero (the decoded torque of a zero command is ``−T_MAX/4095``,
    not 0), else as ``"command"``. A silent motor neither hears nor answers.

    Args:
        motor_id: Its CAN id (1–255).
        motor: The physics it drives.
        ranges: Its firmware's ranges.
        master_id: The CAN id it answers on.
        reply_length: 6 (bgkatz) or 8 (CubeMars, with temperature and ``motor.fault_code``).
        malformed_reply: Fault injection: answer with a frame of this many bytes
            (neither 6 nor 8) instead of a valid reply.
    """

    def __init__(
        self,
        motor_id: int,
        motor: EmulatedMotor,
        ranges: MitRanges,
        *,
        master_id: int = 0,
        reply_length: int = 6,
        malformed_reply: int | None = None,
    ):
        if reply_length not in (6, 8):
            raise ValueError(f"{reply_length=}: expected 6 (bgkatz) or 8 (CubeMars)")
        self.motor_id = motor_id
        self.motor = motor
        self.ranges = ranges
        self.master_id = master_id
        self.reply_length = reply_length
        self.malformed_reply = malformed_reply
        self.zero_offset_rad = 0.0
        self._zero_torque_code = command_codes(ZERO_COMMAND, ranges)[4]

    def on_frame(self, message: can.Message) -> list[can.Message]:
        """Apply a frame addressed to this actuator and return its reply."""
        if (
            message.is_extended_id
            or message.is_remote_frame
            or message.arbitration_id != self.motor_id
            or self.motor.silent
        ):
            return []
        data = bytes(message.data)
        special = parse_special(data)
        if special == MitSpecial.ENTER_MOTOR_MODE:
            self.motor.set_enabled(True)
        elif special == MitSpecial.EXIT_MOTOR_MODE:
            self.motor.set_enabled(False)
        elif special == MitSpecial.SET_ZERO:
            self.zero_offset_rad = self.motor.position_rad
        elif special is None:
            try:
                command = parse_command(data, self.ranges)
            except MalformedFrame:
                return []  # the firmware drops frames of another length
            if self.motor.enabled:
                codes = unpack_command_codes(data)
                safe = codes[2] == 0 and codes[4] == self._zero_torque_code
                command = replace(command, position_rad=command.position_rad + self.zero_offset_rad)
                self.motor.take(command, "safe" if safe else "command")
        return [self._reply()]

    def _reply(self) -> can.Message:
        if self.malformed_reply is not None:
            data = bytes((self.motor_id,)) + bytes(max(0, self.malformed_reply - 1))
        else:
            m = self.motor
            data = make_reply(
                self.motor_id,
                m.position_rad - self.zero_offset_rad,
                m.velocity_rad_s,
                m.torque_Nm(),
                self.ranges,
                temperature_C=m.temperature_C if self.reply_length == 8 else None,
                fault_code=m.fault_code,
            )
        return can.Message(arbitration_id=self.master_id, data=data, is_extended_id=False)
