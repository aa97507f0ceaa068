"""The weighted controllers' tick by the compiled core: one call from state to command.

``controller_server._core.WeightedTick`` (``controller_server/core/weighted_tick.hpp``) runs
:class:`~controller_server.controllers.momentum.MomentumController`'s tick in C++: the
dynamics terms, the optimizer of Macchietto 2008, eq. 5.1 (the tasks ``tracking``,
``linear_momentum``, ``angular_momentum`` and the point targets, the KKT of App. D with
damped least squares) every N-th tick or when the supports change, and the inverse dynamics
of eq. 4.2 with its contact-force QP (eiquadprog) — with the GIL released and no allocation
after the first ticks. The Python tick stays the specification (``kernel = "python"``);
tests hold the two together.

What stays in Python, per tick: the parameters in force and the point targets handed to the
core when they change, a motion clip's sample, a hosted behaviour (between
:meth:`WeightedTick.prepare` and the rest of the tick, at the optimizer's rate), and the
diagnostics' assembly.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from controller_server.behaviors import Observation
from controller_server.compiled import load_core
from controller_server.controllers.base import ControlInput, ControlOutput
from controller_server.controllers.diagnostics import weighted_diagnostics
from controller_server.dynamics import new_core
from controller_server.errors import ControllerFailed, InvalidParams
from controller_server.tasks import (
    CopWeightedAngularMomentumTask,
    LinearMomentumTask,
    PointTask,
    TrackingTask,
)

if TYPE_CHECKING:
    from controller_server.controllers.momentum import MomentumController

__all__ = ["COMPILED_TASKS", "CompiledWeightedTick"]

COMPILED_TASKS: dict[str, type] = {
    "tracking": TrackingTask,
    "linear_momentum": LinearMomentumTask,
    "angular_momentum": CopWeightedAngularMomentumTask,
}
"""The weighted stack's tasks that the core computes, by name (and every :class:`PointTask`)."""


class CompiledWeightedTick:
    """One session's compiled tick for a weighted controller (created at its first tick).

    Raises:
        CompiledCoreUnavailable: The core is not built or was built for another Pinocchio.
    """

    def __init__(self, controller: MomentumController):
        robot = controller.robot
        self._tick = load_core().WeightedTick(new_core(robot), robot.torque_limit)
        self._tick.set_limits(controller.joint_limits().compiled())
        self._model = robot.model
        self._synced: Mapping[str, Any] | None = None  # the parameters the core holds
        self._synced_points: tuple[tuple[PointTask, float], ...] = ()  # its point targets

    def compute(self, controller: MomentumController, control_input: ControlInput) -> ControlOutput:
        """One tick of ``controller`` by the core.

        Raises:
            InvalidParams: Measured ground-force mode without measured wrenches.
            ControllerFailed: The dynamics overflow at this state, or a linear solve failed.
        """
        tick, q, v = self._tick, control_input.q, control_input.v
        params = self._sync(controller, self._check_tasks(controller))
        wrenches = control_input.contact_wrench_in_world
        if wrenches is not None:
            wrenches = np.ascontiguousarray(wrenches, dtype=float).reshape(-1, 6)
        if params["ground_force_mode"] == "measured" and wrenches is None:
            raise InvalidParams(
                "contact_wrench_in_world", "required in ground_force_mode 'measured'"
            )
        flags = controller.supports(control_input)
        supports = list(flags)
        prepared = False
        if params.get("behavior", "balance") != "balance" and tick.optimizer_due(supports):
            # A behaviour runs at the optimizer's rate, on the state's terms: its targets
            # steer this tick's solve.
            tick.prepare(q, v)
            prepared = True
            controller._host(control_input, lambda: self._observation(controller, control_input))
            params = self._sync(controller, self._synced_points)
        clip = controller.clip_sample(control_input.time_s)
        out = tick.compute(
            q,
            v,
            supports,
            wrenches,
            *(clip if clip is not None else (None, None, None)),
            prepared,
            control_input.want_diagnostics,
        )
        if out["failure"] is not None:
            failure: str = out["failure"]
            if failure.startswith("non-finite"):
                failure += (
                    f" at this state (max |v| = {float(np.max(np.abs(v))):.3g}: the dynamics "
                    "overflow); no command"
                )
            raise ControllerFailed(failure)
        diagnostics = None
        if control_input.want_diagnostics:
            diagnostics = weighted_diagnostics(
                controller.robot.total_mass, params["ground_height"], flags, out
            )
        return ControlOutput(
            acceleration=out["acceleration"],
            joint_torque=out["joint_torque"],
            contact_force_in_world=out["contact_force_in_world"],
            contact_wrench_in_world=out["contact_wrench_in_world"],
            diagnostics=diagnostics,
        )

    @property
    def inverse_dynamics_path(self) -> str:
        """Which branch of the inverse dynamics answered the last tick (``exact``, …)."""
        return self._tick.inverse_dynamics_path

    @staticmethod
    def _check_tasks(controller: MomentumController) -> tuple[tuple[PointTask, float], ...]:
        """The stack's point targets and weights (compared by identity), or a refusal.

        A task the core does not compute (a user's, run-time task) is refused.

        Raises:
            InvalidParams: Naming the task and the kernel that solves it.
        """
        points = []
        for slot in controller.tasks:
            task = slot.task
            if isinstance(task, PointTask):
                points.append((task, slot.weight))
            if type(task) is not COMPILED_TASKS.get(task.name, PointTask):
                raise InvalidParams(
                    "params.kernel",
                    f"task {task.name!r} ({type(task).__name__}) is not in the compiled tick, "
                    "which solves tracking, linear_momentum, angular_momentum and point "
                    "targets: set kernel 'python' to solve it",
                )
        return tuple(points)

    def _sync(
        self, controller: MomentumController, points: tuple[tuple[PointTask, float], ...]
    ) -> Mapping[str, Any]:
        """The parameters in force, handed to the core whenever they (or the points) changed."""
        params = controller.in_force()
        if params is not self._synced or points != self._synced_points:
            self._tick.set_params(params)
            self._tick.set_points(
                [
                    self._point(slot.task, slot.weight)
                    for slot in controller.tasks
                    if isinstance(slot.task, PointTask)
                ]
            )
            self._synced, self._synced_points = params, points
        return params

    def _point(self, task: PointTask, weight: float) -> tuple[Any, ...]:
        """A point target as the core takes it (its frame by id)."""
        target = task.target
        return (
            task.name.removeprefix("point:"),
            int(self._model.getFrameId(target.frame)),
            target.offset_in_frame,
            target.target_position_in_world,
            target.target_velocity_in_world,
            target.stiffness,
            target.damping,
            weight,
        )

    def _observation(
        self, controller: MomentumController, control_input: ControlInput
    ) -> Observation:
        """What a behaviour observes of the prepared state."""
        seen = self._tick.observation()
        return controller.observation(
            control_input,
            position_com_in_world=seen["position_com_in_world"],
            velocity_com_in_world=seen["velocity_com_in_world"],
            position_contact_frames_in_world=seen["position_contact_frames_in_world"],
            orientation_contact_frames_in_world=seen["orientation_contact_frames_in_world"].reshape(
                -1, 3, 3
            ),
        )
