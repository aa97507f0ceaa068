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
and safe-state latches; then what the view costs the loop's thread directly
(each observer call timed: median, 99th percentile, longest) and the CPU the
view's child process used (% of one core over the run). On a machine shared
with other work the loop's metrics move with the load (printed); the
observer's time does not.

Usage: python bench/bridge_view.py [--map examples/bridge/revolute_humanoid_mit.toml]
       [--seconds 10] [--rate-hz HZ] [--watchdog-s S] [--rounds 2]
       [--modes none,process,inline]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import os
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np

from clients.bridge.app import open_bridge
from clients.bridge.config import load_bridge_config
from clients.bridge.loop import BridgeStartError
from clients.server_process import ServerProcess

ROOT = Path(__file__).resolve().parents[1]


def observer_of(
    mode: str, stack: ExitStack, call_s: list[float]
) -> tuple[Callable[[Any], None] | None, int | None]:
    """The mode's observer, timed into ``call_s``, and the pid of the view's child process."""
    if mode == "none":
        return None, None
    child = None
    if mode == "process":
        from clients.visual.live_process import LiveViewProcess

        view: Any = LiveViewProcess(port=8390)
        child = view._process.pid
    else:
        from clients.visual.live import LiveView

        view = LiveView(port=8390)
    stack.callback(view.close)

    return timed(view.observe, call_s), child


def timed(call: Callable[..., Any], seconds: list[float]) -> Callable[..., Any]:
    """``call``, each call's duration appended to ``seconds``."""

    def timed_call(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        result = call(*args, **kwargs)
        seconds.append(time.perf_counter() - start)
        return result

    return timed_call


def cpu_s(pid: int) -> float:
    """CPU time (user + system) a process used so far (s), from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default=str(ROOT / "examples/bridge/revolute_humanoid_mit.toml"))
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate-hz", type=float, default=None, help="default: the map's")
    parser.add_argument(
        "--watchdog-s",
        type=float,
        default=None,
        help="default: the map's; longer keeps a starved server from latching the safe state "
        "(then no command comes and nothing is drawn)",
    )
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--modes", default="none,process,inline")
    args = parser.parse_args()
    config = load_bridge_config(args.map)
    changes = {"rate_hz": args.rate_hz, "watchdog_s": args.watchdog_s}
    bridge = config.bridge.model_copy(update={k: v for k, v in changes.items() if v is not None})
    config = config.model_copy(update={"bridge": bridge})
    modes = args.modes.split(",")
    print(
        f"{Path(args.map).name}: {args.seconds:g} s on the wall clock at "
        f"{config.bridge.rate_hz:g} Hz, watchdog {config.bridge.watchdog_s:g} s, "
        f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
    )
    with ServerProcess() as server:
        for round_ in range(args.rounds):
            for mode in modes:
                call_s: list[float] = []
                add_s: list[float] = []
                with ExitStack() as stack:
                    observer, child = observer_of(mode, stack, call_s)
                    with open_bridge(
                        config, server.endpoint, emulate=True, wall_clock=True, observer=observer
                    ) as session:
                        track = session.bridge.track
                        if track is not None:  # the loop's own part of the view: its track
                            track.add = timed(track.add, add_s)  # type: ignore[method-assign]
                        child_cpu_s = cpu_s(child) if child else 0.0
                        start = time.monotonic()
                        try:
                            report = session.bridge.run(args.seconds)
                        except BridgeStartError as exc:  # an emulator starved at start-up
                            print(f"round {round_ + 1} {mode:<8} did not start: {exc}")
                            continue
                        wall_s = time.monotonic() - start
                        child_cpu_s = cpu_s(child) - child_cpu_s if child else 0.0
                timing = report.timing
                print(
                    f"round {round_ + 1} {mode:<8} {timing.ticks:6d} ticks, period "
                    f"{1e3 * timing.period_mean_s:6.3f} ms ± {1e3 * timing.jitter_s:6.3f}, "
                    f"max {1e3 * timing.period_max_s:7.2f}, work max "
                    f"{1e3 * timing.work_max_s:7.2f} ms, {timing.overruns:5d} overruns, "
                    f"{len(report.latches)} latches, load {os.getloadavg()[0]:.1f}",
                    flush=True,
                )
                if call_s:
                    calls = 1e6 * (np.array(call_s) + np.array(add_s[: len(call_s)]))
                    print(
                        f"        the view's part of a tick (Track.add + observer): median "
                        f"{np.median(calls):.1f} µs, p99 {np.percentile(calls, 99):.1f} µs, "
                        f"max {calls.max():.0f} µs"
                        + (
                            f"; view process {100 * child_cpu_s / wall_s:.0f}% of a core"
                            if child
                            else ""
                        ),
                        flush=True,
                    )


if __name__ == "__main__":
    main()
