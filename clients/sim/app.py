"""``poise sim``: run scenarios or a push sweep against a server, write reports and plots."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from clients.client import CurveKeys
from clients.progress import ProgressBar
from clients.server_process import ServerProcess
from clients.sim.metrics import compute_metrics
from clients.sim.output import OutputDirectory
from clients.sim.plots import plot_run, plot_walk_paths
from clients.sim.runner import run_scenario
from clients.sim.scenario import PushSpec, Scenario, load_scenario
from clients.sim.series import save_series
from clients.track import RunObserver
from clients.visual.gl import choose_headless_gl
from clients.visual.track import track_of_run
from clients.visual.video import write_video

__all__ = [
    "ABLATIONS",
    "SWEEP_CONTROLLERS",
    "SWEEP_DIRECTIONS",
    "run_scenarios",
    "server_endpoint",
    "sweep_controllers",
    "sweep_push",
]

ANGULAR_OFF: dict[str, Any] = {"angular_momentum_gain": 0.0, "weight_angular_momentum": 0.0}
ABLATIONS: dict[str, dict[str, Any]] = {
    "tracking only": {"weight_linear_momentum": 0.0, **ANGULAR_OFF},
    "+ linear momentum": ANGULAR_OFF,
    "+ linear and angular momentum": {},
}
"""Thesis ch. 7.1 ablations of the momentum controller, as parameter overrides."""
SWEEP_CONTROLLERS: dict[str, tuple[str, dict[str, Any]]] = {
    **{label: ("momentum", params) for label, params in ABLATIONS.items()},
    "prioritized (de Lasa 2010)": ("prioritized", {}),
}
"""What ``poise sim --sweep-push`` compares: label → (controller, parameter overrides)."""
SWEEP_DIRECTIONS: dict[str, tuple[float, float, float]] = {
    "from behind": (1.0, 0.0, 0.0),
    "from the front": (-1.0, 0.0, 0.0),
    "from the side": (0.0, 1.0, 0.0),
}
"""Default push directions of the sweep (world axes, x forward, y left): a robot
survives a push of a given size only if it survives it from its weakest side."""


@contextlib.contextmanager
def server_endpoint(endpoint: str | None) -> Iterator[str]:
    """Yield ``endpoint``, or start a `poise serve` process and yield its endpoint."""
    if endpoint is not None:
        yield endpoint
        return
    with ServerProcess() as process:
        yield process.endpoint


def run_scenarios(
    names: Sequence[str],
    output_dir: Path,
    endpoint: str | None = None,
    overrides: dict[str, Any] | None = None,
    progress: bool = True,
    curve: CurveKeys | None = None,
    record_dir: Path | None = None,
    series: bool = False,
    video: bool = False,
    observer: RunObserver | None = None,
) -> list[dict[str, Any]]:
    """Run each scenario, write ``<name>.png`` and ``report.json``, print a summary table.

    ``report.json`` is rewritten after every scenario, so a run killed half-way
    leaves the report of what ran; a scenario stopped early (Ctrl-C, SIGTERM, a
    server that stopped answering) is reported with ``complete: false`` and
    why, then Ctrl-C or SIGTERM stops the run (``KeyboardInterrupt``).
    With ``record_dir``, each scenario's conversation with the server is
    recorded to ``record_dir/<name>.mcap`` (``poise replay`` replays it); with
    ``series``, its raw time series go to ``<name>.npz`` (:mod:`clients.sim.series`);
    with ``video``, it is rendered to ``<name>.mp4`` (:mod:`clients.visual.video`);
    ``observer`` sees the run's track after every tick (the live view, :mod:`clients.visual.live`).

    Raises:
        ScenarioError: A scenario cannot run (checked for all before the first runs).
        OutputBusy: Another run writes to ``output_dir``.
        RenderingUnavailable: ``video`` on a machine where MuJoCo cannot render
            offscreen (checked before anything runs).
    """
    # Every scenario is checked before a server starts or a file is written.
    scenarios = [load_scenario(name, **(overrides or {})) for name in names]
    if video:
        choose_headless_gl()
    reports: list[dict[str, Any]] = []
    with OutputDirectory(output_dir) as output, server_endpoint(endpoint) as address:
        for scenario in scenarios:
            log_path = None
            if record_dir is not None:
                record_dir.mkdir(parents=True, exist_ok=True)
                log_path = record_dir / f"{scenario.name}.mcap"
            with ProgressBar(scenario.name, enabled=progress) as bar:
                record = run_scenario(
                    scenario,
                    address,
                    progress=bar,
                    curve=curve,
                    log_path=log_path,
                    observer=observer,
                )
            metrics = compute_metrics(record)
            if record.commands:
                metrics["plot"] = str(output_dir / f"{scenario.name}.png")
                plot_run(record, Path(metrics["plot"]))
                if "walking" in metrics:
                    metrics["walking"]["plot"] = str(output_dir / f"{scenario.name}_paths.png")
                    plot_walk_paths(record, Path(metrics["walking"]["plot"]))
                if series:
                    metrics["series"] = str(
                        save_series(record, output_dir / f"{scenario.name}.npz")
                    )
                if video:
                    metrics["video"] = str(output_dir / f"{scenario.name}.mp4")
                    with ProgressBar(f"{scenario.name} video", enabled=progress) as bar:
                        write_video(track_of_run(record), metrics["video"], progress=bar)
            reports.append(metrics)
            output.write_report(reports)
            if record.stopped == "interrupted":
                _print_table(reports)
                raise KeyboardInterrupt
    _print_table(reports)
    return reports


def _print_table(reports: list[dict[str, Any]]) -> None:
    notes = {(r["scenario"], note) for r in reports for note in r.get("model_notes", [])}
    for scenario, note in sorted(notes):
        print(f"note ({scenario}): {note}")
    width = max([24, *(len(r["scenario"]) + 2 for r in reports)])
    print(
        f"{'scenario':<{width}}{'backend':<10}{'result':<16}{'CM exc. m':>10}{'COP in':>8}"
        f"{'slip mm':>9}{'RTF':>7}"
    )
    for r in reports:
        if r["fell"]:
            result = f"fell {r['fall_time_s']:.2f} s"
        elif not r["complete"]:
            result = f"stopped {r['simulated_s']:.2f} s"
        else:
            result = "stayed up"
        if "com_excursion_m" not in r:  # stopped before its first tick
            print(f"{r['scenario']:<{width}}{r['backend']:<10}{result:<16}")
            continue
        print(
            f"{r['scenario']:<{width}}{r['backend']:<10}{result:<16}{r['com_excursion_m']:>10.3f}"
            f"{r['cop_strictly_inside_fraction']:>8.0%}{r['foot_slip_m'] * 1e3:>9.1f}"
            f"{r['real_time_factor']:>7.2f}"
        )


def sweep_push(
    base: Scenario,
    push: PushSpec,
    endpoint: str,
    max_force_N: float = 2000.0,
    tolerance_N: float = 5.0,
    settle_s: float = 3.0,
    curve: CurveKeys | None = None,
) -> float:
    """Largest push force (N) the scenario survives, by bisection (thesis ch. 7.1).

    The push's direction is ``push.force_in_world_N`` normalised; its body,
    point, start and duration are kept. Each trial runs at least ``settle_s``
    past the end of the push: a robot still toppling when the scenario's own
    duration ends has not survived. Returns 0 if even the smallest push fells it.
    """
    duration_s = max(base.duration_s, push.start_s + push.duration_s + settle_s)
    direction = [
        c / max(1e-12, sum(x * x for x in push.force_in_world_N) ** 0.5)
        for c in push.force_in_world_N
    ]

    def survives(force_N: float) -> bool:
        spec = push.model_copy(update={"force_in_world_N": tuple(force_N * d for d in direction)})
        scenario = base.model_copy(update={"pushes": [spec], "duration_s": duration_s})
        return not run_scenario(scenario, endpoint, curve=curve).fell

    low, high = 0.0, max_force_N
    if survives(high):
        return high
    while high - low > tolerance_N:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if survives(middle) else (low, middle)
    return low


def sweep_controllers(
    scenario_name: str,
    push: PushSpec,
    directions: dict[str, tuple[float, float, float]],
    endpoint: str,
    overrides: dict[str, Any] | None = None,
    curve: CurveKeys | None = None,
) -> dict[str, dict[str, float]]:
    """:func:`sweep_push` for each of ``SWEEP_CONTROLLERS`` and each direction; prints a table.

    The scenario's own pushes are removed; its parameters and parameter
    changes are kept only for its own controller (they are written for it).
    Returns label → direction → largest force survived (N).
    """
    own_controller = load_scenario(scenario_name).controller
    header = "".join(f"{name:>16}" for name in directions)
    print(f"{'largest push survived (N)':<32}{header}{'weakest':>10}{'× tracking':>12}")
    results: dict[str, dict[str, float]] = {}
    for label, (controller, params) in SWEEP_CONTROLLERS.items():
        base = load_scenario(scenario_name, **{**(overrides or {}), "controller": controller})
        own = controller == own_controller
        base = base.model_copy(
            update={
                "params": {**(base.params if own else {}), **params},
                "param_changes": base.param_changes if own else [],
                "pushes": [],
            }
        )
        results[label] = {
            name: sweep_push(
                base, push.model_copy(update={"force_in_world_N": xyz}), endpoint, curve=curve
            )
            for name, xyz in directions.items()
        }
        weakest = min(results[label].values())
        baseline = min(next(iter(results.values())).values())
        ratio = f"{weakest / baseline:.2f}×" if baseline > 0 else "-"
        cells = "".join(f"{force:>16.1f}" for force in results[label].values())
        print(f"{label:<32}{cells}{weakest:>10.1f}{ratio:>12}", flush=True)
    return results
