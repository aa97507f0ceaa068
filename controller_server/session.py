"""One client's session: its robot, its controller, its counters."""

from __future__ import annotations

import dataclasses
import logging
import time
import uuid
from collections import deque

import numpy as np

from controller_server.controllers import create_controller
from controller_server.errors import ModelMismatch, ServerFault, TickTooCostly
from controller_server.estimation import BaseEstimate, ImuBaseEstimator
from controller_server.models import load_robot_model
from controller_server.wire import command_from_output, control_input_from_state
from protocol.errors import ProtocolError
from protocol.messages import Command, Hello, Params, SessionStats, SetParams, State, Welcome

__all__ = ["MIN_TICK_BUDGET_S", "PROBE_TICKS", "TICK_COST_MARGIN", "Session"]

log = logging.getLogger("poise.server")

COMPUTE_TIME_WINDOW = 1000
"""Ticks kept for the compute-time percentiles in ``stats``."""

PROBE_TICKS = 3
"""Ticks a ``hello`` times on the standing state (the fastest counts: others' load only adds)."""
TICK_COST_MARGIN = 10.0
"""How much longer than the standing tick other states' ticks may take.

Measured on the built-in robots with 2 × 4 to 2 × 64 points per foot: random states
near standing (joint spread 0.3 rad, random supports) took up to 3× the standing tick
at 2 × 4 points, 7× at 2 × 32 and 35× at 2 × 64 (the caps on points keep the ratio
near the first); every QP is capped in iterations besides."""
MIN_TICK_BUDGET_S = 0.5
"""Tick budget of a server whose deadline is shorter (a deadline below any tick is how a
test gets ``DEADLINE_EXCEEDED``): its late ticks are answered so, without a refusal."""


class Session:
    """State the server keeps for one client identity between requests."""

    def __init__(self, hello: Hello, tick_budget_s: float | None = None):
        """Load the model and create the controller named in ``hello``.

        Args:
            hello: The request.
            tick_budget_s: Longest a tick may take (the server's deadline): a session
                whose standing tick × :data:`TICK_COST_MARGIN` exceeds
                ``max(tick_budget_s, MIN_TICK_BUDGET_S)`` is refused. ``None``: not timed.

        Raises:
            ServerFault: Model not found, invalid, mismatched or over a cap
                (:mod:`controller_server.errors`), unknown controller, invalid
                initial parameters, or a tick over the budget (``TickTooCostly``).
        """
        self.robot = load_robot_model(
            hello.model,
            model_text=hello.model_text,
            model_format=hello.model_format,
            model_assets=hello.model_assets,
            contacts=hello.contacts,
            keyframe=hello.keyframe,
        )
        if (
            hello.expected_model_hash is not None
            and hello.expected_model_hash != self.robot.model_hash
        ):
            raise ModelMismatch(
                f"client expects {hello.expected_model_hash[:12]}…, server model "
                f"{self.robot.name!r} is {self.robot.model_hash[:12]}…",
                field="expected_model_hash",
            )
        self.controller = create_controller(hello.controller, self.robot, hello.params)
        if tick_budget_s is not None:
            self._check_tick_cost(hello, max(tick_budget_s, MIN_TICK_BUDGET_S))
        self.base_estimator = ImuBaseEstimator(self.robot, hello)
        self.diagnostics_period_ticks = hello.diagnostics_period_ticks
        self.session_id = uuid.uuid4().hex
        self.ticks = 0
        self.errors = 0
        self.last_seen_s = time.monotonic()
        self._compute_times_s: deque[float] = deque(maxlen=COMPUTE_TIME_WINDOW)

    def _check_tick_cost(self, hello: Hello, budget_s: float) -> None:
        """Time :data:`PROBE_TICKS` ticks of a copy of the controller on the standing state.

        The copy runs its optimizer every tick (``optimizer_period_ticks`` 1, where it has
        one), diagnostics included, so that this session's controller starts fresh.

        Raises:
            TickTooCostly: The fastest tick × :data:`TICK_COST_MARGIN` exceeds ``budget_s``.
        """
        probe = create_controller(hello.controller, self.robot, hello.params)
        if "optimizer_period_ticks" in probe.parameters():
            probe.set_params({"optimizer_period_ticks": 1})
        robot = self.robot
        standing = State(
            seq=0,
            time_s=0.0,
            joint_position=np.array(robot.standing_joint_position, float),
            joint_velocity=np.zeros(robot.nv_joints),
            position_base_in_world=np.array(robot.standing_position_base_in_world, float),
            orientation_base_in_world_xyzw=np.array(
                robot.standing_orientation_base_in_world_xyzw, float
            ),
            linear_velocity_base_in_world=np.zeros(3),
            angular_velocity_base_in_base=np.zeros(3),
            contact_flags=[True] * len(robot.contacts),
        )
        fastest_s = float("inf")
        for _ in range(PROBE_TICKS):
            start = time.perf_counter()
            try:
                control_input, _ = control_input_from_state(robot, standing, True)
                probe.compute(control_input)
            except (ServerFault, ProtocolError) as exc:  # the time spent counts all the same
                log.info("probe tick of a new session failed: %s", exc)
            elapsed_s = time.perf_counter() - start
            fastest_s = min(fastest_s, elapsed_s)
            if elapsed_s > budget_s:
                break  # over the whole budget alone: not worth repeating
        if fastest_s * TICK_COST_MARGIN <= budget_s:
            return
        raise TickTooCostly(
            f"a tick of this model and controller takes {fastest_s * 1e3:.1f} ms on this "
            f"server standing (nv = {robot.model.nv}, {len(robot.contacts)} contacts, "
            f"{robot.num_contact_points} points), and other states up to "
            f"{TICK_COST_MARGIN:g}× that: over the {budget_s * 1e3:g} ms budget (the server's "
            "`poise serve --deadline`); use fewer contact points or joints, or a server with "
            "a longer deadline",
            field="model",
        )

    def welcome(self, seq: int) -> Welcome:
        """The handshake reply describing this session's robot and controller."""
        return Welcome(
            seq=seq,
            session_id=self.session_id,
            model_name=self.robot.name,
            model_hash=self.robot.model_hash,
            total_mass=self.robot.total_mass,
            standing_position_base_in_world=tuple(self.robot.standing_position_base_in_world),
            standing_orientation_base_in_world_xyzw=tuple(
                self.robot.standing_orientation_base_in_world_xyzw
            ),
            standing_joint_position=list(self.robot.standing_joint_position),
            joints=list(self.robot.joints),
            contacts=[contact.to_spec() for contact in self.robot.contacts],
            controller=self.controller.name,
            params=self.controller.parameters(),
        )

    def step(self, state: State) -> Command:
        """Answer one state with a command."""
        start = time.perf_counter()
        want_diagnostics = self.ticks % self.diagnostics_period_ticks == 0
        control_input, estimate = control_input_from_state(
            self.robot, state, want_diagnostics, self._estimate_base
        )
        output = self.controller.compute(control_input)
        compute_time_s = time.perf_counter() - start
        if not want_diagnostics and output.diagnostics is not None:
            output = dataclasses.replace(output, diagnostics=None)  # computed anyway: not sent
        command = command_from_output(
            control_input, output, state.seq, compute_time_s, estimate if want_diagnostics else None
        )
        self._compute_times_s.append(compute_time_s)
        self.ticks += 1
        return command

    def _estimate_base(self, state: State) -> BaseEstimate:
        """The base estimate of a state with ``imu``, by the controller's ``kernel`` in force.

        One mechanism for the whole tick: the parameter that selects the compiled dynamics
        terms selects the compiled estimator too, per state (the estimator hands its filter
        over when it changes).
        """
        return self.base_estimator(state, kernel=self.controller.in_force()["kernel"])

    def set_params(self, request: SetParams) -> Params:
        """Apply parameters (all or nothing) and return every value in force."""
        self.controller.set_params(request.params)
        return Params(seq=request.seq, params=self.controller.parameters())

    def stats(self, now_s: float) -> SessionStats:
        """Counters and compute-time percentiles over the last ticks."""
        times = np.array(self._compute_times_s) if self._compute_times_s else np.zeros(1)
        return SessionStats(
            session_id=self.session_id,
            model_name=self.robot.name,
            controller=self.controller.name,
            ticks=self.ticks,
            errors=self.errors,
            compute_time_p50_s=float(np.percentile(times, 50)),
            compute_time_p99_s=float(np.percentile(times, 99)),
            idle_s=now_s - self.last_seen_s,
        )
