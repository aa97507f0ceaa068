"""One client's session: its robot, its controller, its counters."""

from __future__ import annotations

import dataclasses
import time
import uuid
from collections import deque

import numpy as np

from controller_server.controllers import create_controller
from controller_server.errors import ModelMismatch
from controller_server.estimation import ImuBaseEstimator
from controller_server.models import load_robot_model
from controller_server.wire import command_from_output, control_input_from_state
from protocol.messages import Command, Hello, Params, SessionStats, SetParams, State, Welcome

__all__ = ["Session"]

COMPUTE_TIME_WINDOW = 1000
"""Ticks kept for the compute-time percentiles in ``stats``."""


class Session:
    """State the server keeps for one client identity between requests."""

    def __init__(self, hello: Hello):
        """Load the model and create the controller named in ``hello``.

        Raises:
            ServerFault: Model not found, invalid or mismatched
                (:mod:`controller_server.errors`), unknown controller, or invalid
                initial parameters.
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
        self.base_estimator = ImuBaseEstimator(self.robot, hello)
        self.diagnostics_period_ticks = hello.diagnostics_period_ticks
        self.session_id = uuid.uuid4().hex
        self.ticks = 0
        self.errors = 0
        self.last_seen_s = time.monotonic()
        self._compute_times_s: deque[float] = deque(maxlen=COMPUTE_TIME_WINDOW)

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
            self.robot, state, want_diagnostics, self.base_estimator
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
