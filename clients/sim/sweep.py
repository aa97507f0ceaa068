"""Push sweeps: the largest push each controller survives, per direction (thesis ch. 7.1).

For each controller of :data:`SWEEP_CONTROLLERS` and each push direction, a
:class:`Bisection` narrows down the largest force (N) of a push the robot
survives. The pairs are independent, so their trials run on a
:class:`~clients.pool.RunPool` (in this process, on local worker processes or
on a Dask cluster); each pair's trials run one after the other, each force
chosen from the pair's own results, so every pair tries the same forces and
reaches the same answer whatever the pool.

Beside each answer the sweep gives the robot's own no-step bound
(:func:`~clients.physics.robot_terms.no_step_bound`): the largest impulse
(N·s) it could take on both feet without stepping, from its standing pose
and soles, and the impulse survived (force × duration) as a share of it.

A sweep writes its JSON and picture (:func:`~.sweep_files.write_sweep`) after every finished
bisection, each replaced in one step, and once more when it ends, however it
ends (Ctrl-C, SIGTERM, a trial without an answer): a stopped sweep keeps every
trial that ran, its JSON says ``"complete": false``.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from clients.client import CurveKeys, ServerTimeout
from clients.physics.backend import PushSpec
from clients.physics.errors import ScenarioError
from clients.physics.model_file import describe_model
from clients.physics.robot_terms import NoStepBound, RobotTermsError, no_step_bound, resolve_body
from clients.pool import BATCH_DEADLINE_S, RunPool, Task
from clients.progress import ProgressBar
from clients.sim.runner import run_scenario
from clients.sim.scenario import Scenario, initial_configuration, load_scenario
from clients.sim.sweep_files import sweep_paths, write_sweep
from protocol.errors import ErrorCode

__all__ = [
    "ABLATIONS",
    "SWEEP_CONTROLLERS",
    "SWEEP_DIRECTIONS",
    "TRIAL_ATTEMPTS",
    "TRIAL_QP_TIME_BUDGET_S",
    "Bisection",
    "Sweep",
    "push_survived",
    "sweep_bounds",
    "sweep_controllers",
    "sweep_entries",
    "sweep_push",
    "trial_scenario",
]

ANGULAR_OFF: dict[str, Any] = {"angular_momentum_gain": 0.0, "weight_angular_momentum": 0.0}
ABLATIONS: dict[str, dict[str, Any]] = {
    "tracking only": {"weight_linear_momentum": 0.0, **ANGULAR_OFF},
    "+ linear momentum": ANGULAR_OFF,
    "+ linear and angular momentum": {},
}
"""Thesis ch. 7.1 ablations of the momentum controller, as parameter overrides."""
TRIAL_QP_TIME_BUDGET_S = 5.0
"""The prioritized controller's ``qp_time_budget_s`` in a sweep (default 0.02 s): with the
default, a tick near the limits skips its QP's second tries once 20 ms of wall time are spent,
so on a busy machine (or with more workers) a trial near the survival boundary could come out
otherwise (seen: 265.6 N from behind survived on one worker and fell on two)."""
SWEEP_CONTROLLERS: dict[str, tuple[str, dict[str, Any]]] = {
    **{label: ("momentum", params) for label, params in ABLATIONS.items()},
    "prioritized (de Lasa 2010)": ("prioritized", {"qp_time_budget_s": TRIAL_QP_TIME_BUDGET_S}),
}
"""What ``poise sim --sweep-push`` compares: label → (controller, parameter overrides).

Only what depends on the simulation, not on the machine's speed: see
:data:`TRIAL_QP_TIME_BUDGET_S` and :data:`~clients.pool.BATCH_DEADLINE_S`."""


def sweep_entries(controller: str | None) -> dict[str, tuple[str, dict[str, Any]]]:
    """What a sweep compares: :data:`SWEEP_CONTROLLERS` (``None``), or one controller's own.

    ``momentum`` is the full controller (``+ linear and angular momentum``, not its
    ablations), ``prioritized`` de Lasa's; any other controller is swept as it is.
    """
    if controller is None:
        return dict(SWEEP_CONTROLLERS)
    full = {
        "momentum": "+ linear and angular momentum",
        "prioritized": "prioritized (de Lasa 2010)",
    }
    if controller in full:
        return {full[controller]: SWEEP_CONTROLLERS[full[controller]]}
    return {controller: (controller, {})}


SWEEP_DIRECTIONS: dict[str, tuple[float, float, float]] = {
    "from behind": (1.0, 0.0, 0.0),
    "from the front": (-1.0, 0.0, 0.0),
    "from the side": (0.0, 1.0, 0.0),
}
"""Default push directions of the sweep (world axes, x forward, y left): a robot
survives a push of a given size only if it survives it from its weakest side."""
MAX_FORCE_N = 2000.0
TOLERANCE_N = 5.0
SETTLE_S = 3.0
"""Each trial runs this long past the end of its push: a robot still toppling has not survived."""
TRIAL_ATTEMPTS = 3
"""Runs of a trial that keeps missing the server's deadline before the sweep gives up."""
DEADLINE_MISSED = f"controller error {ErrorCode.DEADLINE_EXCEEDED.name}"
"""How :func:`~clients.sim.runner.run_scenario` reports a run ended by a missed deadline."""

log = logging.getLogger("poise.sim")


@dataclass
class Bisection:
    """The bisection of one (controller, direction) pair: which force to try next.

    First ``max_force_N``: survived, that is the answer. Else the interval
    ``[low, high]`` (0 survived by assumption, ``high`` fell) is halved at its
    middle until it is at most ``tolerance_N`` wide; the answer is ``low``
    (0 if even the smallest push tried fells the robot).

    Attributes:
        max_force_N: The largest push tried (N).
        tolerance_N: Width of the final interval (N).
        trials: ``(force_N, survived)`` of each trial, in order.
    """

    max_force_N: float = MAX_FORCE_N
    tolerance_N: float = TOLERANCE_N
    trials: list[tuple[float, bool]] = field(default_factory=list)

    @property
    def low_N(self) -> float:
        """Largest force survived so far (N; 0 before any)."""
        return max([0.0, *(force for force, survived in self.trials if survived)])

    @property
    def high_N(self) -> float:
        """Smallest force that felled the robot so far (N; ``max_force_N`` before any)."""
        return min([self.max_force_N, *(force for force, survived in self.trials if not survived)])

    @property
    def done(self) -> bool:
        """True once the answer is known."""
        if not self.trials:
            return False
        return self.trials[0][1] or self.high_N - self.low_N <= self.tolerance_N

    @property
    def largest_survived_N(self) -> float:
        """The answer (N): the largest push survived, once :attr:`done`."""
        return self.low_N

    @property
    def max_trials(self) -> int:
        """Most trials a bisection of this range and tolerance takes."""
        return 1 + max(0, math.ceil(math.log2(self.max_force_N / self.tolerance_N)))

    def next_force_N(self) -> float | None:
        """The force to try next (N), or ``None`` once :attr:`done`."""
        if not self.trials:
            return self.max_force_N
        return None if self.done else 0.5 * (self.low_N + self.high_N)


def trial_scenario(base: Scenario, push: PushSpec, force_N: float, settle_s: float) -> Scenario:
    """``base`` with the one push ``push`` of ``force_N`` along its direction.

    The run lasts at least ``settle_s`` past the end of the push.
    """
    norm = max(1e-12, math.sqrt(sum(c * c for c in push.force_in_world_N)))
    force = tuple(force_N * c / norm for c in push.force_in_world_N)
    return base.model_copy(
        update={
            "pushes": [push.model_copy(update={"force_in_world_N": force})],
            "duration_s": max(base.duration_s, push.start_s + push.duration_s + settle_s),
        }
    )


def push_survived(scenario: Scenario, *, endpoint: str, curve: CurveKeys | None = None) -> bool:
    """Run one trial: True if the robot did not fall (a :class:`~clients.pool.RunPool` task).

    A run that ended because the server missed its deadline (``DEADLINE_EXCEEDED``:
    the machine was busy) says nothing about the robot: it runs again, up to
    :data:`TRIAL_ATTEMPTS` times.

    Raises:
        KeyboardInterrupt: The run was interrupted (Ctrl-C, SIGTERM).
        ServerTimeout: The server stopped answering, or missed its deadline in
            every attempt: the trial has no answer.
    """
    for attempt in range(1, TRIAL_ATTEMPTS + 1):
        record = run_scenario(scenario, endpoint, curve=curve)
        if record.stopped == "interrupted":
            raise KeyboardInterrupt
        if record.stopped:
            raise ServerTimeout(f"push trial of {scenario.name}: {record.stopped}")
        if not record.fall_reason.startswith(DEADLINE_MISSED):
            return not record.fell
        log.warning(
            "push trial of %s (attempt %d of %d): %s",
            scenario.name,
            attempt,
            TRIAL_ATTEMPTS,
            record.fall_reason,
        )
    raise ServerTimeout(
        f"push trial of {scenario.name}: the server missed its deadline in {TRIAL_ATTEMPTS} "
        "attempts (DEADLINE_EXCEEDED), so the outcome would depend on the machine's load; "
        "give it a longer `poise serve --deadline` (a sweep's own server has "
        f"{BATCH_DEADLINE_S:g} s)"
    )


def sweep_push(
    base: Scenario,
    push: PushSpec,
    endpoint: str,
    max_force_N: float = MAX_FORCE_N,
    tolerance_N: float = TOLERANCE_N,
    settle_s: float = SETTLE_S,
    curve: CurveKeys | None = None,
) -> float:
    """Largest push force (N) the scenario survives, by bisection, in this process.

    The push's direction is ``push.force_in_world_N`` normalised; its body,
    point, start and duration are kept.
    """
    bisection = Bisection(max_force_N, tolerance_N)
    while (force_N := bisection.next_force_N()) is not None:
        scenario = trial_scenario(base, push, force_N, settle_s)
        bisection.trials.append((force_N, push_survived(scenario, endpoint=endpoint, curve=curve)))
    return bisection.largest_survived_N


@dataclass
class Sweep:
    """A sweep's bisections: controller label → direction name → :class:`Bisection`.

    Attributes:
        scenario: The swept scenario's name.
        push: The push (its force gives only the direction of each sweep; see
            ``directions``).
        directions: Direction name → push direction in world (x, y, z).
        bisections: Controller label → direction name → its bisection.
        bounds: Direction name → the robot's no-step bound along it (empty: not computed).
    """

    scenario: str
    push: PushSpec
    directions: dict[str, tuple[float, float, float]]
    bisections: dict[str, dict[str, Bisection]]
    bounds: dict[str, NoStepBound] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """True once every bisection is :attr:`~Bisection.done`."""
        return all(b.done for row in self.bisections.values() for b in row.values())

    def unfinished(self) -> dict[str, list[str]]:
        """Controller label → direction names of its bisections not done (only labels with any)."""
        unfinished = {
            label: [name for name, b in row.items() if not b.done]
            for label, row in self.bisections.items()
        }
        return {label: names for label, names in unfinished.items() if names}

    def largest_survived_N(self) -> dict[str, dict[str, float]]:
        """Controller label → direction name → largest force survived (N), of finished bisections.

        A bisection not :attr:`~Bisection.done` has no answer yet: its direction is left out.
        """
        return {
            label: {name: b.largest_survived_N for name, b in row.items() if b.done}
            for label, row in self.bisections.items()
        }

    def impulse_survived_N_s(self) -> dict[str, dict[str, float]]:
        """Controller label → direction name → largest impulse survived (N·s, force × duration)."""
        return {
            label: {name: force * self.push.duration_s for name, force in row.items()}
            for label, row in self.largest_survived_N().items()
        }

    def fraction_of_bound(self) -> dict[str, dict[str, float]]:
        """Controller label → direction name → impulse survived / no-step bound."""
        return {
            label: {
                name: impulse / self.bounds[name].impulse_N_s
                for name, impulse in row.items()
                if name in self.bounds and self.bounds[name].impulse_N_s > 0.0
            }
            for label, row in self.impulse_survived_N_s().items()
        }

    def table(self) -> list[str]:
        """The printed table: a header, then a row per controller done so far, in order.

        Each cell is the largest force survived (N) and, with :attr:`bounds`, the impulse
        it gives (force × duration) as a share of the no-step bound; the second header line
        gives the bound (N·s) per direction.
        """
        width = 22 if self.bounds else 16
        header = "".join(f"{name:>{width}}" for name in self.directions)
        title = "largest push survived (N, % bound)" if self.bounds else "largest push survived (N)"
        lines = [f"{title:<36}{header}{'weakest':>10}{'× first':>10}"]
        if self.bounds:
            cells = "".join(
                f"{f'{self.bounds[name].impulse_N_s:.1f} N·s':>{width}}" for name in self.directions
            )
            lines.append(f"{'no-step bound (m ω d)':<36}{cells}")
        baseline = None
        for label, row in self.bisections.items():
            if not all(b.done for b in row.values()):
                break
            forces = [b.largest_survived_N for b in row.values()]
            weakest = min(forces)
            baseline = weakest if baseline is None else baseline
            ratio = f"{weakest / baseline:.2f}×" if baseline > 0 else "-"
            cells = ""
            for name, force in zip(row, forces, strict=True):
                bound = self.bounds.get(name)
                if bound is None or bound.impulse_N_s <= 0.0:
                    cells += f"{force:>{width}.1f}"
                else:
                    share = force * self.push.duration_s / bound.impulse_N_s
                    cells += f"{f'{force:.1f} {share:4.0%}':>{width}}"
            lines.append(f"{label:<36}{cells}{weakest:>10.1f}{ratio:>10}")
        return lines

    def to_json(self) -> dict[str, Any]:
        """The sweep as JSON: the push, and per controller and direction the trials and answer.

        ``complete`` is false until every bisection is done (a sweep written as it runs, or
        stopped); the answers (``largest_survived_N`` and what follows from it) are those of
        the finished bisections, ``unfinished`` names the others, and ``trials`` has every
        trial that ran, those of an unfinished bisection too.
        """
        return {
            "scenario": self.scenario,
            "complete": self.complete,
            "unfinished": self.unfinished(),
            "push": self.push.model_dump(mode="json", exclude={"force_in_world_N"}),
            "directions": {name: list(xyz) for name, xyz in self.directions.items()},
            "largest_survived_N": self.largest_survived_N(),
            "impulse_survived_N_s": self.impulse_survived_N_s(),
            "no_step_bound": {
                name: {
                    "impulse_N_s": bound.impulse_N_s,
                    "mass_kg": bound.mass_kg,
                    "com_height_m": bound.com_height_m,
                    "omega_per_s": bound.omega_per_s,
                    "distance_m": bound.distance_m,
                }
                for name, bound in self.bounds.items()
            },
            "fraction_of_bound": self.fraction_of_bound(),
            "trials": {
                label: {
                    name: [{"force_N": f, "survived": s} for f, s in b.trials]
                    for name, b in row.items()
                }
                for label, row in self.bisections.items()
            },
        }


class _SweepTasks:
    """The pool's task source: each unfinished pair's next trial, the table as rows complete.

    ``bisection_done`` is called after each bisection finishes (its row printed, if complete).
    """

    def __init__(
        self,
        sweep: Sweep,
        bases: dict[str, Scenario],
        settle_s: float,
        bar: ProgressBar,
        bisection_done: Callable[[], object] | None = None,
    ):
        self.sweep = sweep
        self.bases = bases
        self.settle_s = settle_s
        self.bar = bar
        self.bisection_done = bisection_done
        self.waiting = [(label, name) for label in sweep.bisections for name in sweep.directions]
        header = sweep.table()  # no row is done yet
        for line in header:
            self.bar.print(line)
        self.printed = len(header)

    def next_task(self) -> Task | None:
        if not self.waiting:
            return None
        label, name = key = self.waiting.pop(0)
        force_N = self.sweep.bisections[label][name].next_force_N()
        assert force_N is not None  # a pair waits only while unfinished
        push = self.sweep.push.model_copy(update={"force_in_world_N": self.sweep.directions[name]})
        scenario = trial_scenario(self.bases[label], push, force_N, self.settle_s)
        return Task(key, push_survived, (scenario,), {})

    def finished(self, task: Task, result: Any) -> None:
        label, name = task.key
        bisection = self.sweep.bisections[label][name]
        bisection.trials.append((bisection.next_force_N(), bool(result)))  # type: ignore[arg-type]
        if not bisection.done:  # first in line: a worker sees its pair through, rows end in order
            self.waiting.insert(0, task.key)
        for line in self.sweep.table()[self.printed :]:
            self.bar.print(line)
            self.printed += 1
        if bisection.done and self.bisection_done is not None:
            self.bisection_done()
        self._progress()

    def _progress(self) -> None:
        pairs = [b for row in self.sweep.bisections.values() for b in row.values()]
        done = sum(len(b.trials) for b in pairs)
        most = sum(len(b.trials) if b.done else b.max_trials for b in pairs)
        self.bar(done / most, f"{done}/≤{most} trials")


def sweep_bases(
    scenario_name: str,
    overrides: Mapping[str, Any] | None = None,
    controllers: Mapping[str, tuple[str, dict[str, Any]]] = SWEEP_CONTROLLERS,
) -> dict[str, Scenario]:
    """The scenario each controller is swept on, its own pushes removed.

    Its parameters and parameter changes are kept only for its own controller
    (they are written for it).
    """
    own_controller = load_scenario(scenario_name).controller
    bases = {}
    for label, (controller, params) in controllers.items():
        base = load_scenario(scenario_name, **{**(overrides or {}), "controller": controller})
        own = controller == own_controller
        bases[label] = base.model_copy(
            update={
                "params": {**(base.params if own else {}), **params},
                "param_changes": base.param_changes if own else [],
                "pushes": [],
            }
        )
    return bases


def sweep_controllers(
    scenario_name: str,
    push: PushSpec,
    directions: dict[str, tuple[float, float, float]],
    pool: RunPool,
    overrides: Mapping[str, Any] | None = None,
    *,
    output_dir: Path | None = None,
    controllers: Mapping[str, tuple[str, dict[str, Any]]] = SWEEP_CONTROLLERS,
    max_force_N: float = MAX_FORCE_N,
    tolerance_N: float = TOLERANCE_N,
    settle_s: float = SETTLE_S,
    progress: bool = True,
) -> Sweep:
    """Bisect each controller's largest push per direction on ``pool``; print a table.

    Each row is printed once its controller's directions are done. With
    ``output_dir``, writes ``sweep_<scenario>.json`` (every trial) and
    ``sweep_<scenario>.png`` (survived/fell over direction × force, a polar
    plot per controller, :func:`~clients.sim.sweep_plot.plot_sweep`) after
    every finished bisection and once more at the end, also when the sweep
    stops early (Ctrl-C, SIGTERM, a failed trial: the exception propagates
    once they are written), so a stopped sweep keeps what ran, with
    ``"complete": false`` (:func:`~.sweep_files.write_sweep`).

    The push's body is the robot's (``chest`` on a robot without one: its trunk,
    :func:`~clients.physics.robot_terms.resolve_body`), checked before the first trial.

    Raises:
        ScenarioError: The scenario cannot run, or the robot has no such push body.
    """
    bases = sweep_bases(scenario_name, overrides, controllers)
    first = bases[next(iter(bases))]
    push = push.model_copy(update={"body": _push_body(first, push.body)})
    sweep = Sweep(
        scenario=first.name,
        push=push,
        directions=dict(directions),
        bisections={
            label: {name: Bisection(max_force_N, tolerance_N) for name in directions}
            for label in controllers
        },
        bounds=sweep_bounds(first, directions),
    )
    save = None
    if output_dir is not None:
        from clients.sim.sweep_plot import pyplot

        pyplot()  # now, not halfway through when a Ctrl-C comes
        save = functools.partial(write_sweep, sweep, output_dir)
    try:
        with ProgressBar(f"sweep {sweep.scenario}", enabled=progress) as bar:
            pool.run(_SweepTasks(sweep, bases, settle_s, bar, save))
    finally:  # however the sweep ends, what ran is kept (a KeyboardInterrupt still propagates)
        if output_dir is not None:
            json_path, png_path = sweep_paths(sweep, output_dir)
            stopped = ""
            if not sweep.complete:  # complete: written as its last bisection finished
                write_sweep(sweep, output_dir)
                pairs = [b for row in sweep.bisections.values() for b in row.values()]
                finished = sum(b.done for b in pairs)
                stopped = f" (stopped: {finished} of {len(pairs)} bisections finished)"
            print(f"sweep{stopped}: {json_path}; picture: {png_path}", flush=True)
    return sweep


def _push_body(scenario: Scenario, body: str) -> str:
    """The robot's body a sweep's push acts on; refused in one line if it has none such."""
    description = describe_model(
        scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
    )
    resolved = resolve_body(description, body)
    if resolved is None:
        bodies = [b.name for b in description.bodies]
        raise ScenarioError(
            f"--push-body: {scenario.model} has no body {body!r}; give one of "
            f"{', '.join(bodies)} (or `trunk`, `root`)"
        )
    return resolved


def sweep_bounds(
    scenario: Scenario, directions: Mapping[str, tuple[float, float, float]]
) -> dict[str, NoStepBound]:
    """The robot's no-step bound per direction, at the scenario's starting pose.

    A direction without a bound (straight up or down, or a CM outside the soles) has none.
    """
    description = describe_model(
        scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
    )
    q = initial_configuration(scenario)
    bounds = {}
    for name, direction in directions.items():
        try:
            bounds[name] = no_step_bound(description, direction, q)
        except RobotTermsError:
            continue
    return bounds
