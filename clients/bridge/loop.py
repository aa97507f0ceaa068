"""The bridge loop: read the actuators, step the server, command the actuators, safely.

One tick (``rate_hz``, 200 Hz–1 kHz):

1. every bus sends the commands decided last tick
   (:meth:`~clients.bridge.actuator.ActuatorBus.exchange`) and returns each actuator's feedback (one
   frame each way per actuator: the MIT-mode pattern);
2. the feedback is checked (faults, silence, limits, temperature) and
   turned into joint positions and velocities; the base state comes from a
   :class:`~clients.bridge.base_state.BaseStateSource`;
3. the state goes to the server. The torques it returns act from the next
   tick's exchange on, so the state sent is the one predicted one period
   ahead (as ``poise sim`` does with ``command_delay_ticks = 1``). With an
   IMU instead of the base pose (``base_state = "imu"``) the prediction
   would need the pose the server estimates: the measured state goes, with
   the IMU's newest sample;
4. the torques are checked (finite, one per joint), clamped to the derated
   limits, and converted to motor commands for step 1 of the next tick;
5. the pacer waits for the next tick (the wall clock, or a simulated plant).

Start-up reads every actuator with a zero command before enabling any, so
enabling cannot kick. Any reason of :mod:`clients.bridge.safety` latches
the safe state, which holds until the operator re-arms (``rearm``); the
bridge logs one line saying why. An e-stop (``estop``, SIGINT, SIGTERM)
latches it and ends the run; every actuator is disabled on the way out.
"""

from __future__ import annotations

import gc
import logging
import math
import queue
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Protocol, TypeVar

import numpy as np
import pinocchio as pin

from clients.bridge.actuator import ZERO_COMMAND, ActuatorBus, BusError, MotorCommand, MotorFeedback
from clients.bridge.base_state import BaseStateSource, ImuBaseReading
from clients.bridge.config import BridgeSettings
from clients.bridge.joint_map import JointMap
from clients.bridge.report import BridgeReport, JointLink
from clients.bridge.safety import (
    InvalidCommand,
    SafetyLatch,
    Watchdog,
    check_feedback,
    check_joints,
    clamp_torque,
)
from clients.client import ControllerClient, ServerError, ServerTimeout
from clients.state import RobotState
from clients.track import RunObserver, Track
from protocol.errors import PoiseError
from protocol.messages import Command

__all__ = ["Bridge", "BridgeStartError", "Pacer"]

log = logging.getLogger("poise.bridge")

_T = TypeVar("_T")

_NO_BASE = (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), np.zeros(3))
"""The base fields of a measured state whose base goes as an IMU sample (never sent)."""

STATUS_PERIOD_S = 5.0
"""A status line (timing, link quality) is logged this often, at level INFO."""

START_READ_ATTEMPTS = 3
"""Zero-command reads at start-up before a silent actuator refuses the start."""


class BridgeStartError(PoiseError, RuntimeError):
    """The bridge cannot start: an actuator is silent, faulted or out of its limits."""


class Pacer(Protocol):
    """What the loop waits on between ticks (wall clock or simulated plant)."""

    period_s: float

    def now_s(self) -> float:
        """Time (s) of the loop's clock."""
        ...

    def wait(self) -> bool:
        """Wait for the next tick; True if it was already late (an overrun)."""
        ...


class Bridge:
    """Drives one robot's actuators from one server session.

    Args:
        settings: The ``[bridge]`` table.
        joint_map: Joints in wire order and their actuators.
        buses: Every bus by name, open.
        client: Connected client (``connect`` done, welcome checked).
        base: Where the base state (or the IMU sample the server estimates it
            from) comes from.
        pacer: What the loop waits on between ticks.
        model: Pinocchio model of the robot (free-flyer root, wire order) for
            the one-period prediction of the state sent (not used with an IMU).
        operator: Operator commands (``"estop"``, ``"rearm"``, ``"quit"``),
            read once per tick.
        connect_timeout_s: How long a re-arm waits for the server's handshake.
        safe_margin_s: How long before the watchdog expires the wait for the
            server ends, so that the safe state reaches the actuators within
            ``watchdog_s`` of the last valid command (an exchange's worth).
        imu_max_sample_age_s: With an IMU, the same sample for longer than this (s)
            latches the safe state (``[imu] max_sample_age_s``).
        observer: Called with ``track`` after every tick the server answered:
            it must return at once (the live view: a
            :class:`~clients.visual.live_process.LiveViewProcess`).
        track: Where those ticks go: the measured state (with an IMU, the
            joints and the base the server estimates) and the server's command.
    """

    def __init__(
        self,
        settings: BridgeSettings,
        joint_map: JointMap,
        buses: Mapping[str, ActuatorBus],
        client: ControllerClient,
        base: BaseStateSource,
        pacer: Pacer,
        model: pin.Model,
        operator: queue.Queue[str] | None = None,
        connect_timeout_s: float = 10.0,
        safe_margin_s: float = 0.003,
        imu_max_sample_age_s: float = 0.02,
        observer: RunObserver | None = None,
        track: Track | None = None,
    ):
        self.connect_timeout_s = connect_timeout_s
        self.observer = observer
        self.track = track
        self.settings = settings
        self.joint_map = joint_map
        self.buses = dict(buses)
        self.client = client
        self.base = base
        self.pacer = pacer
        self.model = model
        self.operator: queue.Queue[str] = operator if operator is not None else queue.Queue()
        self.latch = SafetyLatch()
        # One clock for the watchdog and the state's time: the pacer's (the wall clock
        # on hardware; with emulation, the simulated robot's, whose time a stall of
        # this process does not advance).
        self.watchdog = Watchdog(settings.watchdog_s, clock=pacer.now_s)
        self._origin_s = pacer.now_s()
        self.safe_margin_s = safe_margin_s
        self.report = BridgeReport(
            links=[JointLink(ref.joint, ref.bus, ref.id) for ref in joint_map.actuators]
        )
        n = len(joint_map)
        self.joint_position_rad = np.zeros(n)
        self.joint_velocity_rad_s = np.zeros(n)
        self.temperature_C = np.full(n, np.nan)
        self._missed_in_a_row = np.zeros(n, dtype=int)
        self._damping = joint_map.motor_damping(settings.safe_damping_Nm_s_per_rad)
        self._commands = self._zero_commands()
        self._held: Command | None = None
        self._failed_buses: set[str] = set()
        self._pool: ThreadPoolExecutor | None = None
        self._last_time_s = -math.inf
        self.imu_max_sample_age_s = imu_max_sample_age_s
        self._imu_sample: np.ndarray | None = None
        self._imu_sample_since_s = 0.0

    def _zero_commands(self) -> dict[str, dict[int, MotorCommand]]:
        return {
            bus: {ref.id: ZERO_COMMAND for ref in self.joint_map.actuators if ref.bus == bus}
            for bus in self.buses
        }

    # --- start-up and shutdown -------------------------------------------------

    def start(self) -> None:
        """Read every actuator with a zero command, check, arm watchdogs, enable.

        Raises:
            BridgeStartError: An actuator stays silent, reports a fault after
                one clear, or its joint is outside its limits.
            BusError: A bus failed.
        """
        self._commands = self._zero_commands()
        feedback = self._read_all_with_zero()
        faulted = [i for i, reply in enumerate(feedback) if reply is not None and reply.fault]
        if faulted:
            for bus in self.buses.values():
                bus.clear_faults()
            feedback = self._read_all_with_zero()
        self._absorb(feedback)
        reason = (
            check_feedback(self.joint_map, feedback, np.zeros(len(self.joint_map), dtype=int), 1)
            or self._check_joints()
        )
        if reason:
            raise BridgeStartError(f"not starting: {reason}")
        if self.settings.actuator_watchdog_s > 0.0:
            for bus in self.buses.values():
                bus.arm_watchdog(self.settings.actuator_watchdog_s)
        for bus in self.buses.values():
            bus.enable()
        self._absorb(self._exchange(self._commands))
        self._held = None
        self.watchdog.feed()
        log.info("enabled %d actuators on %d buses", len(self.joint_map), len(self.buses))

    def _read_all_with_zero(self) -> list[MotorFeedback | None]:
        feedback: list[MotorFeedback | None] = []
        for _ in range(START_READ_ATTEMPTS):
            feedback = self._exchange(self._commands)
            if all(reply is not None for reply in feedback):
                return feedback
        silent = [
            f"{ref.joint} (bus {ref.bus!r}, id {ref.id})"
            for ref, reply in zip(self.joint_map.actuators, feedback, strict=True)
            if reply is None
        ]
        raise BridgeStartError(
            f"not starting: no reply from {', '.join(silent)} to {START_READ_ATTEMPTS} zero "
            "commands; check power, wiring, ids and the bus's bit rate"
        )

    def shutdown(self) -> None:
        """Disable every actuator (best effort on each bus, one line per failure)."""
        results = self._on_every_bus(lambda name, bus: bus.disable())
        for name, result in results.items():
            if isinstance(result, BusError):
                log.error("could not disable the actuators of bus %r: %s", name, result.detail)
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    # --- the loop ----------------------------------------------------------------

    def run(self, duration_s: float = 0.0) -> BridgeReport:
        """Start, loop until the duration, ``quit`` or an e-stop, and disable.

        ``duration_s`` = 0 runs until stopped. Ctrl-C or SIGTERM (as
        ``KeyboardInterrupt``) is an e-stop.
        """
        try:
            self.start()
            # Everything loaded so far lives for the whole run: out of the collector's
            # sight, a full collection takes ~1 ms instead of ~80 ms (a missed tick).
            gc.collect()
            gc.freeze()
            end_s = self.pacer.now_s() + duration_s if duration_s > 0 else math.inf
            status_ticks = max(1, round(STATUS_PERIOD_S / self.pacer.period_s))
            previous_s = time.perf_counter()
            while not self.report.stopped:
                tick_s = time.perf_counter()
                self._operator_commands()
                if self.report.stopped:
                    break
                self.tick()
                work_s = time.perf_counter() - tick_s
                if self.pacer.now_s() >= end_s - 1e-9:
                    self.report.stopped = "duration"
                    break
                self.report.timing.overruns += self.pacer.wait()
                now = time.perf_counter()
                self.report.timing.add(now - previous_s, work_s)
                previous_s = now
                if self.report.timing.ticks % status_ticks == 0:
                    log.info("%s", self.status())
        except KeyboardInterrupt:
            self.estop("interrupted (SIGINT/SIGTERM)")
            self.report.stopped = "interrupted"
        finally:
            self.shutdown()
        return self.report

    def status(self) -> str:
        """One line: loop timing and link quality so far (logged every few seconds)."""
        timing, links = self.report.timing, self.report.links
        hottest = max(links, key=lambda link: np.nan_to_num(link.temperature_C, nan=-np.inf))
        return (
            f"{timing.ticks} ticks, period {1e3 * timing.period_mean_s:.2f} ms "
            f"± {1e3 * timing.jitter_s:.2f}, {timing.overruns} overruns, "
            f"{sum(link.missed for link in links)} missed replies, "
            f"{sum(link.faults for link in links)} faults, hottest {hottest.joint} "
            f"{hottest.temperature_C:.0f} °C, "
            f"{'SAFE: ' + self.latch.reason if self.latch.latched else 'running'}"
        )

    def estop(self, why: str) -> None:
        """Latch the safe state now and command it once (the run then ends)."""
        self._trip(f"e-stop: {why}")
        try:
            self._hold_safe()
        except BusError as exc:
            log.error("e-stop: %s", exc)

    def _operator_commands(self) -> None:
        while True:
            try:
                command = self.operator.get_nowait().strip().lower()
            except queue.Empty:
                return
            if command == "estop":
                self.estop("operator")
                self.report.stopped = "estop"
            elif command == "quit":
                self.report.stopped = "quit"
            elif command == "rearm":
                self.rearm()
            elif command:
                log.warning("unknown operator command %r (estop, rearm, quit)", command)

    def rearm(self) -> None:
        """Leave the safe state: the operator's decision, never the bridge's.

        The start-up sequence runs again (zero command, checks, enable); if
        it fails the safe state stays latched with the new reason.
        """
        if not self.latch.latched:
            return
        reason = self.latch.rearm()
        log.warning("re-armed by the operator (was: %s)", reason)
        try:
            self.client.timeout_s = self.connect_timeout_s
            self.client.reconnect()  # a fresh session: the server may have restarted
            self.start()
        except (BridgeStartError, BusError, ServerTimeout, ServerError) as exc:
            self._trip(f"re-arm failed: {exc}")

    def tick(self) -> None:
        """One tick: exchange, check, step the server, decide the next commands."""
        if self.latch.latched:
            self._hold_safe()
            return
        try:
            feedback = self._exchange(self._commands)
        except BusError as exc:
            self._trip(str(exc))
            self._hold_safe()  # on the buses that still work
            return
        self._absorb(feedback)
        reason = (
            check_feedback(
                self.joint_map, feedback, self._missed_in_a_row, self.settings.max_missed_replies
            )
            or self._check_joints()
        )
        if reason:
            self._trip(reason)
            self._hold_safe()
            return
        command = self._step_server()
        if self.latch.latched:  # the server step found a reason (a stale IMU)
            self._hold_safe()
            return
        if command is None:
            self._without_command()
            return
        limit = self.joint_map.derated_torque_limit_Nm(self.temperature_C)
        try:
            torque, clamped = clamp_torque(
                self.settings.torque_scale * np.asarray(command.joint_torque),
                limit,
                self.joint_map.names,
            )
        except InvalidCommand as exc:
            self.report.invalid_commands += 1
            log.warning("refused the server's command for seq %d: %s", command.seq, exc)
            self._without_command()
            return
        self.report.clamped_torques += len(clamped)
        self._commands = self.joint_map.torque_commands(torque)
        self._held = command
        self.report.commands += 1
        self.watchdog.feed()

    def _without_command(self) -> None:
        """A tick without a valid command: the previous one holds, unless the watchdog ends.

        The next chance of a valid command is a period away: if the watchdog
        expires before it (less the time the safe state takes to go out), the
        safe state latches now, so it reaches the actuators within ``watchdog_s``
        of the last valid command.
        """
        if self.watchdog.remaining_s() <= self.safe_margin_s + self.pacer.period_s:
            self._trip(
                f"no valid command from the server for {self.settings.watchdog_s:g} s "
                "(the watchdog)"
            )
            self._hold_safe()

    def _stale_imu(self, reading: ImuBaseReading, time_s: float) -> str:
        """Why the IMU's sample is too old to send (unchanged too long), or ``""``."""
        sample = np.concatenate(
            [reading.imu.angular_velocity_imu_in_imu, reading.imu.linear_acceleration_imu_in_imu]
        )
        if self._imu_sample is None or not np.array_equal(sample, self._imu_sample):
            self._imu_sample, self._imu_sample_since_s = sample, time_s
            return ""
        age_s = time_s - self._imu_sample_since_s
        limit_s = self.imu_max_sample_age_s
        if age_s <= limit_s:
            return ""
        return (
            f"the IMU sent the same sample for {age_s * 1e3:.0f} ms (limit "
            f"[imu] max_sample_age_s = {limit_s:g} s): its driver stalled?"
        )

    def _step_server(self) -> Command | None:
        """Send this tick's state; the server's command, or None (counted, logged)."""
        reading = self.base.read()
        time_s = self.pacer.now_s() - self._origin_s
        if isinstance(reading, ImuBaseReading):
            stale = self._stale_imu(reading, time_s)
            if stale:
                self._trip(stale)
                return None
            # The server estimates the base from the IMU, integrated over the time between
            # states: the measured joints go with the newest sample, at a time that advances.
            if time_s <= self._last_time_s:
                time_s = math.nextafter(self._last_time_s, math.inf)
            joints = RobotState(
                self.joint_position_rad.copy(), self.joint_velocity_rad_s.copy(), *_NO_BASE
            )
            state = joints.to_imu_message(time_s, reading.contact_flags, reading.imu)
            seen, seen_time_s = joints, time_s
        else:
            measured = RobotState(
                self.joint_position_rad.copy(),
                self.joint_velocity_rad_s.copy(),
                reading.position_base_in_world,
                reading.orientation_base_in_world_xyzw,
                reading.linear_velocity_base_in_world,
                reading.angular_velocity_base_in_base,
            )
            sent, seen, seen_time_s = measured, measured, time_s
            if self._held is not None:  # the command decided now acts from the next tick
                sent = measured.predicted(self.pacer.period_s, self.model, self._held)
                time_s += self.pacer.period_s
            state = sent.to_message(time_s, reading.contact_flags)
        remaining_s = self.watchdog.remaining_s() - self.safe_margin_s
        if remaining_s <= 0.0:
            return None
        self.client.timeout_s = remaining_s
        self._last_time_s = time_s
        try:
            self.client.send_state(state)
            command = self.client.receive_command()
        except ServerTimeout:
            self.report.server_timeouts += 1
            return None
        except ServerError as exc:
            self.report.invalid_commands += 1
            log.warning("the server refused the state: %s %s", exc.code.name, exc.detail)
            return None
        if self.observer is not None and self.track is not None:
            imu = isinstance(reading, ImuBaseReading)
            if self.track.add(seen_time_s, seen, command, base_estimated=imu):
                self.observer(self.track)
        return command

    def _on_every_bus(self, call: Callable[[str, ActuatorBus], _T]) -> dict[str, _T | BusError]:
        """``call`` on every bus at once, one thread each: their waits for replies overlap.

        Buses are separate wires: one after another, a tick would take the sum
        of their exchanges (4 buses of 6 MIT actuators at 1 Mbit/s: 6.2 ms of
        frames, against a 2 ms period at 500 Hz); together it takes the longest.
        A bus that fails gives its :class:`BusError` instead of a result.
        """
        if len(self.buses) == 1:
            name, bus = next(iter(self.buses.items()))
            try:
                return {name: call(name, bus)}
            except BusError as exc:
                return {name: exc}
        if self._pool is None:
            self._pool = ThreadPoolExecutor(len(self.buses), thread_name_prefix="bridge-bus")
        futures = {name: self._pool.submit(call, name, bus) for name, bus in self.buses.items()}
        results: dict[str, _T | BusError] = {}
        for name, future in futures.items():
            try:
                results[name] = future.result()
            except BusError as exc:
                results[name] = exc
        return results

    def _exchange(
        self, commands: Mapping[str, Mapping[int, MotorCommand]]
    ) -> list[MotorFeedback | None]:
        """Exchange on every bus; a failed bus raises its :class:`BusError` (after all ran)."""
        results = self._on_every_bus(lambda name, bus: bus.exchange(commands[name]))
        failed = [result for result in results.values() if isinstance(result, BusError)]
        if failed:
            raise failed[0]
        return self._counted(results)  # type: ignore[arg-type]

    def _hold_safe(self) -> None:
        """Command the safe state on every bus; a failing bus does not stop the others."""
        results = self._on_every_bus(lambda name, bus: bus.hold_safe(self._damping[name]))
        feedback: dict[str, dict[int, MotorFeedback | None]] = {}
        for name, result in results.items():
            if not isinstance(result, BusError):
                feedback[name] = result
            elif name not in self._failed_buses:
                log.error("cannot command the safe state on bus %r: %s", name, result.detail)
                self._failed_buses.add(name)
        self._absorb(self._counted(feedback))

    def _counted(
        self, feedback: Mapping[str, Mapping[int, MotorFeedback | None]]
    ) -> list[MotorFeedback | None]:
        """Each joint's reply (wire order), counted in its link quality."""
        replies = self.joint_map.gather(feedback)
        for link, reply in zip(self.report.links, replies, strict=True):
            link.add(reply)
        return replies

    def _check_joints(self) -> str:
        return check_joints(
            self.joint_map,
            self.joint_position_rad,
            self.joint_velocity_rad_s,
            self.temperature_C,
            self.settings.position_margin_rad,
        )

    def _absorb(self, feedback: list[MotorFeedback | None]) -> None:
        q, v, temperature = self.joint_map.joint_state(
            feedback, (self.joint_position_rad, self.joint_velocity_rad_s)
        )
        self.joint_position_rad, self.joint_velocity_rad_s = q, v
        known = ~np.isnan(temperature)
        self.temperature_C[known] = temperature[known]

    def _trip(self, reason: str) -> None:
        if self.latch.trip(reason, self.pacer.now_s() - self._origin_s):
            self.report.latches.append(reason)
            log.error("safe state latched: %s; re-arm to resume", reason)
