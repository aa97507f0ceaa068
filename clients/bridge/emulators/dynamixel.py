"""Dynamixel X-series servos on a pseudo-terminal, answering Protocol 2.0 like the real ones.

A host (``dynamixel-sdk``, :class:`~clients.bridge.protocols.dynamixel_bus.DynamixelBus`)
opens :attr:`DynamixelEmulator.port` as its serial port. A thread parses the
instruction packets with :class:`~clients.bridge.protocols.dynamixel.PacketReader`
and answers from a control table per servo (a ``bytearray`` at the real
addresses), as the e-Manual describes (https://emanual.robotis.com/docs/en/dxl/protocol2/
and the X-series model pages):

- PING, READ, WRITE, REBOOT, SYNC READ (servos answer in the order of the
  IDs in the packet) and SYNC WRITE (no answer); broadcast PING answers in ID
  order, broadcast WRITE executes silently; other instructions answer
  Instruction Error.
- A packet with a bad CRC addressed to a servo is answered with status error
  CRC (0x03).
- EEPROM (addresses < 64) is writable only with Torque Enable 0 (Access
  Error otherwise); read-only registers answer Access Error; a Goal Current
  beyond Current Limit (38) answers Data Limit Error.
- Goal Current drives the servo's :class:`EmulatedMotor` (``take`` with the
  torque of :func:`torque_from_current`, kind ``"safe"`` for 0) only with
  torque on in current-control mode (other modes make no torque here: their
  position/velocity loops are not modelled).
- Bus Watchdog (98) sets the motor's own watchdog. When it fires the
  register reads −1, Torque Enable stays 1, and Goal Current writes answer
  Data Range Error until 0 is written to the register (then goals are
  accepted again). The motor's watchdog counts commands; the real servo
  counts every instruction packet, so a host that only reads would trip the
  emulated one sooner (the bridge always writes before it reads).
- ``motor.fault_code`` (a :class:`HardwareError` value) latches into
  Hardware Error Status (70), turns torque off and sets the alert bit of
  every status packet; REBOOT clears it (and the motor's fault) and resets
  the RAM area.
- ``motor.silent``: the servo hears nothing and answers nothing.
- Replies wait the Return Delay Time (9), in 2 µs units (X default 250 =
  500 µs), before the first status packet of a request.
"""

from __future__ import annotations

import math
import os
import select
import threading
import time
import tty
from collections.abc import Mapping

from clients.bridge.actuator import MotorCommand
from clients.bridge.emulators.motor import EmulatedMotor
from clients.bridge.protocols.dynamixel import (
    ALERT_BIT,
    BROADCAST_ID,
    BUS_WATCHDOG_UNIT_S,
    EEPROM_END,
    POSITION_UNIT_RAD,
    REGISTER_SIZE_BYTES,
    RETURN_DELAY_UNIT_S,
    VELOCITY_UNIT_RAD_S,
    ControlTable,
    DynamixelModel,
    Instruction,
    OperatingMode,
    Packet,
    PacketError,
    PacketReader,
    StatusError,
    current_from_torque,
    get_model,
    make_status,
    pack_register,
    torque_from_current,
    unpack_register,
)

__all__ = ["CONTROL_TABLE_SIZE_BYTES", "DynamixelEmulator", "EmulatedServo"]

CONTROL_TABLE_SIZE_BYTES = 662
"""Addresses 0–661 (the last Indirect Data is 661)."""

FIRMWARE_VERSION = 46
"""Firmware version the emulated servos report (Bus Watchdog needs ≥ 38)."""

_READ_ONLY = frozenset(
    range(ControlTable.MODEL_NUMBER, ControlTable.ID)  # model number, information, firmware
) | frozenset(
    (
        ControlTable.REGISTERED_INSTRUCTION,
        ControlTable.HARDWARE_ERROR_STATUS,
        *range(ControlTable.REALTIME_TICK, ControlTable.PRESENT_TEMPERATURE + 2),
    )
)
"""Addresses a WRITE may not touch (Access Error)."""

_EEPROM_DEFAULTS: tuple[tuple[ControlTable, int], ...] = (
    (ControlTable.FIRMWARE_VERSION, FIRMWARE_VERSION),
    (ControlTable.BAUD_RATE, 3),  # 1 Mbps
    (ControlTable.RETURN_DELAY_TIME, 250),
    (ControlTable.OPERATING_MODE, OperatingMode.POSITION),
    (ControlTable.SECONDARY_ID, 255),
    (ControlTable.PROTOCOL_TYPE, 2),
    (ControlTable.MOVING_THRESHOLD, 10),
    (ControlTable.TEMPERATURE_LIMIT, 80),
    (ControlTable.MAX_VOLTAGE_LIMIT, 160),
    (ControlTable.MIN_VOLTAGE_LIMIT, 95),
    (ControlTable.PWM_LIMIT, 885),
    (ControlTable.VELOCITY_LIMIT, 350),
    (ControlTable.MAX_POSITION_LIMIT, 4095),
    (ControlTable.SHUTDOWN, 52),
)
_RAM_DEFAULTS: tuple[tuple[ControlTable, int], ...] = (
    (ControlTable.STATUS_RETURN_LEVEL, 2),
    (ControlTable.VELOCITY_I_GAIN, 1920),
    (ControlTable.VELOCITY_P_GAIN, 100),
    (ControlTable.POSITION_P_GAIN, 800),
    (ControlTable.PRESENT_INPUT_VOLTAGE, 120),  # 12.0 V
)

_WATCHDOG_ERROR = 0xFF
"""Bus Watchdog (98) reads −1 after it fired."""


class EmulatedServo:
    """One X-series servo: its control table, model and motor.

    Attributes:
        servo_id: Its ID (also written at ID (7)).
        model: The model it emulates.
        motor: The physics it drives.
        table: Its control table at the real addresses.
        corrupt_replies: Fault injection: its status packets go out with a
            wrong CRC (a noisy line), so the host must drop them.
    """

    def __init__(self, servo_id: int, model: DynamixelModel, motor: EmulatedMotor):
        self.servo_id = servo_id
        self.model = model
        self.motor = motor
        self.table = bytearray(CONTROL_TABLE_SIZE_BYTES)
        self.corrupt_replies = False
        self._set(ControlTable.MODEL_NUMBER, model.model_number)
        self._set(ControlTable.ID, servo_id)
        self._set(ControlTable.CURRENT_LIMIT, model.current_limit_units)
        for register, value in _EEPROM_DEFAULTS:
            self._set(register, value)
        self._reset_ram()

    # ---------------------------------------------------------------- registers

    def get(self, register: ControlTable) -> int:
        """A register's value (signed where the register is)."""
        size = REGISTER_SIZE_BYTES[register]
        return unpack_register(register, self.table[register : register + size])

    def _set(self, register: ControlTable, value: int) -> None:
        data = pack_register(register, value)
        self.table[register : register + len(data)] = data

    def _reset_ram(self) -> None:
        self.table[EEPROM_END:] = bytes(CONTROL_TABLE_SIZE_BYTES - EEPROM_END)
        for register, value in _RAM_DEFAULTS:
            self._set(register, value)

    # ---------------------------------------------------------------- state

    @property
    def return_delay_s(self) -> float:
        """Return Delay Time (9) in seconds."""
        return self.table[ControlTable.RETURN_DELAY_TIME] * RETURN_DELAY_UNIT_S

    @property
    def torque_on(self) -> bool:
        """Torque Enable (64)."""
        return self.table[ControlTable.TORQUE_ENABLE] == 1

    @property
    def watchdog_fired(self) -> bool:
        """Bus Watchdog (98) reads −1."""
        return self.table[ControlTable.BUS_WATCHDOG] == _WATCHDOG_ERROR

    def error_byte(self, status: StatusError = StatusError.NONE) -> int:
        """A status packet's error byte: alert bit if Hardware Error Status is set."""
        alert = ALERT_BIT if self.table[ControlTable.HARDWARE_ERROR_STATUS] else 0
        return alert | status

    def update(self) -> None:
        """Latch injected faults and a fired watchdog into the control table."""
        motor = self.motor
        if motor.fault_code and not self.table[ControlTable.HARDWARE_ERROR_STATUS]:
            self.table[ControlTable.HARDWARE_ERROR_STATUS] = (motor.fault_code & 0xFF) or 0x01
            if self.torque_on or motor.enabled:
                self.table[ControlTable.TORQUE_ENABLE] = 0
                motor.set_enabled(False)
        watchdog = self.table[ControlTable.BUS_WATCHDOG]
        if self.torque_on and 1 <= watchdog <= 127:
            motor.watchdog_expired()
            if not motor.enabled:
                self.table[ControlTable.BUS_WATCHDOG] = _WATCHDOG_ERROR

    def refresh_present(self) -> None:
        """Present Current/Velocity/Position/Temperature from the motor, in register units."""
        motor = self.motor
        current_units = round(
            current_from_torque(self.model, motor.torque_Nm()) / self.model.current_unit_A
        )
        self._set(ControlTable.PRESENT_CURRENT, max(-32768, min(32767, current_units)))
        velocity_units = round(motor.velocity_rad_s / VELOCITY_UNIT_RAD_S)
        self._set(ControlTable.PRESENT_VELOCITY, max(-(2**31), min(2**31 - 1, velocity_units)))
        pulses = round(motor.position_rad / POSITION_UNIT_RAD)
        self._set(ControlTable.PRESENT_POSITION, max(-(2**31), min(2**31 - 1, pulses)))
        temperature = motor.temperature_C
        self.table[ControlTable.PRESENT_TEMPERATURE] = (
            max(0, min(255, round(temperature))) if math.isfinite(temperature) else 255
        )
        self.update()

    # ---------------------------------------------------------------- instructions

    def read(self, address: int, length: int) -> tuple[StatusError, bytes]:
        """READ: the bytes, or Access Error beyond the table."""
        if address + length > CONTROL_TABLE_SIZE_BYTES or length == 0:
            return StatusError.ACCESS, b""
        self.refresh_present()
        return StatusError.NONE, bytes(self.table[address : address + length])

    def write(self, address: int, data: bytes) -> StatusError:
        """WRITE: check access, store, and apply what the written registers do."""
        end = address + len(data)
        if end > CONTROL_TABLE_SIZE_BYTES or not data:
            return StatusError.ACCESS
        if any(a in _READ_ONLY for a in range(address, end)):
            return StatusError.ACCESS
        if address < EEPROM_END and self.torque_on:
            return StatusError.ACCESS  # EEPROM is locked while torque is on
        self.update()
        goal = ControlTable.GOAL_CURRENT
        writes_goal = address < goal + 2 and end > goal
        if writes_goal and self.watchdog_fired:
            return StatusError.DATA_RANGE  # goals are read-only after the watchdog fired
        old = bytes(self.table[address:end])
        self.table[address:end] = data
        if writes_goal and abs(self.get(goal)) > self.get(ControlTable.CURRENT_LIMIT):
            self.table[address:end] = old
            return StatusError.DATA_LIMIT
        self._apply(address, end, old)
        return StatusError.NONE

    def _apply(self, address: int, end: int, old: bytes) -> None:
        def written(register: ControlTable) -> bool:
            return address <= register < end

        motor = self.motor
        if written(ControlTable.BUS_WATCHDOG):
            value = self.table[ControlTable.BUS_WATCHDOG]
            was_fired = old[ControlTable.BUS_WATCHDOG - address] == _WATCHDOG_ERROR
            if value == 0:
                motor.watchdog_timeout_s = 0.0
                if was_fired and self.torque_on and not motor.fault_code:
                    motor.set_enabled(True)  # torque never went off; goals are accepted again
            elif value <= 127:
                motor.watchdog_timeout_s = value * BUS_WATCHDOG_UNIT_S
            else:
                self.table[ControlTable.BUS_WATCHDOG] = old[ControlTable.BUS_WATCHDOG - address]
        if written(ControlTable.TORQUE_ENABLE):
            was_on = old[ControlTable.TORQUE_ENABLE - address] == 1
            if self.torque_on and self.table[ControlTable.HARDWARE_ERROR_STATUS]:
                self.table[ControlTable.TORQUE_ENABLE] = 0  # only a REBOOT re-enables it
            elif self.torque_on != was_on:
                motor.set_enabled(self.torque_on)
                if self.torque_on:
                    self._apply_goal_current(initial=True)
        if address < ControlTable.GOAL_CURRENT + 2 and end > ControlTable.GOAL_CURRENT:
            self._apply_goal_current()

    def _apply_goal_current(self, *, initial: bool = False) -> None:
        if not self.torque_on or self.watchdog_fired:
            return
        if self.table[ControlTable.OPERATING_MODE] != OperatingMode.CURRENT:
            return
        units = self.get(ControlTable.GOAL_CURRENT)
        if initial and units == 0:
            return
        torque_Nm = torque_from_current(self.model, units * self.model.current_unit_A)
        self.motor.take(MotorCommand(torque_Nm=torque_Nm), "safe" if units == 0 else "command")

    def reboot(self) -> None:
        """REBOOT: clear the hardware error and the RAM area (EEPROM is kept)."""
        self.motor.fault_code = 0
        self.motor.watchdog_timeout_s = 0.0
        if self.motor.enabled:
            self.motor.set_enabled(False)
        self._reset_ram()

    def status(self, error: StatusError = StatusError.NONE, params: bytes = b"") -> bytes:
        """This servo's status packet (with a broken CRC if ``corrupt_replies``)."""
        packet = make_status(self.servo_id, self.error_byte(error), params)
        if self.corrupt_replies:
            packet = packet[:-1] + bytes([packet[-1] ^ 0xFF])
        return packet


class DynamixelEmulator:
    """X-series servos answering on a pseudo-terminal, from a thread.

    Use as a context manager: the thread starts on entry; on exit it stops
    and both ends of the pty are closed.

    Args:
        servos: Servo ID → model name (a key of ``DYNAMIXEL_MODELS``).
        motors: Servo ID → its motor (default: one per servo, torque limit at
            the model's 12 V stall torque).
        return_delay_s: Return Delay Time written to every servo (default:
            the X-series 500 µs), in 2 µs steps up to 508 µs.
    """

    def __init__(
        self,
        servos: Mapping[int, str],
        motors: Mapping[int, EmulatedMotor] | None = None,
        *,
        return_delay_s: float | None = None,
    ):
        self.servos: dict[int, EmulatedServo] = {}
        for servo_id, model_name in sorted(servos.items()):
            model = get_model(model_name)
            motor = (motors or {}).get(servo_id) or EmulatedMotor(
                torque_limit_Nm=model.stall_torque_Nm
            )
            self.servos[servo_id] = EmulatedServo(servo_id, model, motor)
        if return_delay_s is not None:
            units = max(0, min(254, round(return_delay_s / RETURN_DELAY_UNIT_S)))
            for servo in self.servos.values():
                servo.table[ControlTable.RETURN_DELAY_TIME] = units
        self._master_fd, self._slave_fd = os.openpty()
        tty.setraw(self._slave_fd)
        self.port = os.ttyname(self._slave_fd)
        """The pty's slave path: open it as the servos' serial port."""
        self._reader = PacketReader()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._serve, name="dxl-emulator", daemon=True)

    @property
    def motors(self) -> dict[int, EmulatedMotor]:
        """Servo ID → its motor."""
        return {servo_id: servo.motor for servo_id, servo in self.servos.items()}

    def __enter__(self) -> DynamixelEmulator:
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the thread and close the pty (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for fd in (self._master_fd, self._slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master_fd = self._slave_fd = -1

    # ---------------------------------------------------------------- serving

    def _serve(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master_fd], [], [], 0.005)
            with self._lock:
                for servo in self.servos.values():
                    servo.update()
            if not ready:
                continue
            try:
                data = os.read(self._master_fd, 4096)
            except OSError:
                return
            for packet in self._reader.feed(data):
                with self._lock:
                    replies = self.handle(packet)
                if replies:
                    self._send(replies)

    def _send(self, replies: list[tuple[EmulatedServo, bytes]]) -> None:
        time.sleep(replies[0][0].return_delay_s)
        try:
            os.write(self._master_fd, b"".join(reply for _, reply in replies))
        except OSError:
            pass

    def handle(self, packet: Packet | PacketError) -> list[tuple[EmulatedServo, bytes]]:
        """Execute one received packet; return the status packets to send, in order.

        Pure apart from the servos' state (no I/O): tests may call it directly.
        """
        if isinstance(packet, PacketError):
            servo = self.servos.get(packet.packet_id)
            if packet.field == "crc" and servo is not None and not servo.motor.silent:
                return [(servo, servo.status(StatusError.CRC))]
            return []
        if packet.is_status:
            return []
        if packet.instruction == Instruction.SYNC_READ:
            return self._sync_read(packet.params)
        if packet.instruction == Instruction.SYNC_WRITE:
            self._sync_write(packet.params)
            return []
        if packet.packet_id == BROADCAST_ID:
            targets = list(self.servos.values())
        elif packet.packet_id in self.servos:
            targets = [self.servos[packet.packet_id]]
        else:
            return []
        replies = []
        for servo in targets:
            if servo.motor.silent:
                continue
            reply = self._execute(servo, packet)
            if reply is not None and (
                packet.packet_id != BROADCAST_ID or packet.instruction == Instruction.PING
            ):
                replies.append((servo, reply))
        return replies

    def _execute(self, servo: EmulatedServo, packet: Packet) -> bytes | None:
        servo.update()
        params = packet.params
        instruction = packet.instruction
        if instruction == Instruction.PING:
            info = servo.table[ControlTable.MODEL_NUMBER : ControlTable.MODEL_NUMBER + 2]
            return servo.status(params=bytes(info) + bytes([FIRMWARE_VERSION]))
        if instruction == Instruction.READ:
            if len(params) != 4:
                return servo.status(StatusError.DATA_LENGTH)
            address = int.from_bytes(params[:2], "little")
            length = int.from_bytes(params[2:4], "little")
            error, data = servo.read(address, length)
            return servo.status(error, data)
        if instruction == Instruction.WRITE:
            if len(params) < 3:
                return servo.status(StatusError.DATA_LENGTH)
            error = servo.write(int.from_bytes(params[:2], "little"), params[2:])
            return servo.status(error)
        if instruction == Instruction.REBOOT:
            reply = servo.status()
            servo.reboot()
            return reply
        return servo.status(StatusError.INSTRUCTION)

    def _sync_read(self, params: bytes) -> list[tuple[EmulatedServo, bytes]]:
        if len(params) < 5:
            return []
        address = int.from_bytes(params[:2], "little")
        length = int.from_bytes(params[2:4], "little")
        replies = []
        for servo_id in params[4:]:
            servo = self.servos.get(servo_id)
            if servo is None or servo.motor.silent:
                continue
            error, data = servo.read(address, length)
            replies.append((servo, servo.status(error, data)))
        return replies

    def _sync_write(self, params: bytes) -> None:
        if len(params) < 4:
            return
        address = int.from_bytes(params[:2], "little")
        length = int.from_bytes(params[2:4], "little")
        blocks = params[4:]
        for offset in range(0, len(blocks) - length, length + 1):
            servo = self.servos.get(blocks[offset])
            if servo is not None and not servo.motor.silent:
                servo.write(address, blocks[offset + 1 : offset + 1 + length])
