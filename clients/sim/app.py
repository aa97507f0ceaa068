"""``poise sim``: run scenarios against a server, write reports and plots (sweeps: .sweep)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from clients.client import CurveKeys
from clients.pool import RunPool, Task
from clients.progress import ProgressBar
from clients.server_process import ServerProcess
from clients.sim.metrics import compute_metrics, start_pose_note
from clients.sim.output import OutputDirectory
from clients.sim.plots import plot_run, plot_walk_paths
from clients.sim.runner import RunRecord, run_scenario, track_of_run
from clients.sim.scenario import Scenario, load_scenario
from clients.sim.series import save_series
from clients.track import RunObserver
from clients.visual.gl import choose_headless_gl
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
    """Run each scenario, write ``<name>.png`` and ``report.json``, print a summary.

    The summary is a table per kind of scenario (balance, walk, jump: each its own
    columns), the scenarios' warnings (a push after the end, fewer than two contacts:
    :func:`~clients.sim.scenario.scenario_warnings`), and a last line saying where
    the report and the plots went.

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
    _print_written(output_dir, reports)
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


_Column = tuple[str, int, Callable[[dict[str, Any]], str]]
"""A summary column: header, width and the text of a report's cell."""

_COLUMNS: dict[str, list[_Column]] = {
    "balance": [
        ("CM exc. m", 10, lambda r: f"{r['com_excursion_m']:.3f}"),
        ("COP in", 8, lambda r: f"{r['cop_strictly_inside_fraction']:.0%}"),
        ("slip mm", 9, lambda r: f"{r['foot_slip_m'] * 1e3:.1f}"),
    ],
    "walk": [
        ("distance m", 12, lambda r: f"{r['walking']['distance_m']:.2f}"),
        ("speed m/s", 11, lambda r: f"{r['walking']['speed_m_per_s']:.2f}"),
        ("steps", 7, lambda r: f"{r['walking']['step_count']}"),
        ("slip mm", 9, lambda r: f"{r['walking']['foot_slip_m'] * 1e3:.1f}"),
    ],
    "jump": [
        ("clearance m", 13, lambda r: f"{r['jump']['clearance_m']:.3f}"),
        ("flight s", 10, lambda r: f"{r['jump']['flight_s']:.2f}"),
        ("turn °", 8, lambda r: f"{round(r['jump']['turn_deg'])}"),  # never "-0"
    ],
}
"""Per kind of scenario (``report["kind"]``), the columns between the result and the RTF."""


def _result(report: dict[str, Any]) -> str:
    """A run's outcome in a few words, in its kind's terms."""
    if report["fell"]:
        return f"fell {report['fall_time_s']:.2f} s"
    if not report["complete"]:
        return f"stopped {report['simulated_s']:.2f} s"
    if report["kind"] == "walk" and "walking" in report:
        return "walked" if report["walking"]["step_count"] else "no steps"
    if report["kind"] == "jump" and "jump" in report:
        if not report["jump"]["flight_s"]:
            return "no flight"
        return "landed" if report["jump"]["landed"] else "not landed"
    return "stayed up"


def _print_table(reports: list[dict[str, Any]]) -> None:
    """One table per kind of scenario (balance, walk, jump), each with its own columns.

    Balance: the largest horizontal CM excursion, the fraction of ticks with the COP
    strictly inside the support polygon, the largest slide of a supporting sole; walk:
    the distance, the speed from the first lift-off, the steps and the slide; jump: the
    soles' clearance, the longest flight and the feet's turn. The model's notes come
    before, the scenarios' warnings after.
    """
    notes: dict[str, list[str]] = {}  # a note, and the scenarios it is about, in run order
    for r in reports:
        for note in [*r.get("model_notes", []), start_pose_note(r)]:
            if note and r["scenario"] not in notes.setdefault(note, []):
                notes[note].append(r["scenario"])
    for note, scenarios in notes.items():
        print(f"note ({', '.join(scenarios)}): {note}")
    width = max([24, *(len(r["scenario"]) + 2 for r in reports)])
    kinds = list(dict.fromkeys(r["kind"] for r in reports))
    for index, kind in enumerate(kinds):
        columns = [*_COLUMNS[kind], ("RTF", 7, lambda r: f"{r['real_time_factor']:.2f}")]
        if index:
            print()
        print(
            f"{'scenario':<{width}}{'backend':<10}{'result':<16}"
            + "".join(f"{header:>{size}}" for header, size, _ in columns)
        )
        for r in reports:
            if r["kind"] != kind:
                continue
            row = f"{r['scenario']:<{width}}{r['backend']:<10}{_result(r):<16}"
            if "com_excursion_m" in r:  # else stopped before its first tick
                row += "".join(f"{cell(r):>{size}}" for _, size, cell in columns)
            print(row.rstrip())
    for r in reports:
        for warning in r.get("warnings", []):
            print(f"warning ({r['scenario']}): {warning}")


def _print_written(output_dir: Path, reports: list[dict[str, Any]]) -> None:
    """Where the run wrote: the report, then the plots (as ``poise demo`` says it)."""
    plots = [
        path
        for r in reports
        for path in (r.get("plot"), r.get("walking", {}).get("plot"))
        if path is not None
    ]
    print(
        f"report: {output_dir / 'report.json'}" + (f"; plots: {', '.join(plots)}" if plots else "")
    )
    for key, label in (("series", "series"), ("video", "videos")):
        paths = [r[key] for r in reports if key in r]
        if paths:
            print(f"{label}: {', '.join(paths)}")
