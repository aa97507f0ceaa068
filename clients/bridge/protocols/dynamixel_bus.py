"""The Dynamixel bus: X-series servos on one serial port through ``dynamixel-sdk``.

The bus, :class:`DynamixelBus`, drives one serial port through the
official ``dynamixel-sdk`` (PortHandler, Protocol 2.0 PacketHandler,
GroupSyncWrite, GroupSyncRead) in current-control mode: a sync write of Goal
Current and one sync read of Present Current … Present Temperature per tick.

dynamixel-sdk 4.1.0 caveats found while testing against it: its Python
``txPacket`` discards ``addStuffing``'s result, so a packet that needs stuffing
goes out unstuffed (the bus never sends an ``FF FF FD`` run: Goal Current
sync writes put an ID ≤ 0xFC after every two data bytes); its GroupSyncRead
stops at the first missing status packet and its ``readRx`` discards other
IDs' packets while waiting, so the bus collects the sync-read replies itself.
"""

from __future__ import annotations

import select
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import dynamixel_sdk as sdk

from clients.bridge.actuator import BusError, MotorCommand, MotorFeedback
from clients.bridge.protocols.dynamixel import (
    ALERT_BIT,
    FEEDBACK_LENGTH_BYTES,
    FEEDBACK_START,
    MAX_ID,
    POSITION_UNIT_RAD,
    REGISTER_SIZE_BYTES,
    VELOCITY_UNIT_RAD_S,
    CommandError,
    ControlTable,
    DynamixelModel,
    Instruction,
    OperatingMode,
    Packet,
    PacketReader,
    StatusError,
    decode_feedback,
    describe_hardware_error,
    get_model,
    goal_current_from_torque,
    pack_register,
    torque_from_current,
    watchdog_register_from_timeout,
)

__all__ = ["DynamixelBus"]


def _port_handler(port: str, reply_timeout_s: float):
    """A dynamixel-sdk PortHandler whose status timeout is ``reply_timeout_s``.

    The SDK waits ``2 × LATENCY_TIMER + 2`` ms (34 ms) past the transfer time
    for every status packet, sized for a USB adapter's 16 ms FTDI latency
    timer; set that timer to 1 ms (``/sys/bus/usb-serial/devices/ttyUSB*/
    latency_timer``) on real hardware and give the bus a matching timeout.
    """

    class _TimedPortHandler(sdk.PortHandler):
        def setPacketTimeout(self, packet_length: int) -> None:
            self.packet_start_time = self.getCurrentTime()
            self.packet_timeout = self.tx_time_per_byte * packet_length + reply_timeout_s * 1e3

        def readPort(self, length: int) -> bytes:
            # The SDK polls a non-blocking port in a busy loop; wait in select
            # instead (until data or the packet timeout), freeing the CPU and the GIL.
            if not self.ser.in_waiting:
                remaining_ms = self.packet_timeout - self.getTimeSinceStart()
                if remaining_ms > 0.0:
                    select.select([self.ser.fileno()], [], [], remaining_ms * 1e-3)
            return self.ser.read(length)

    return _TimedPortHandler(port)


@dataclass
class _ServoState:
    model: DynamixelModel
    hardware_error: int = 0
    last_error_byte: int = 0


@dataclass
class DynamixelBus:
    """Dynamixel X servos on one serial port, in current control, as an ActuatorBus.

    Each :meth:`exchange` is one sync write of Goal Current (102) and one sync
    read of Present Current (126) … Present Temperature (146), 21 bytes per
    servo. A servo whose status packet has the alert bit gets its Hardware
    Error Status (70) read once (the error latches until a reboot) and
    reported as the feedback's fault. Replies are collected by
    :class:`PacketReader`, so one silent or corrupted servo costs only its own
    feedback (the SDK's GroupSyncRead gives up at the first missing reply).

    On hardware, set each servo's Return Delay Time (9) to 0 (the default
    250 is 500 µs per status packet) and the USB adapter's latency timer to
    1 ms; at 1 Mbit/s six servos then take about 2.5 ms per exchange on the
    wire (≈ 250 bytes).

    Args:
        port: Serial device (``/dev/ttyUSB0``, or an emulator's pty).
        servos: Servo ID → model name (a key of :data:`DYNAMIXEL_MODELS`).
        baudrate: Bits per second (the servos' Baud Rate (8) setting).
        name: The bus's name in errors.
        reply_timeout_s: How long to wait for status packets past their
            transfer time.
    """

    port: str
    servos: Mapping[int, str]
    baudrate: int = 1_000_000
    name: str = ""
    reply_timeout_s: float = 0.01
    actuator_ids: tuple[int, ...] = field(init=False)
    _state: dict[int, _ServoState] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.name = self.name or self.port
        self._state = {}
        for servo_id, model_name in self.servos.items():
            if not 0 <= servo_id <= MAX_ID:
                raise CommandError(servo_id, "id", f"{servo_id=} is not 0–252")
            try:
                self._state[servo_id] = _ServoState(get_model(model_name))
            except CommandError as error:
                raise CommandError(servo_id, "model", error.detail) from None
        self.actuator_ids = tuple(sorted(self._state))
        self._port = _port_handler(self.port, self.reply_timeout_s)
        try:
            opened = self._port.openPort() and self._port.setBaudRate(self.baudrate)
        except Exception as error:  # pyserial raises SerialException / OSError
            raise BusError(self.name, f"cannot open {self.port}: {error}") from error
        if not opened:
            raise BusError(self.name, f"cannot open {self.port} at {self.baudrate} bit/s")
        self._packets = sdk.PacketHandler(2.0)
        self._goal_current = sdk.GroupSyncWrite(
            self._port,
            self._packets,
            ControlTable.GOAL_CURRENT,
            REGISTER_SIZE_BYTES[ControlTable.GOAL_CURRENT],
        )
        self._feedback = sdk.GroupSyncRead(
            self._port, self._packets, FEEDBACK_START, FEEDBACK_LENGTH_BYTES
        )
        for servo_id in self.actuator_ids:
            self._feedback.addParam(servo_id)
        self._reader = PacketReader()
        self._closed = False

    # ----------------------------------------------------------------- ActuatorBus

    def exchange(self, commands: Mapping[int, MotorCommand]) -> dict[int, MotorFeedback | None]:
        """Sync-write each servo's Goal Current, then sync-read every servo's feedback.

        Raises:
            CommandError: ``kp`` or ``kd`` is not 0 (current control is torque
                only), a torque is not finite, or an ID is not on this bus;
                nothing is sent.
            BusError: The port failed.
        """
        goal_units: dict[int, int] = {}
        for servo_id, command in commands.items():
            state = self._state.get(servo_id)
            if state is None:
                raise CommandError(servo_id, "id", f"not on bus {self.name!r} {self.actuator_ids}")
            if command.kp_Nm_per_rad != 0.0 or command.kd_Nm_s_per_rad != 0.0:
                raise CommandError(
                    servo_id,
                    "kp_Nm_per_rad/kd_Nm_s_per_rad",
                    f"kp={command.kp_Nm_per_rad}, kd={command.kd_Nm_s_per_rad}: Dynamixel current "
                    "control takes torque only; close position/velocity loops in the bridge",
                )
            try:
                goal_units[servo_id] = goal_current_from_torque(state.model, command.torque_Nm)
            except CommandError as error:
                raise CommandError(servo_id, error.field, error.detail) from None
        if goal_units:
            self._sync_write_goal_current(goal_units)
        return self._read_feedback()

    def enable(self) -> None:
        """Torque off, Operating Mode current control, Goal Current 0, torque on."""
        for servo_id in self.actuator_ids:
            self._write(servo_id, ControlTable.TORQUE_ENABLE, 0)
            self._write(servo_id, ControlTable.OPERATING_MODE, OperatingMode.CURRENT)
            self._write(servo_id, ControlTable.GOAL_CURRENT, 0)
            self._write(servo_id, ControlTable.TORQUE_ENABLE, 1)

    def arm_watchdog(self, timeout_s: float) -> None:
        """Arm each servo's Bus Watchdog (98), in 20 ms units (1–127, rounded up).

        It monitors only while Torque Enable is 1, so call it after
        :meth:`enable`. Once it fires the servo stops, the register reads −1
        and Goal Current is refused (Data Range Error) until the register is
        written 0 (which :meth:`disable` does, and ``timeout_s=0`` here).
        """
        units = 0 if timeout_s == 0.0 else watchdog_register_from_timeout(timeout_s)
        for servo_id in self.actuator_ids:
            self._write(servo_id, ControlTable.BUS_WATCHDOG, units)

    def hold_safe(
        self, damping_Nm_s_per_rad: Mapping[int, float]
    ) -> dict[int, MotorFeedback | None]:
        """Zero Goal Current on every servo; the damping is ignored.

        Current control has no damping term in the servo, and closing one in
        the bridge from a latched-safe state would be a command, not a safe
        state; the servo's own back-EMF and gear friction damp the joint.
        """
        del damping_Nm_s_per_rad
        self._sync_write_goal_current(dict.fromkeys(self.actuator_ids, 0))
        return self._read_feedback()

    def clear_faults(self) -> None:
        """REBOOT every servo whose Hardware Error Status was non-zero.

        A reboot is the only way to clear an X-series hardware error; the
        servo comes back with Torque Enable 0, so call :meth:`enable` again.
        Servos without a known error are left alone.
        """
        for servo_id, state in self._state.items():
            if state.hardware_error or state.last_error_byte & ALERT_BIT:
                result, _ = self._packets.reboot(self._port, servo_id)
                self._check_result(result, f"REBOOT servo {servo_id}")
                state.hardware_error = 0
                state.last_error_byte = 0

    def disable(self) -> None:
        """Disarm the Bus Watchdog and turn torque off on every servo."""
        for servo_id in self.actuator_ids:
            self._write(servo_id, ControlTable.BUS_WATCHDOG, 0, missing_ok=True)
            self._write(servo_id, ControlTable.TORQUE_ENABLE, 0, missing_ok=True)

    def close(self) -> None:
        """Close the serial port (idempotent)."""
        if not self._closed:
            self._closed = True
            self._port.closePort()

    def __enter__(self) -> DynamixelBus:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ----------------------------------------------------------------- helpers

    def _check_result(self, result: int, what: str) -> None:
        if result in (sdk.COMM_PORT_BUSY, sdk.COMM_TX_FAIL, sdk.COMM_TX_ERROR):
            raise BusError(self.name, f"{what}: {self._packets.getTxRxResult(result)}")

    def _write(
        self, servo_id: int, register: ControlTable, value: int, *, missing_ok: bool = False
    ) -> None:
        data = list(pack_register(register, value))
        try:
            result, error = self._packets.writeTxRx(self._port, servo_id, register, len(data), data)
        except OSError as os_error:
            raise BusError(self.name, f"write {register.name}: {os_error}") from os_error
        self._check_result(result, f"write {register.name}={value} to servo {servo_id}")
        if missing_ok:
            return
        if result != sdk.COMM_SUCCESS:
            raise BusError(
                self.name,
                f"servo {servo_id} did not acknowledge {register.name}={value} "
                f"({self._packets.getTxRxResult(result)}); check its ID, baud rate and power",
            )
        if error & 0x7F:
            status = Packet(servo_id, Instruction.STATUS, error=error).status_error
            text = status.description if isinstance(status, StatusError) else f"error {status}"
            raise BusError(self.name, f"servo {servo_id} refused {register.name}={value}: {text}")

    def _sync_write_goal_current(self, goal_units: Mapping[int, int]) -> None:
        group = self._goal_current
        group.clearParam()
        for servo_id, units in goal_units.items():
            group.addParam(servo_id, list(pack_register(ControlTable.GOAL_CURRENT, units)))
        try:
            result = group.txPacket()
        except OSError as error:
            raise BusError(self.name, f"sync write Goal Current: {error}") from error
        if result != sdk.COMM_SUCCESS:
            raise BusError(
                self.name, f"sync write Goal Current: {self._packets.getTxRxResult(result)}"
            )

    def _read_feedback(self) -> dict[int, MotorFeedback | None]:
        """One sync read; collect status packets until all answered or the timeout."""
        try:
            result = self._feedback.txPacket()
        except OSError as error:
            raise BusError(self.name, f"sync read: {error}") from error
        if result != sdk.COMM_SUCCESS:
            self._port.is_using = False
            raise BusError(self.name, f"sync read: {self._packets.getTxRxResult(result)}")
        replies = self._collect(set(self.actuator_ids))
        self._port.is_using = False  # we read the replies ourselves, not through the SDK
        out: dict[int, MotorFeedback | None] = {}
        for servo_id in self.actuator_ids:
            packet = replies.get(servo_id)
            out[servo_id] = None if packet is None else self._feedback_of(servo_id, packet)
        return out

    def _collect(self, expected: set[int]) -> dict[int, Packet]:
        """Status packets from ``expected`` IDs until all came or the reply timeout passed."""
        serial_port = self._port.ser
        reply_bytes = (11 + FEEDBACK_LENGTH_BYTES) * len(expected)
        deadline = time.monotonic() + reply_bytes * 10.0 / self.baudrate + self.reply_timeout_s
        self._reader.clear()
        replies: dict[int, Packet] = {}
        while len(replies) < len(expected):
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                break
            try:
                ready, _, _ = select.select([serial_port.fileno()], [], [], remaining)
                if not ready:
                    break
                data = serial_port.read(serial_port.in_waiting or 1)
            except (OSError, ValueError) as error:
                raise BusError(self.name, f"reading {self.port}: {error}") from error
            for packet in self._reader.feed(data):
                if (
                    isinstance(packet, Packet)
                    and packet.is_status
                    and packet.packet_id in expected
                    and len(packet.params) == FEEDBACK_LENGTH_BYTES
                ):
                    replies[packet.packet_id] = packet
                # A PacketError (bad CRC, …) is a missed reply: its servo stays None.
        return replies

    def _feedback_of(self, servo_id: int, packet: Packet) -> MotorFeedback:
        state = self._state[servo_id]
        state.last_error_byte = packet.error
        if packet.alert and not state.hardware_error:
            state.hardware_error = self._read_hardware_error(servo_id)
        elif not packet.alert:
            state.hardware_error = 0
        raw = decode_feedback(packet.params)
        model = state.model
        return MotorFeedback(
            position_rad=raw.position_pulses * POSITION_UNIT_RAD,
            velocity_rad_s=raw.velocity_units * VELOCITY_UNIT_RAD_S,
            torque_Nm=torque_from_current(model, raw.current_units * model.current_unit_A),
            temperature_C=float(raw.temperature_C),
            fault=describe_hardware_error(state.hardware_error)
            or ("hardware error (alert bit)" if packet.alert else ""),
            fault_code=state.hardware_error or (ALERT_BIT if packet.alert else 0),
        )

    def _read_hardware_error(self, servo_id: int) -> int:
        self._port.is_using = False
        value, result, _ = self._packets.read1ByteTxRx(
            self._port, servo_id, ControlTable.HARDWARE_ERROR_STATUS
        )
        self._check_result(result, f"read Hardware Error Status of servo {servo_id}")
        return value if result == sdk.COMM_SUCCESS else 0
