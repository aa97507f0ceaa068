"""``poise bridge``: connect, check the map, open the buses, run the loop, report.

With ``emulate``, every bus of the map is served by emulated actuators
(virtual CAN channels and pseudo-terminals instead of the configured
interfaces) on a simulated robot, which the loop paces: the whole stack
runs as on hardware, minus the hardware.
"""

from __future__ import annotations

import json
import logging
import queue
import sys
import threading
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from clients.bridge.base_state import (
    BaseStateSource,
    FixedBase,
    ImuSource,
    SimulatedImuBase,
    SimulatorBase,
)
from clients.bridge.buses import (
    bus_time_per_tick_s,
    check_motors,
    motor_peak_torque_Nm,
    open_buses,
)
from clients.bridge.config import (
    BridgeConfig,
    BridgeConfigError,
    check_against_welcome,
    imu_mount_on_root_body,
)
from clients.bridge.joint_map import JointMap
from clients.bridge.loop import Bridge, Pacer
from clients.bridge.plant import RealTimePacer
from clients.bridge.report import BridgeReport
from clients.client import ControllerClient, CurveKeys
from clients.physics.model_file import describe_model, hello_model
from clients.track import RunObserver, Track

if TYPE_CHECKING:
    from clients.bridge.emulation import Emulation

__all__ = [
    "BridgeRun",
    "BridgeSession",
    "check_base_state",
    "format_report",
    "open_bridge",
    "run_bridge",
    "stdin_operator",
    "write_report",
]

log = logging.getLogger("poise.bridge")

BUS_LOAD_WARNING = 0.8
"""A bus whose exchange needs more than this fraction of the period is warned about."""

DIAGNOSTICS_PERIOD_TICKS = 100
"""The bridge asks for diagnostics every this many ticks (they cost the server time)."""

VIEW_KEEP_S = 10.0
"""Seconds of ticks the bridge keeps for a live view (it plots the last 5 s): a run has no end."""


@dataclass
class BridgeRun:
    """A finished run: the loop's report, and with emulation what the robot did."""

    report: BridgeReport
    emulated: bool = False
    fall_reason: str = ""
    fall_time_s: float | None = None
    simulated_s: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """``report.json``."""
        data = self.report.to_json()
        if self.emulated:
            data["emulation"] = {
                "fell": bool(self.fall_reason),
                "fall_reason": self.fall_reason,
                "fall_time_s": self.fall_time_s,
                "simulated_s": self.simulated_s,
            }
        return data


def stdin_operator() -> queue.Queue[str]:
    """Operator commands typed on stdin (one per line), read by a daemon thread."""
    commands: queue.Queue[str] = queue.Queue()

    def read() -> None:
        for line in sys.stdin:
            commands.put(line)

    threading.Thread(target=read, name="bridge-operator", daemon=True).start()
    return commands


@dataclass
class BridgeSession:
    """A bridge ready to run: its loop and, with emulation, the emulated robot."""

    bridge: Bridge
    emulation: Emulation | None = None


@contextmanager
def open_bridge(
    config: BridgeConfig,
    endpoint: str,
    *,
    emulate: bool = False,
    record: Path | None = None,
    curve: CurveKeys | None = None,
    operator: queue.Queue[str] | None = None,
    timeout_s: float = 10.0,
    wall_clock: bool = False,
    imu_source: ImuSource | None = None,
    observer: RunObserver | None = None,
) -> Iterator[BridgeSession]:
    """Connect, check the map against the server, open the buses (or emulate them).

    Args:
        config: The bridge file.
        endpoint: ``poise serve`` endpoint.
        emulate: Emulated actuators on a simulated robot instead of hardware.
        record: MCAP file of the conversation with the server.
        curve: CURVE keys for a server that requires them.
        operator: Operator commands (``estop``, ``rearm``, ``quit``).
        timeout_s: Wait for the server's handshake.
        wall_clock: With ``emulate``, pace by the wall clock (the emulated
            robot then stands still): for timing the loop.
        imu_source: The robot's IMU and contact flags, for ``base_state =
            "imu"`` with ``[imu] source = "external"`` (real hardware).
        observer: Sees the measured robot and the server's commands after
            every answered tick (a live view); it must never wait
            (:class:`~clients.visual.live_process.LiveViewProcess`).

    Raises:
        BridgeConfigError: The map does not match the server's joints, or a
            motor model is unknown, or the base-state source cannot be had:
            ``base_state = "simulator"`` or an emulated IMU without emulation,
            an external IMU without ``imu_source``, or an ``imu_source`` the
            map does not use, or an ``[imu] frame`` that the model lacks or
            that moves relative to the root body (all before connecting).
        BusError: A bus cannot be opened.
    """
    settings = config.bridge
    check_motors(config)
    check_base_state(config, emulate, imu_source)
    if settings.base_state == "imu":
        imu_mount_on_root_body(config)  # a mistake in [imu] is one line, before connecting
    period_s = 1.0 / settings.rate_hz
    for name, spec in config.buses.items():
        busy_s = bus_time_per_tick_s(spec, len(config.joints_on(name)))
        if busy_s > BUS_LOAD_WARNING * period_s:
            log.warning(
                "bus %r: its %d actuators need at least %.2f ms of bus time per tick, "
                "%.0f%% of the %.2f ms period; split them over more buses or lower rate_hz",
                name,
                len(config.joints_on(name)),
                1e3 * busy_s,
                100 * busy_s / period_s,
                1e3 * period_s,
            )
    with ExitStack() as stack:
        client = stack.enter_context(
            ControllerClient(endpoint, timeout_s=timeout_s, curve=curve, record=record)
        )
        mount: dict[str, Any] = {}
        if settings.base_state == "imu":
            imu = config.imu_settings
            mount = {
                "imu_frame": imu.frame or None,
                "imu_position_in_frame": imu.position_in_frame,
                "imu_orientation_in_frame_xyzw": imu.orientation_in_frame_xyzw,
            }
        welcome = client.connect(
            **hello_model(settings.model),
            controller=settings.controller,
            params=settings.params,
            client_name="poise bridge",
            diagnostics_period_ticks=DIAGNOSTICS_PERIOD_TICKS,
            **mount,
        )
        check_against_welcome(config, welcome)
        joint_map = JointMap(
            config,
            welcome,
            {
                joint: motor_peak_torque_Nm(config.buses[actuator.bus].protocol, actuator)
                for joint, actuator in config.joints.items()
            },
        )
        model = describe_model(settings.model).model
        pacer: Pacer = RealTimePacer(period_s)
        base: BaseStateSource = FixedBase(welcome) if imu_source is None else imu_source
        overrides: dict[str, dict[str, Any]] = {}
        emulation = None
        if emulate:
            from clients.bridge.emulation import Emulation

            emulation = stack.enter_context(Emulation(config, welcome, joint_map, wall_clock))
            overrides = emulation.bus_overrides
            pacer = emulation.pacer(period_s)
            threshold_N = settings.support_force_threshold_N
            if settings.base_state == "simulator":
                base = SimulatorBase(emulation.plant, threshold_N)
            elif emulation.imu is not None:
                base = SimulatedImuBase(emulation.imu, emulation.plant, threshold_N)
        buses = open_buses(config, overrides)
        for bus in buses.values():
            stack.callback(bus.close)
        # The safe state must reach the actuators within the watchdog time: stop
        # waiting for the server early by what one safe exchange may take on the
        # loop's clock. The buses exchange at once: the longest reply timeout, and
        # 1 ms. (Under simulated pacing, the map's: what the hardware would take.)
        in_force = overrides if emulation is not None and emulation.wall_clock else {}
        margin_s = 0.001 + max(
            in_force.get(name, {}).get("reply_timeout_s", spec.reply_timeout_s)
            for name, spec in config.buses.items()
        )
        track = None
        if observer is not None:
            track = Track(
                name=Path(settings.model).stem,
                controller=welcome.controller,
                backend="emulated bridge" if emulate else "bridge",
                model=settings.model,
                keyframe=None,
                welcome=welcome,
                pushes=config.emulation.pushes if emulate else (),
                keep_s=VIEW_KEEP_S,
            )
        bridge = Bridge(
            settings,
            joint_map,
            buses,
            client,
            base,
            pacer,
            model,
            operator,
            timeout_s,
            margin_s,
            imu_max_sample_age_s=config.imu_settings.max_sample_age_s,
            observer=observer,
            track=track,
        )
        yield BridgeSession(bridge, emulation)


def check_base_state(config: BridgeConfig, emulate: bool, imu_source: ImuSource | None) -> None:
    """Refuse a base-state source that this run cannot have, in one line.

    Raises:
        BridgeConfigError: ``base_state = "simulator"``, or ``"imu"`` with an
            emulated IMU, without emulation; an external IMU without
            ``imu_source``; an ``imu_source`` that the map does not use.
    """
    base_state = config.bridge.base_state
    source = config.imu_settings.source
    if base_state == "simulator" and not emulate:
        raise BridgeConfigError(
            'base_state = "simulator" is the emulated robot\'s ground truth: run with '
            '--emulate, or set base_state = "fixed" for a robot on a stand'
        )
    if imu_source is not None and not (base_state == "imu" and source == "external"):
        raise BridgeConfigError(
            'an IMU source was given but the map does not use it: set base_state = "imu" '
            'and, in [imu], source = "external"'
        )
    if base_state != "imu":
        return
    if source == "emulated" and not emulate:
        raise BridgeConfigError(
            '[imu] source = "emulated" is the emulated robot\'s IMU: run with --emulate; '
            'on hardware set source = "external" and give the bridge your IMU (an ImuSource, '
            "docs/bridge.md)"
        )
    if source == "external" and imu_source is None:
        raise BridgeConfigError(
            '[imu] source = "external" needs the robot\'s IMU: pass an ImuSource to '
            "run_bridge or open_bridge (imu_source=...; docs/bridge.md), or set source = "
            '"emulated" with --emulate (poise bridge has no IMU driver of its own)'
        )


def run_bridge(
    config: BridgeConfig,
    endpoint: str,
    *,
    duration_s: float | None = None,
    **options: Any,
) -> BridgeRun:
    """Run the bridge of ``config`` against the server at ``endpoint`` and report.

    Args:
        config: The bridge file.
        endpoint: ``poise serve`` endpoint.
        duration_s: Overrides ``[bridge] duration_s`` (0: until stopped).
        **options: As for :func:`open_bridge`.

    Raises:
        BridgeConfigError: See :func:`open_bridge`.
        BusError: A bus cannot be opened.
        BridgeStartError: An actuator is silent, faulted or out of its limits.
    """
    with open_bridge(config, endpoint, **options) as session:
        duration = config.bridge.duration_s if duration_s is None else duration_s
        run = BridgeRun(session.bridge.run(duration), emulated=session.emulation is not None)
        if session.emulation is not None:
            plant = session.emulation.plant
            run.fall_reason, run.fall_time_s = plant.fall_reason, plant.fall_time_s
            run.simulated_s = plant.time_s
    return run


def format_report(run: BridgeRun) -> str:
    """The summary ``poise bridge`` prints: why it stopped, timing, then one line per joint."""
    report = run.report
    timing = report.timing
    lines = [
        f"stopped: {report.stopped or '?'}; safe state latched {len(report.latches)} time(s)"
        + "".join(f"\n  - {reason}" for reason in report.latches),
        f"loop: {timing.ticks} ticks, period {1e3 * timing.period_mean_s:.3f} ms "
        f"± {1e3 * timing.jitter_s:.3f} (max {1e3 * timing.period_max_s:.3f}), "
        f"work max {1e3 * timing.work_max_s:.3f} ms, {timing.overruns} overruns",
        f"server: {report.commands} commands, {report.invalid_commands} refused, "
        f"{report.server_timeouts} timeouts; {report.clamped_torques} torques clamped",
    ]
    if run.emulated:
        robot = (
            f"fell at {run.fall_time_s:.2f} s ({run.fall_reason})"
            if run.fall_reason
            else "stayed up"
        )
        lines.append(f"emulated robot: {robot} over {run.simulated_s:.2f} s simulated")
    lines.append(
        f"{'joint':<22} {'bus':<10} {'id':>4} {'replies':>8} {'missed':>7} "
        f"{'faults':>6} {'T max °C':>8}"
    )
    for link in report.links:
        lines.append(
            f"{link.joint:<22} {link.bus:<10} {link.id:>4} {link.replies:>8} {link.missed:>7} "
            f"{link.faults:>6} {link.temperature_max_C:>8.1f}"
        )
    return "\n".join(lines)


def write_report(run: BridgeRun, path: Path) -> None:
    """Write ``report.json``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(run.to_json(), indent=2, allow_nan=False, default=str))
