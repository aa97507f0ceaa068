"""The I/O layer of the MIT-mode and Damiao CAN protocols: :class:`MitBus` and :class:`DamiaoBus`.

Both implement :class:`clients.bridge.actuator.ActuatorBus` over any
python-can bus (SocketCAN, a USB adapter, the ``virtual`` interface of the
emulators). The caller opens the channel and hands the bus over; ``close``
shuts it down. Frames are built and read by the pure functions of
:mod:`~clients.bridge.protocols.mit` and :mod:`~clients.bridge.protocols.damiao`;
this module only sends them and gathers the answers.

Every exchange first drops frames left on the bus (late answers to the last
exchange, so they cannot pass for fresh ones), sends all frames, then reads
until each actuator answered or the bus's reply timeout passed. Frames of
other devices and malformed answers are skipped (an actuator whose answer was
malformed reads as silent: ``None``). python-can failures become
:class:`~clients.bridge.actuator.BusError`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from typing import TypeVar

import can

from clients.bridge.actuator import BusError, MotorCommand, MotorFeedback
from clients.bridge.protocols.damiao import (
    PARAMETER_CAN_ID,
    DamiaoMotor,
    DamiaoRegister,
    DamiaoSpecial,
    RegisterOp,
    make_register_read,
    make_register_write,
    parse_feedback,
    parse_register_frame,
    timeout_to_register,
)
from clients.bridge.protocols.mit import (
    MalformedFrame,
    MitRanges,
    MitSpecial,
    make_command,
    make_special,
    parse_reply,
)

__all__ = ["CanChannel", "DamiaoBus", "MitBus", "RegisterWriteError"]

_T = TypeVar("_T")
_DRAIN_LIMIT = 10_000  # frames dropped before an exchange at most (a flooding bus still ends)


class RegisterWriteError(BusError):
    """Actuators did not confirm a register write (no reply, or another value read back).

    Attributes:
        motor_ids: The actuators that did not confirm.
    """

    def __init__(self, bus: str, detail: str, motor_ids: tuple[int, ...]):
        self.motor_ids = motor_ids
        super().__init__(bus, detail)


class CanChannel:
    """Sending, draining and gathering on one python-can bus, with the errors as BusError.

    The base of every CAN actuator bus (MIT, Damiao, ODrive): it owns the
    python-can bus, shuts it down once on :meth:`close`, and is a context
    manager.
    """

    def __init__(self, bus: can.BusABC, name: str, reply_timeout_s: float):
        if not reply_timeout_s > 0.0:
            raise ValueError(f"{reply_timeout_s=}: expected > 0")
        self.name = name
        self.reply_timeout_s = reply_timeout_s
        self._bus = bus
        self._closed = False

    def _send(self, frames: Iterable[can.Message]) -> None:
        for frame in frames:
            try:
                self._bus.send(frame, timeout=self.reply_timeout_s)
            except (can.CanError, OSError) as error:
                raise BusError(
                    self.name,
                    f"sending {frame.arbitration_id:#05x} {bytes(frame.data).hex(' ')} failed: "
                    f"{error} (is the interface up, the bus terminated, an actuator powered?)",
                ) from error

    def _recv(self, timeout_s: float) -> can.Message | None:
        try:
            return self._bus.recv(timeout=timeout_s)
        except (can.CanError, OSError) as error:
            raise BusError(
                self.name, f"receiving failed: {error} (is the interface up?)"
            ) from error

    def _drain(self) -> None:
        for _ in range(_DRAIN_LIMIT):
            if self._recv(0.0) is None:
                return

    def _read_until(self, take: Callable[[can.Message], bool]) -> None:
        """Hand each frame to ``take`` until it says every answer is in, or the timeout passed."""
        deadline = time.monotonic() + self.reply_timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return
            message = self._recv(remaining)
            if message is None or take(message):
                return

    def _gather(
        self, expected: Iterable[int], parse: Callable[[can.Message], tuple[int, _T] | None]
    ) -> dict[int, _T]:
        """Read until every expected id answered or the timeout passed (newest answer kept)."""
        pending = set(expected)
        answers: dict[int, _T] = {}

        def take(message: can.Message) -> bool:
            if message.is_error_frame or message.is_remote_frame or message.is_extended_id:
                return False
            try:
                answer = parse(message)
            except MalformedFrame:
                return False  # counts as nothing: the actuator reads as silent if no valid answer
            if answer is not None and answer[0] in answers.keys() | pending:
                answers[answer[0]] = answer[1]
                pending.discard(answer[0])
            return not pending

        if pending:
            self._read_until(take)
        return answers

    def _round_trip(
        self,
        frames: list[can.Message],
        expected: Iterable[int],
        parse: Callable[[can.Message], tuple[int, _T] | None],
    ) -> dict[int, _T]:
        self._drain()
        self._send(frames)
        return self._gather(expected, parse)

    def close(self) -> None:
        """Shut the python-can bus down (once)."""
        if not self._closed:
            self._closed = True
            self._bus.shutdown()

    def __enter__(self) -> CanChannel:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _frame(arbitration_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)


def _check_commands(name: str, known: Mapping[int, object], ids: Iterable[int]) -> None:
    unknown = sorted(set(ids) - set(known))
    if unknown:
        raise ValueError(f"bus {name!r} has no actuator {unknown} (it has {sorted(known)})")


class _MitFramedBus(CanChannel):
    """A bus of actuators commanded with MIT-mode frames (MIT and Damiao): one exchange."""

    _ranges_by_id: dict[int, MitRanges]
    actuator_ids: tuple[int, ...]

    def _parse(self, message: can.Message) -> tuple[int, MotorFeedback] | None:
        raise NotImplementedError

    def exchange(self, commands: Mapping[int, MotorCommand]) -> dict[int, MotorFeedback | None]:
        """Send each actuator its command (clamped to its ranges) and return its reply.

        Raises:
            BusError: The bus failed.
            NonFiniteValue: A command holds NaN or ±inf (nothing is sent then).
            ValueError: A command is for an actuator not on this bus.
        """
        _check_commands(self.name, self._ranges_by_id, commands)
        frames = [_frame(i, make_command(c, self._ranges_by_id[i])) for i, c in commands.items()]
        answers = self._round_trip(frames, commands, self._parse)
        return {motor_id: answers.get(motor_id) for motor_id in commands}

    def _special(self, code: int) -> None:
        frame = make_special(code)
        self._round_trip(
            [_frame(i, frame) for i in self.actuator_ids], self.actuator_ids, self._parse
        )


class MitBus(_MitFramedBus):
    """MIT-mode actuators (bgkatz motorcontrol firmware, CubeMars AK) on one CAN bus.

    Commands go on each actuator's CAN id; replies come on ``master_id``
    (``CAN_MASTER`` in the firmware, 0 by default) with the actuator's id in
    their first byte. The firmware answers every frame addressed to it, in
    or out of motor mode (out of it the command is ignored), so an
    :meth:`exchange` of :data:`~clients.bridge.actuator.ZERO_COMMAND` reads
    the positions before :meth:`enable`.

    The firmware's CAN timeout can only be set over its serial menu:
    :meth:`arm_watchdog` does nothing, and MIT actuators keep applying their
    last command if the bridge stops (set that timeout on every motor).

    Args:
        bus: An open python-can bus (closed by :meth:`close`).
        ranges: Each actuator's CAN id (1–255) and its model's ranges.
        name: The bus's name in errors (from the actuator map).
        reply_timeout_s: How long an exchange waits for the replies.
        master_id: The CAN id replies come on.
    """

    def __init__(
        self,
        bus: can.BusABC,
        ranges: Mapping[int, MitRanges],
        *,
        name: str = "",
        reply_timeout_s: float = 0.002,
        master_id: int = 0,
    ):
        super().__init__(bus, name, reply_timeout_s)
        for motor_id in ranges:
            if not 1 <= motor_id <= 0xFF or motor_id == master_id:
                raise ValueError(
                    f"bus {name!r}: MIT motor id {motor_id:#x} must be 1–255 (the reply carries "
                    f"it in one byte) and differ from master_id {master_id:#x}"
                )
        self.ranges = dict(ranges)
        self._ranges_by_id = self.ranges
        self.master_id = master_id
        self.actuator_ids = tuple(sorted(self.ranges))

    def _parse(self, message: can.Message) -> tuple[int, MotorFeedback] | None:
        if message.arbitration_id != self.master_id or not message.data:
            return None
        ranges = self.ranges.get(message.data[0])
        if ranges is None:
            return None
        reply = parse_reply(bytes(message.data), ranges)
        return reply.motor_id, reply.feedback

    def enable(self) -> None:
        """Enter motor mode on every actuator (``FF…FC``)."""
        self._special(MitSpecial.ENTER_MOTOR_MODE)

    def arm_watchdog(self, timeout_s: float) -> None:
        """Nothing: the bgkatz firmware's CAN timeout is set over its serial menu only."""

    def hold_safe(
        self, damping_Nm_s_per_rad: Mapping[int, float]
    ) -> dict[int, MotorFeedback | None]:
        """Command ``kp = 0``, ``kd`` = the damping (clamped), ``τ = 0``; return the feedback."""
        return self.exchange(
            {i: MotorCommand(kd_Nm_s_per_rad=kd) for i, kd in damping_Nm_s_per_rad.items()}
        )

    def clear_faults(self) -> None:
        """Nothing: MIT firmware has no clear-fault frame (exit and re-enter motor mode)."""

    def disable(self) -> None:
        """Exit motor mode on every actuator (``FF…FD``): the motors go limp."""
        self._special(MitSpecial.EXIT_MOTOR_MODE)


class DamiaoBus(_MitFramedBus):
    """Damiao DM-J motors in MIT mode on one CAN bus.

    Commands go on each motor's CAN id (``ESC_ID``); feedback and register
    replies come on its master id (``MST_ID``), with the low nibble of its
    id in feedback byte 0. Motors may share a master id if the low nibbles
    of their ids differ. A disabled motor answers commands (status 0) but
    does not apply them. The feedback's ``fault`` / ``fault_code`` carry the
    status nibble when it is a fault (8–E); disabled and enabled are not.

    Args:
        bus: An open python-can bus (closed by :meth:`close`).
        motors: Each motor's CAN id and its ranges and master id.
        name: The bus's name in errors (from the actuator map).
        reply_timeout_s: How long an exchange waits for the replies.
    """

    def __init__(
        self,
        bus: can.BusABC,
        motors: Mapping[int, DamiaoMotor],
        *,
        name: str = "",
        reply_timeout_s: float = 0.002,
    ):
        super().__init__(bus, name, reply_timeout_s)
        self.motors = dict(motors)
        self._ranges_by_id = {motor_id: motor.ranges for motor_id, motor in self.motors.items()}
        self.actuator_ids = tuple(sorted(self.motors))
        self._by_reply: dict[tuple[int, int], int] = {}
        for motor_id, motor in self.motors.items():
            if not 1 <= motor_id <= 0x7FF or motor_id == PARAMETER_CAN_ID:
                raise ValueError(f"bus {name!r}: Damiao motor id {motor_id:#x} must be 1–0x7FE")
            if motor.master_id in self.motors:
                raise ValueError(
                    f"bus {name!r}: motor {motor_id:#x} answers on {motor.master_id:#x}, "
                    "which is another motor's command id"
                )
            key = (motor.master_id, motor_id & 0xF)
            if key in self._by_reply:
                raise ValueError(
                    f"bus {name!r}: motors {self._by_reply[key]:#x} and {motor_id:#x} share master"
                    f" id {motor.master_id:#x} and id low nibble: their replies look alike"
                )
            self._by_reply[key] = motor_id

    def _parse(self, message: can.Message) -> tuple[int, MotorFeedback] | None:
        if not message.data:
            return None
        motor_id = self._by_reply.get((message.arbitration_id, message.data[0] & 0xF))
        if motor_id is None:
            return None
        return motor_id, parse_feedback(bytes(message.data), self.motors[motor_id].ranges).feedback

    def enable(self) -> None:
        """Enable every motor (``FF…FC``)."""
        self._special(DamiaoSpecial.ENABLE)

    def disable(self) -> None:
        """Disable every motor (``FF…FD``)."""
        self._special(DamiaoSpecial.DISABLE)

    def clear_faults(self) -> None:
        """Clear every motor's latched error (``FF…FB``); it stays disabled until enabled."""
        self._special(DamiaoSpecial.CLEAR_ERROR)

    def hold_safe(
        self, damping_Nm_s_per_rad: Mapping[int, float]
    ) -> dict[int, MotorFeedback | None]:
        """Command ``kp = 0``, ``kd`` = the damping (clamped), ``τ = 0``; return the feedback."""
        return self.exchange(
            {i: MotorCommand(kd_Nm_s_per_rad=kd) for i, kd in damping_Nm_s_per_rad.items()}
        )

    def _register_parser(
        self, op: RegisterOp, register: int
    ) -> Callable[[can.Message], tuple[int, int | float] | None]:
        def parse(message: can.Message) -> tuple[int, int | float] | None:
            if len(message.data) != 8 or message.data[2] != op or message.data[3] != register:
                return None  # feedback, or another register's reply
            frame = parse_register_frame(bytes(message.data))
            motor = self.motors.get(frame.motor_id)
            if motor is None or motor.master_id != message.arbitration_id:
                return None
            return frame.motor_id, frame.value

        return parse

    def read_register(self, register: int) -> dict[int, int | float | None]:
        """Read one register of every motor (``0x33`` on ``0x7FF``); ``None``: no reply."""
        frames = [_frame(PARAMETER_CAN_ID, make_register_read(i, register)) for i in self.motors]
        answers = self._round_trip(
            frames, self.actuator_ids, self._register_parser(RegisterOp.READ, register)
        )
        return {motor_id: answers.get(motor_id) for motor_id in self.actuator_ids}

    def write_register(
        self, register: int, values: Mapping[int, int | float]
    ) -> dict[int, int | float | None]:
        """Write one register of some motors (``0x55``, RAM only); the values they echo back.

        Raises:
            ValueError: A motor is not on this bus, or a value does not fit the register.
        """
        _check_commands(self.name, self.motors, values)
        frames = [
            _frame(PARAMETER_CAN_ID, make_register_write(i, register, v)) for i, v in values.items()
        ]
        answers = self._round_trip(
            frames, values, self._register_parser(RegisterOp.WRITE, register)
        )
        return {motor_id: answers.get(motor_id) for motor_id in values}

    def arm_watchdog(self, timeout_s: float) -> None:
        """Write every motor's TIMEOUT register (units of 50 µs; 0 turns it off) and check it.

        A motor that then hears no command for ``timeout_s`` disables itself
        and reports status D (communication lost) until its faults are cleared.

        Raises:
            RegisterWriteError: A motor did not echo the value back.
            BusError: The bus failed.
        """
        units = timeout_to_register(timeout_s)
        echoed = self.write_register(DamiaoRegister.TIMEOUT, dict.fromkeys(self.motors, units))
        failed = tuple(i for i, value in echoed.items() if value != units)
        if failed:
            got = {i: echoed[i] for i in failed}
            raise RegisterWriteError(
                self.name,
                f"TIMEOUT={units} ({timeout_s} s) not confirmed by motors {list(failed)} "
                f"(echoed {got}; None: no reply within {self.reply_timeout_s} s — check their "
                "ids, master ids and that they are powered)",
                failed,
            )
