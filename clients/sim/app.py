"""``poise sim``: run scenarios against a server, write reports and plots (sweeps: .sweep)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from clients.client import CurveKeys
from clients.pool import RunPool, Task
from clients.progress import ProgressBar
from clients.server_process import ServerProcess
from clients.sim.metrics import compute_metrics
from clients.sim.output import OutputDirectory
from clients.sim.plots import plot_run, plot_walk_paths
from clients.sim.runner import RunRecord, run_scenario
from clients.sim.scenario import Scenario, load_scenario
from clients.sim.series import save_series
from clients.track import RunObserver
from clients.visual.gl import choose_headless_gl
from clients.visual.track import track_of_run
from clients.visual.video import write_video

__all__ = ["run_scenarios", "server_endpoint"]


@contextlib.contextmanager
def server_endpoint(endpoint: str | None, deadline_s: float | None = None) -> Iterator[str]:
    """Yield ``endpoint``, or start a `poise serve` process and yield its endpoint.

    Args:
        endpoint: A running server's, or ``None`` to start one on loopback.
        deadline_s: The started server's ``--deadline`` (default ``poise serve``'s).
    """
    if endpoint is not None:
        yield endpoint
        return
    extra_args = [] if deadline_s is None else ["--deadline", f"{deadline_s:g}"]
    with ServerProcess(extra_args=extra_args) as process:
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
    workers: int = 1,
    dask: str | None = None,
) -> list[dict[str, Any]]:
    """Run each scenario, write ``<name>.png`` and ``report.json``, print a summary table.

    The scenarios run on a :class:`~clients.pool.RunPool` of ``workers``
    local processes (no more than there are scenarios), or on the Dask
    cluster at ``dask``; the report, plots
    and table are made here, in the order of ``names`` whatever the order the
    runs finish in. ``report.json`` is rewritten after every scenario, so a run
    killed half-way leaves the report of what ran; in this process
    (``workers=1``) a scenario stopped early (Ctrl-C, SIGTERM, a server that
    stopped answering) is reported with ``complete: false`` and why, then
    Ctrl-C or SIGTERM stops the run (``KeyboardInterrupt``); with workers, the
    scenarios still running are abandoned.
    With ``record_dir``, each scenario's conversation with the server is
    recorded to ``record_dir/<name>.mcap`` (``poise replay`` replays it; on
    Dask, on the worker's file system); with ``series``, its raw time series
    go to ``<name>.npz`` (:mod:`clients.sim.series`); with ``video``, it is
    rendered to ``<name>.mp4`` (:mod:`clients.visual.video`, here);
    ``observer`` sees the run's track after every tick (the live view,
    :mod:`clients.visual.live`): it needs the runs in this process (``workers=1``).

    Raises:
        ScenarioError: A scenario cannot run (checked for all before the first runs).
        OutputBusy: Another run writes to ``output_dir``.
        ClusterUnavailable: ``dask`` answers no scheduler.
        RenderingUnavailable: ``video`` on a machine where MuJoCo cannot render
            offscreen (checked before anything runs).
        ValueError: An ``observer`` with more than one worker or with ``dask``.
    """
    if observer is not None and (workers > 1 or dask is not None):
        raise ValueError("an observer sees the runs of this process: workers=1, no dask")
    # Every scenario is checked before a server starts or a file is written.
    scenarios = [load_scenario(name, **(overrides or {})) for name in names]
    if video:
        choose_headless_gl()
    label = scenarios[0].name if len(scenarios) == 1 else "scenarios"
    tasks: _ScenarioTasks | None = None
    with OutputDirectory(output_dir) as output:
        try:  # the pool sees the interrupt: it abandons what still runs
            with (
                RunPool(min(workers, len(scenarios)), dask, endpoint, curve) as pool,
                ProgressBar(label, enabled=progress) as bar,
            ):
                tasks = _ScenarioTasks(scenarios, output, pool, bar, record_dir, series, video)
                tasks.observer = observer
                pool.run(tasks)
        except KeyboardInterrupt:
            if tasks is None:
                raise
            tasks.interrupted = True
    reports = tasks.reports()
    _print_table(reports)
    if tasks.interrupted:
        raise KeyboardInterrupt
    return reports


class _ScenarioTasks:
    """The pool's task source of :func:`run_scenarios`: each scenario once, in order."""

    def __init__(
        self,
        scenarios: list[Scenario],
        output: OutputDirectory,
        pool: RunPool,
        bar: ProgressBar,
        record_dir: Path | None,
        series: bool,
        video: bool,
    ):
        self.scenarios = scenarios
        self.output = output
        self.pool = pool
        self.bar = bar
        self.record_dir = record_dir
        self.series = series
        self.video = video
        self.observer: RunObserver | None = None
        self.started = 0
        self.done: dict[int, dict[str, Any]] = {}
        self.interrupted = False

    def reports(self) -> list[dict[str, Any]]:
        """The reports of the scenarios done, in the order given."""
        return [self.done[index] for index in sorted(self.done)]

    def next_task(self) -> Task | None:
        if self.started == len(self.scenarios) or self.interrupted:
            return None
        index = self.started
        scenario = self.scenarios[index]
        self.started += 1
        kwargs: dict[str, Any] = {}
        if self.record_dir is not None:
            self.record_dir.mkdir(parents=True, exist_ok=True)
            kwargs["log_path"] = self.record_dir / f"{scenario.name}.mcap"
        count = len(self.scenarios)
        if self.pool.in_process:  # a bar that moves with the ticks
            detail = f"{index + 1}/{count} {scenario.name}" if count > 1 else ""
            kwargs["progress"] = lambda fraction: self.bar((index + fraction) / count, detail)
            kwargs["observer"] = self.observer
        else:
            self.bar(len(self.done) / count, f"{len(self.done)}/{count} done")
        return Task(index, run_scenario, (scenario,), kwargs)

    def finished(self, task: Task, record: RunRecord) -> None:
        name = record.scenario.name
        output_dir = self.output.path
        metrics = compute_metrics(record)
        if record.commands:
            metrics["plot"] = str(output_dir / f"{name}.png")
            plot_run(record, Path(metrics["plot"]))
            if "walking" in metrics:
                metrics["walking"]["plot"] = str(output_dir / f"{name}_paths.png")
                plot_walk_paths(record, Path(metrics["walking"]["plot"]))
            if self.series:
                metrics["series"] = str(save_series(record, output_dir / f"{name}.npz"))
            if self.video:
                metrics["video"] = str(output_dir / f"{name}.mp4")
                with ProgressBar(f"{name} video", enabled=self.bar.enabled) as bar:
                    write_video(track_of_run(record), metrics["video"], progress=bar)
        self.done[task.key] = metrics
        self.output.write_report(self.reports())
        if record.stopped == "interrupted":
            self.interrupted = True
        if not self.pool.in_process:
            count = len(self.scenarios)
            self.bar(len(self.done) / count, f"{len(self.done)}/{count} done")


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
