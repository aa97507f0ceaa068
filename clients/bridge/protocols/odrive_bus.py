"""The ODrive bus: CANSimple axes on one CAN channel, in torque control (:class:`ODriveBus`).

Frames are built and parsed by the pure functions of :mod:`clients.bridge.protocols.odrive`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Mapping

import can

from clients.bridge.actuator import MotorCommand, MotorFeedback
from clients.bridge.protocols.can_io import CanChannel
from clients.bridge.protocols.odrive import (
    DEFAULT_WATCHDOG_ENDPOINTS,
    TURN_RAD,
    AxisState,
    Command,
    ControlMode,
    EncoderEstimates,
    Firmware,
    Heartbeat,
    InputMode,
    InvalidCommand,
    MalformedFrame,
    Temperature,
    Torques,
    WatchdogEndpoints,
    arbitration_id,
    axis_state_name,
    describe_axis_error,
    make_clear_errors,
    make_estop,
    make_request,
    make_rx_sdo_write,
    make_set_axis_state,
    make_set_controller_mode,
    make_set_input_torque,
    parse_encoder_estimates,
    parse_heartbeat,
    parse_set_input_torque,
    parse_temperature,
    parse_torques,
    split_arbitration_id,
)

__all__ = ["ODriveBus"]


class ODriveBus(CanChannel):
    """ODrives on one CAN channel, each axis a CANSimple node, in torque control.

    Implements :class:`clients.bridge.actuator.ActuatorBus`. Each
    :meth:`exchange` sends every commanded node a Set_Input_Torque, then RTR
    requests for Get_Encoder_Estimates and (firmware 0.6) Get_Torques, and
    every ``temperature_period`` exchanges Get_Temperature; it then reads
    until every node answered or ``reply_timeout_s`` passed. Heartbeats (sent
    cyclically by the ODrive, ``heartbeat_msg_rate_ms``, 100 ms by default)
    are read whenever they arrive; the newest gives each node's axis error and
    state.

    A node reports a fault (:attr:`MotorFeedback.fault`) when its heartbeat
    carries axis errors, or when it left CLOSED_LOOP_CONTROL while the bus
    expects it there (after :meth:`enable`), e.g. ``"axis IDLE, error
    WATCHDOG_TIMER_EXPIRED"``; ``fault_code`` is the raw axis error (0 when
    the axis only left closed loop).

    Args:
        bus: An open python-can bus; :meth:`close` shuts it down.
        node_ids: The axes' CAN node ids (0…63).
        name: The bus's name in errors (the actuator map's).
        reply_timeout_s: How long to wait for replies after the last request.
        torque_limit_Nm: Clamp for commanded torques: one for all nodes, or
            per node (nodes not in the mapping are not clamped), or ``None``.
        firmware: CANSimple generation. With ``Firmware.V0_5`` (ODrive v3.6)
            there is no Get_Torques, Get_Temperature or SDO: torque feedback is
            the command, no temperature, and :meth:`arm_watchdog` raises (set
            ``axis.config.watchdog_timeout`` over USB; 0.5 feeds it on every
            CAN frame to the axis).
        watchdog_endpoints: ``flat_endpoints.json`` ids for :meth:`arm_watchdog`.
        request_torques: Ask Get_Torques each exchange (0.6) for the torque
            estimate; otherwise the feedback torque is the command.
        temperature_period: Ask Get_Temperature every this many exchanges
            (0: never); the newest answer is reported in between.
        arm_timeout_s: After :meth:`enable`, how long an axis may report a
            state other than CLOSED_LOOP_CONTROL without an error (still
            arming, or a heartbeat sent before the request) before that is a
            fault; once seen in closed loop, leaving it is a fault at once.

    Raises:
        InvalidCommand: Bad node ids, timeout or torque limits.
    """

    def __init__(
        self,
        bus: can.BusABC,
        node_ids: Iterable[int],
        *,
        name: str = "",
        reply_timeout_s: float = 0.002,
        torque_limit_Nm: Mapping[int, float] | float | None = None,
        firmware: Firmware = Firmware.V0_6,
        watchdog_endpoints: WatchdogEndpoints = DEFAULT_WATCHDOG_ENDPOINTS,
        request_torques: bool = True,
        temperature_period: int = 10,
        arm_timeout_s: float = 0.5,
    ):
        ids = tuple(node_ids)
        for node_id in ids:
            arbitration_id(node_id, 0)  # validates the range
        if len(set(ids)) != len(ids) or not ids:
            raise InvalidCommand(-1, "node_ids", f"{ids=} must be distinct and not empty")
        if not (math.isfinite(reply_timeout_s) and reply_timeout_s > 0.0):
            raise InvalidCommand(-1, "reply_timeout_s", f"{reply_timeout_s=} must be > 0")
        if temperature_period < 0:
            raise InvalidCommand(-1, "temperature_period", f"{temperature_period=} must be ≥ 0")
        super().__init__(bus, name, reply_timeout_s)
        self.actuator_ids: tuple[int, ...] = ids
        self.firmware = firmware
        self.watchdog_endpoints = watchdog_endpoints
        self.request_torques = request_torques and firmware is Firmware.V0_6
        self.temperature_period = temperature_period if firmware is Firmware.V0_6 else 0
        self.arm_timeout_s = arm_timeout_s
        self.torque_limit_Nm = self._limits(torque_limit_Nm)
        self.malformed_frames = 0
        """Frames from our nodes that did not decode (counted, never raised)."""
        self._exchanges = 0
        self._heartbeat: dict[int, Heartbeat] = {}
        self._heartbeat_s: dict[int, float] = {}
        self._temperature: dict[int, Temperature] = {}
        self._closed_loop_expected: dict[int, bool] = dict.fromkeys(ids, False)
        self._enabled_s: dict[int, float] = dict.fromkeys(ids, 0.0)
        self._armed_seen: dict[int, bool] = dict.fromkeys(ids, False)
        self._commanded_Nm: dict[int, float] = dict.fromkeys(ids, 0.0)

    def _limits(self, limit: Mapping[int, float] | float | None) -> dict[int, float | None]:
        if limit is None or isinstance(limit, int | float):
            limits: dict[int, float | None] = dict.fromkeys(self.actuator_ids, limit)
        else:
            unknown = set(limit) - set(self.actuator_ids)
            if unknown:
                raise InvalidCommand(
                    -1, "torque_limit_Nm", f"nodes {sorted(unknown)} are not on this bus"
                )
            limits = {node: limit.get(node) for node in self.actuator_ids}
        for node, value in limits.items():
            if value is not None and not (value > 0.0 and not math.isnan(value)):
                raise InvalidCommand(node, "torque_limit_Nm", f"{value=} must be > 0")
        return limits

    # ------------------------------------------------------------ the verbs

    def exchange(self, commands: Mapping[int, MotorCommand]) -> dict[int, MotorFeedback | None]:
        """Send each node its torque and return what each reported (see the class).

        All commands are checked before anything is sent.

        Raises:
            InvalidCommand: A node not on this bus, ``kp``/``kd`` ≠ 0 (ODrive
                torque control has no PD law here: compute the torque), or a
                NaN torque.
            BusError: The CAN interface failed.
        """
        frames = []
        for node_id, command in commands.items():
            if node_id not in self._closed_loop_expected:
                raise InvalidCommand(node_id, "node_id", f"not on bus {self.name!r}")
            if command.kp_Nm_per_rad != 0.0 or command.kd_Nm_s_per_rad != 0.0:
                raise InvalidCommand(
                    node_id,
                    "kp/kd",
                    f"kp={command.kp_Nm_per_rad}, kd={command.kd_Nm_s_per_rad}: ODrive torque "
                    "control takes torque only; fold the PD law into torque_Nm",
                )
            frames.append(
                make_set_input_torque(
                    node_id, command.torque_Nm, torque_limit_Nm=self.torque_limit_Nm[node_id]
                )
            )
        for frame in frames:
            node_id, _ = split_arbitration_id(frame.arbitration_id)
            self._commanded_Nm[node_id] = parse_set_input_torque(bytes(frame.data))
        return self._poll(list(commands), frames)

    def hold_safe(
        self, damping_Nm_s_per_rad: Mapping[int, float]
    ) -> dict[int, MotorFeedback | None]:
        """Idle every axis (the ODrive has no damping mode here) and read them all.

        The damping is ignored: an idle ODrive leaves the motor free. Sent
        every tick, so an axis that re-armed is idled again.
        """
        del damping_Nm_s_per_rad
        frames = [make_set_axis_state(node, AxisState.IDLE) for node in self.actuator_ids]
        for node in self.actuator_ids:
            self._closed_loop_expected[node] = False
            self._commanded_Nm[node] = 0.0
        return self._poll(list(self.actuator_ids), frames)

    def enable(self) -> None:
        """Torque control with passthrough input, then CLOSED_LOOP_CONTROL, on every axis."""
        self._drain()
        frames = []
        for node in self.actuator_ids:
            frames.append(
                make_set_controller_mode(node, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH)
            )
            frames.append(make_set_axis_state(node, AxisState.CLOSED_LOOP_CONTROL))
        self._send(frames)
        now = time.monotonic()
        for node in self.actuator_ids:
            self._closed_loop_expected[node] = True
            self._enabled_s[node] = now
            self._armed_seen[node] = False

    def disable(self) -> None:
        """Set every axis IDLE (motor free)."""
        self._idle([make_set_axis_state(node, AxisState.IDLE) for node in self.actuator_ids])

    def clear_faults(self) -> None:
        """Clear_Errors on every axis; they stay idle until :meth:`enable`."""
        self._idle([make_clear_errors(node) for node in self.actuator_ids])

    def estop(self) -> None:
        """Estop every axis: each latches ESTOP_REQUESTED and disarms (clear, then enable)."""
        self._idle([make_estop(node) for node in self.actuator_ids])

    def arm_watchdog(self, timeout_s: float) -> None:
        """Write ``axis0.config.watchdog_timeout`` then ``enable_watchdog`` over RxSdo.

        ``timeout_s = 0`` disables the watchdog. An armed axis that hears no
        frame for ``timeout_s`` goes IDLE with WATCHDOG_TIMER_EXPIRED (0.5.x
        feeds it on every frame addressed to the axis; which frames feed it
        in 0.6 is not stated in the sources checked — the emulator feeds it
        on Set_Input_Torque only, the strictest reading).

        Raises:
            InvalidCommand: ``timeout_s`` negative or not finite, or firmware
                0.5 (no SDO over CAN: configure the watchdog over USB).
        """
        if self.firmware is Firmware.V0_5:
            raise InvalidCommand(
                -1, "firmware", "0.5.x has no RxSdo: set axis.config.watchdog_timeout over USB"
            )
        if not (math.isfinite(timeout_s) and timeout_s >= 0.0):
            raise InvalidCommand(-1, "timeout_s", f"{timeout_s=} must be finite and ≥ 0")
        ids = self.watchdog_endpoints
        frames = []
        for node in self.actuator_ids:
            if timeout_s > 0.0:
                frames.append(make_rx_sdo_write(node, ids.watchdog_timeout, timeout_s, "float"))
            frames.append(make_rx_sdo_write(node, ids.enable_watchdog, timeout_s > 0.0, "bool"))
        self._send(frames)

    # ------------------------------------------------------------ internals

    def _idle(self, frames: list[can.Message]) -> None:
        self._send(frames)
        for node in self.actuator_ids:
            self._closed_loop_expected[node] = False
            self._commanded_Nm[node] = 0.0

    def _drain(self) -> None:
        """Take in what arrived since the last call (cyclic heartbeats), without waiting."""
        while (message := self._recv(0.0)) is not None:
            self._take(message, None)

    def _poll(
        self, node_ids: list[int], commands: list[can.Message]
    ) -> dict[int, MotorFeedback | None]:
        self._drain()
        self._exchanges += 1
        ask_temperature = (
            self.temperature_period > 0 and (self._exchanges - 1) % self.temperature_period == 0
        )
        wanted = [Command.GET_ENCODER_ESTIMATES]
        if self.request_torques:
            wanted.append(Command.GET_TORQUES)
        frames = list(commands)
        for node in node_ids:
            frames.extend(make_request(node, command) for command in wanted)
            if ask_temperature:
                frames.append(make_request(node, Command.GET_TEMPERATURE))
        self._send(frames)
        replies: dict[int, dict[int, object]] = {node: {} for node in node_ids}
        pending = set(node_ids)

        def take(message: can.Message) -> bool:
            node = self._take(message, replies)
            if node in pending and all(command in replies[node] for command in wanted):
                pending.discard(node)
            return not pending

        if pending:
            self._read_until(take)
        return {node: self._feedback(node, replies[node]) for node in node_ids}

    def _take(self, message: can.Message, replies: dict[int, dict[int, object]] | None) -> int:
        """Decode one frame into the caches; returns its node (-1: not ours or bad)."""
        if message.is_extended_id or message.is_remote_frame or message.is_error_frame:
            return -1
        node, command = split_arbitration_id(message.arbitration_id)
        if node not in self._closed_loop_expected:
            return -1
        data = bytes(message.data)
        try:
            if command == Command.HEARTBEAT:
                heartbeat = parse_heartbeat(data, firmware=self.firmware)
                self._heartbeat[node] = heartbeat
                self._heartbeat_s[node] = time.monotonic()
                if heartbeat.axis_state == AxisState.CLOSED_LOOP_CONTROL:
                    self._armed_seen[node] = True
                return node
            if command == Command.GET_TEMPERATURE and self.firmware is Firmware.V0_6:
                self._temperature[node] = parse_temperature(data)
                return node
            if replies is None or node not in replies:
                return -1
            if command == Command.GET_ENCODER_ESTIMATES:
                replies[node][command] = parse_encoder_estimates(data)
            elif command == Command.GET_TORQUES and self.request_torques:
                replies[node][command] = parse_torques(data)
            else:
                return -1
        except MalformedFrame:
            self.malformed_frames += 1
            return -1
        return node

    def _feedback(self, node: int, replies: dict[int, object]) -> MotorFeedback | None:
        estimates = replies.get(Command.GET_ENCODER_ESTIMATES)
        if not isinstance(estimates, EncoderEstimates):
            return None
        heartbeat = self._heartbeat.get(node)
        fault_code = 0
        parts = []
        if heartbeat is not None:
            fault_code = heartbeat.axis_error
            if (
                self._closed_loop_expected[node]
                and self._heartbeat_s[node] > self._enabled_s[node]
                and heartbeat.axis_state != AxisState.CLOSED_LOOP_CONTROL
                and (
                    heartbeat.axis_error
                    or self._armed_seen[node]
                    or time.monotonic() - self._enabled_s[node] > self.arm_timeout_s
                )
            ):
                parts.append(f"axis {axis_state_name(heartbeat.axis_state)}")
        if fault_code:
            parts.append(f"error {describe_axis_error(fault_code, self.firmware)}")
        torques = replies.get(Command.GET_TORQUES)
        if isinstance(torques, Torques):
            torque_Nm = torques.estimate_Nm
        elif self._closed_loop_expected[node] and not parts:
            torque_Nm = self._commanded_Nm[node]
        else:
            torque_Nm = 0.0
        temperature = self._temperature.get(node)
        readings = (
            [t for t in (temperature.fet_C, temperature.motor_C) if math.isfinite(t)]
            if temperature
            else []
        )
        return MotorFeedback(
            position_rad=estimates.position_turns * TURN_RAD,
            velocity_rad_s=estimates.velocity_turns_s * TURN_RAD,
            torque_Nm=torque_Nm,
            temperature_C=max(readings) if readings else None,
            fault=", ".join(parts),
            fault_code=fault_code,
        )
