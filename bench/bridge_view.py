"""What ``poise bridge --view`` costs the bridge's loop: its own timing, with and without a view.

The emulated robot of an example map (every actuator emulated in this
process) runs against a real server for ``--seconds`` on the wall clock
(``RealTimePacer`` at the map's rate, or ``--rate-hz``; the emulated robot
stands still), once per mode, the modes alternating ``--rounds`` times so
that all see the same machine load:

- **none**: no view;
- **process**: the view of ``--view`` (:class:`~clients.visual.live_process.LiveViewProcess`:
  the loop keeps a tick in a deque, a child process draws);
- **inline**: a :class:`~clients.visual.live.LiveView` called from the loop
  itself, as ``poise sim --view`` does (drawing at most 30 times a second).

No browser is attached (viser still builds every update). Prints, per
mode, the loop's own metrics (``BridgeReport``): ticks, mean period and its
standard deviation, the longest period, the longest tick's work, overruns,
and safe-state latches.

Usage: python bench/bridge_view.py [--map examples/bridge/revolute_humanoid_mit.toml]
       [--seconds 10] [--rate-hz HZ] [--rounds 2] [--modes none,process,inline]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import os
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from clients.bridge.app import open_bridge
from clients.bridge.config import load_bridge_config
from clients.server_process import ServerProcess

ROOT = Path(__file__).resolve().parents[1]


def observer_of(mode: str, stack: ExitStack) -> Callable[[Any], None] | None:
    if mode == "none":
        return None
    if mode == "process":
        from clients.visual.live_process import LiveViewProcess

        view: Any = LiveViewProcess(port=8390)
    else:
        from clients.visual.live import LiveView

        view = LiveView(port=8390)
    stack.callback(view.close)
    return view.observe


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default=str(ROOT / "examples/bridge/revolute_humanoid_mit.toml"))
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate-hz", type=float, default=None, help="default: the map's")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--modes", default="none,process,inline")
    args = parser.parse_args()
    config = load_bridge_config(args.map)
    if args.rate_hz is not None:
        bridge = config.bridge.model_copy(update={"rate_hz": args.rate_hz})
        config = config.model_copy(update={"bridge": bridge})
    modes = args.modes.split(",")
    print(
        f"{Path(args.map).name}: {args.seconds:g} s on the wall clock at "
        f"{config.bridge.rate_hz:g} Hz, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
    )
    with ServerProcess() as server:
        for round_ in range(args.rounds):
            for mode in modes:
                with ExitStack() as stack:
                    observer = observer_of(mode, stack)
                    with open_bridge(
                        config, server.endpoint, emulate=True, wall_clock=True, observer=observer
                    ) as session:
                        report = session.bridge.run(args.seconds)
                timing = report.timing
                print(
                    f"round {round_ + 1} {mode:<8} {timing.ticks:6d} ticks, period "
                    f"{1e3 * timing.period_mean_s:6.3f} ms ± {1e3 * timing.jitter_s:6.3f}, "
                    f"max {1e3 * timing.period_max_s:7.2f}, work max "
                    f"{1e3 * timing.work_max_s:7.2f} ms, {timing.overruns:5d} overruns, "
                    f"{len(report.latches)} latches, load {os.getloadavg()[0]:.1f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
