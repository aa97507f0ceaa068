"""``poise demo``: the thesis humanoid balancing under pushes, served over ZeroMQ.

The README's main job. Starts ``poise serve`` on a free loopback port (or
uses ``--connect``), runs the thesis' push scenarios (Macchietto 2008,
ch. 7.1: a sequence of 150 N × 100 ms pushes across the upper body, then one
220 N × 100 ms push to the head) in the reference simulator with the full
momentum controller, writes ``report.json`` and one PNG per scenario, and
prints a summary table.
"""

from __future__ import annotations

from pathlib import Path

from clients.client import CurveKeys
from clients.sim.app import run_scenarios
from clients.track import RunObserver

__all__ = ["DEMO_SCENARIOS", "run_demo"]

DEMO_SCENARIOS = ("push_sequence", "head_push")
"""The thesis' impact tests (ch. 7.1), in the order the demo runs them."""


def run_demo(
    output_dir: Path,
    endpoint: str | None = None,
    backend: str = "reference",
    controller: str = "momentum",
    curve: CurveKeys | None = None,
    record_dir: Path | None = None,
    series: bool = False,
    video: bool = False,
    observer: RunObserver | None = None,
) -> int:
    """Run the push scenarios; exit code 0 if the robot stayed up in all of them, else 1."""
    if endpoint is None:
        print("starting `poise serve` on a free loopback port …", flush=True)
    reports = run_scenarios(
        DEMO_SCENARIOS,
        output_dir,
        endpoint,
        overrides={"backend": backend, "controller": controller},
        curve=curve,
        record_dir=record_dir,
        series=series,
        video=video,
        observer=observer,
    )
    return 1 if any(r["fell"] or not r["complete"] for r in reports) else 0
