"""Run a scenario: a physics backend as a client of the controller server.

Every control tick the runner reads the backend's state, sends it to the
server (``state``), and applies the returned torques for the physics steps
until the next tick (zero-order hold). With ``command_delay_ticks = 1`` the
torques of tick k's command are held from tick k + 1 on, and the physics
steps while the server computes (client and server run in parallel, one
control period apart, as on hardware); the state sent at tick k is then the
one predicted for tick k + 1 (:meth:`RobotState.predicted`), so each command
is computed for the state it will act on. The scenario's parameter changes go
out as ``set_params`` at their tick. Each state carries the backend's
contact wrenches (the thesis' penalty forces): the momentum controller reads
its instability indicator ``‖p − g‖`` (eq. 5.17) from them in either
ground-force mode, and in ``measured`` mode its inverse dynamics uses them
too. A predicted state (``command_delay_ticks = 1``) carries them only in
``measured`` mode: they were measured a tick before it, and with them the
MuJoCo ``push_sequence`` fell in that configuration. The run stops early
once the robot has fallen.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from clients.client import ControllerClient, CurveKeys, ServerError, ServerTimeout
from clients.physics.backend import PhysicsBackend, Push, physics_backend
from clients.physics.imu import SimulatedImu
from clients.physics.model_file import describe_model, hello_model
from clients.physics.status import fall_reason, standing_state, support_flags
from clients.sim.scenario import Scenario, controller_params, initial_joint_positions
from clients.state import RobotState
from clients.track import RunObserver, Track
from protocol.messages import Command, Diagnostics, Welcome

__all__ = ["RunRecord", "make_backend", "run_scenario", "track_of_run"]


def make_backend(scenario: Scenario) -> PhysicsBackend:
    """The scenario's physics backend at its physics rate and friction."""
    return physics_backend(
        scenario.backend,
        scenario.model,
        scenario.physics_rate_hz,
        scenario.friction_coefficient,
        contacts=scenario.contacts,
        keyframe=scenario.keyframe,
        mujoco_contact_time_constant_s=scenario.mujoco_contact_time_constant_s,
    )


@dataclass
class RunRecord:
    """Time series of one run, one row per control tick."""

    scenario: Scenario
    welcome: Welcome
    time_s: list[float] = field(default_factory=list)
    states: list[RobotState] = field(default_factory=list)
    commands: list[Command] = field(default_factory=list)
    contact_flags: list[list[bool]] = field(default_factory=list)
    fell: bool = False
    fall_time_s: float | None = None
    fall_reason: str = ""
    stopped: str = ""
    """Why the run ended before ``duration_s`` without a fall ("": it did not)."""
    model_notes: list[str] = field(default_factory=list)
    """What the backend changed so it simulates what the server controls (servos → motors …)."""
    wall_time_s: float = 0.0

    def diagnostics(self) -> list[Diagnostics]:
        """The diagnostics of :meth:`diagnosed_ticks`, in order."""
        return [c.diagnostics for c in self.commands if c.diagnostics is not None]

    def diagnosed_ticks(self) -> list[int]:
        """Indices of the ticks whose command carries diagnostics (``diagnostics_period_ticks``)."""
        return [
            tick for tick, command in enumerate(self.commands) if command.diagnostics is not None
        ]

    @property
    def simulated_s(self) -> float:
        """Simulated time covered."""
        return self.time_s[-1] + 1.0 / self.scenario.control_rate_hz if self.time_s else 0.0

    @property
    def real_time_factor(self) -> float:
        """Simulated time over wall-clock time (≥ 1: faster than real time)."""
        return self.simulated_s / self.wall_time_s if self.wall_time_s > 0 else float("nan")


def track_of_run(record: RunRecord) -> Track:
    """The track of a simulator run (its true states): it shares the record's lists, so it grows."""
    scenario = record.scenario
    return Track(
        name=scenario.name,
        controller=scenario.controller,
        backend=scenario.backend,
        model=scenario.model,
        keyframe=scenario.keyframe,
        welcome=record.welcome,
        time_s=record.time_s,
        states=record.states,
        commands=record.commands,
        pushes=scenario.pushes,
    )


def _step_physics(
    backend: PhysicsBackend,
    joint_torque: np.ndarray,
    pushes: list[Push],
    steps: int,
    imu: SimulatedImu | None,
) -> bool:
    """Hold ``joint_torque`` for ``steps`` physics steps (the IMU sees each one).

    Returns:
        True if a non-foot body touched the ground.
    """
    non_foot_contact = False
    for _ in range(steps):
        non_foot_contact |= backend.step(joint_torque, pushes).non_foot_contact
        if imu is not None:
            imu.update(backend.state(), backend.time_s)
    return non_foot_contact


def run_scenario(
    scenario: Scenario,
    endpoint: str,
    progress: Any = None,
    timeout_s: float = 10.0,
    curve: CurveKeys | None = None,
    log_path: str | os.PathLike[str] | None = None,
    observer: RunObserver | None = None,
) -> RunRecord:
    """Simulate ``scenario`` against the server at ``endpoint``.

    Args:
        scenario: What to run.
        endpoint: ``poise serve`` endpoint.
        progress: Optional callable ``progress(fraction)`` for a progress bar.
        timeout_s: Per-request timeout.
        curve: CURVE keys for a server that requires them.
        log_path: MCAP file to record the conversation with the server to.
        observer: Called with the run's track after every tick is added to it (a live view).
    """
    backend = make_backend(scenario)
    pushes = [push.to_push() for push in scenario.pushes]
    measured = scenario.ground_force_mode == "measured"
    imu = None
    imu_mount: dict[str, Any] = {}
    if scenario.base_state == "imu":
        spec = scenario.imu.model_copy(update={"rate_hz": scenario.control_rate_hz})
        imu = SimulatedImu(spec, scenario.model)
        imu_mount = {
            "imu_frame": imu.body_name,
            "imu_position_in_frame": spec.position_in_body_m,
            "imu_orientation_in_frame_xyzw": spec.orientation_in_body_xyzw,
        }
    with ControllerClient(endpoint, timeout_s=timeout_s, curve=curve, record=log_path) as client:
        welcome = client.connect(
            **hello_model(scenario.model),
            contacts=scenario.contacts,
            keyframe=scenario.keyframe,
            controller=scenario.controller,
            # Only the weighted controllers have a measured mode; distributed is their default.
            params={
                **controller_params(scenario),
                **({"ground_force_mode": "measured"} if measured else {}),
            },
            client_name=f"poise sim {scenario.name}",
            diagnostics_period_ticks=scenario.diagnostics_period_ticks,
            **imu_mount,
        )
        backend.reset(
            standing_state(
                welcome,
                initial_joint_positions(scenario),
                describe_model(scenario.model).model,
                scenario.model,
            )
        )
        if imu is not None:
            imu.reset(backend.state(), backend.time_s)
        standing_height_m = welcome.standing_position_base_in_world[2]
        record = RunRecord(scenario, welcome, model_notes=list(backend.conversions))
        track = track_of_run(record)
        ticks = round(scenario.duration_s * scenario.control_rate_hz)
        steps = scenario.physics_steps_per_control_tick
        changes = list(scenario.param_changes)
        flags = backend.contact_flags()  # at rest on the ground: every touching foot supports
        held_command = None  # with a command delay: the previous tick's command
        # Pipelined runs predict the state with a Pinocchio model of the same file.
        model = describe_model(scenario.model).model if scenario.command_delay_ticks else None
        state = backend.state()
        start = time.perf_counter()
        try:
            for tick in range(ticks):
                while changes and changes[0].time_s <= backend.time_s + 1e-9:
                    client.set_params(changes.pop(0).params)
                touching = backend.contact_flags()
                # Read every tick: MuJoCo makes a contact-force call per contact (40 µs for 8).
                wrenches = backend.contact_wrenches_in_world()
                flags = support_flags(
                    flags, touching, wrenches[:, 2], scenario.support_force_threshold_N
                )
                if scenario.command_delay_ticks and not measured:
                    wrenches = None
                sent, sent_time_s = state, backend.time_s
                if held_command is not None and model is not None:
                    # This tick's command acts from the next tick on: send the state it will
                    # meet there, predicted with the accelerations of the command acting now.
                    period_s = 1.0 / scenario.control_rate_hz
                    sent = state.predicted(period_s, model, held_command)
                    sent_time_s += period_s
                try:
                    if imu is None:
                        client.send_state(sent.to_message(sent_time_s, flags, wrenches))
                    else:  # the joints, and the IMU for the base (sampled at this tick)
                        sample = imu.reading().to_sample()  # type: ignore[union-attr]
                        client.send_state(sent.to_imu_message(sent_time_s, flags, sample, wrenches))
                    if held_command is None or not scenario.command_delay_ticks:
                        command = client.receive_command()
                        non_foot_contact = _step_physics(
                            backend, command.joint_torque, pushes, steps, imu
                        )
                    else:  # the physics runs while the server computes this state's command
                        non_foot_contact = _step_physics(
                            backend, held_command.joint_torque, pushes, steps, imu
                        )
                        command = client.receive_command()
                    held_command = command
                except ServerError as exc:  # no command for this state: the run ends here
                    record.fell, record.fall_time_s = True, backend.time_s
                    record.fall_reason = f"controller error {exc.code.name}: {exc.detail}"
                    break
                except ServerTimeout as exc:  # the server is gone: keep what ran
                    record.stopped = str(exc)
                    break
                record.time_s.append(tick / scenario.control_rate_hz)
                record.states.append(state)
                record.commands.append(command)
                record.contact_flags.append(flags)
                if observer is not None:
                    observer(track)
                state = backend.state()  # after the step: checked now, sent next tick
                reason = fall_reason(state, standing_height_m, non_foot_contact)
                if reason:
                    record.fell, record.fall_time_s = True, backend.time_s
                    record.fall_reason = reason
                    break
                if progress is not None and tick % 50 == 0:
                    progress(tick / ticks)
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM: keep what ran; the caller stops
            record.stopped = "interrupted"
        record.wall_time_s = time.perf_counter() - start
    return record
