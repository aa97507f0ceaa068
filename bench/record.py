"""Recording overhead on the 1 kHz control loop, against the same loop unrecorded, in one run.

Two comparisons, each of two identical loops stepping the thesis humanoid
standing (same states) at 1 kHz on loopback:

- client side: a `ControllerClient(record=...)` and one without, same server;
- server side: a `poise serve --record DIR` and a `poise serve`, same client code.

The loops alternate in blocks (A B A B ...) so drift of a busy machine hits
both alike. Reported per loop: mean and p99 of the time of one tick (send the
state, get the command, hand both to the recorder), the ratio recorded /
unrecorded, messages dropped by the recorder, and the log's size.
Target: mean ratio ≤ 1.05.

Usage: python bench/record.py [--blocks 10] [--block-ticks 500]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from clients import ControllerClient
from clients.server_process import ServerProcess
from clients.state import RobotState


def paced_block(step: Callable[[], object], ticks: int) -> np.ndarray:
    """Tick times (s) of ``ticks`` steps, one per millisecond."""
    times = np.empty(ticks)
    next_tick = time.perf_counter()
    for i in range(ticks):
        next_tick += 1e-3
        while time.perf_counter() < next_tick:
            pass
        start = time.perf_counter()
        step()
        times[i] = time.perf_counter() - start
    return times


def compare(
    plain: ControllerClient, recorded: ControllerClient, blocks: int, block_ticks: int
) -> tuple[np.ndarray, np.ndarray]:
    """Alternate blocks of the two loops; their tick times."""
    welcome = plain.welcome
    assert welcome is not None
    state = RobotState.standing(welcome).to_message(0.0, [True] * len(welcome.contacts))
    times: dict[str, list[np.ndarray]] = {"plain": [], "recorded": []}
    for _ in range(blocks):
        times["plain"].append(paced_block(lambda: plain.step(state), block_ticks))
        times["recorded"].append(paced_block(lambda: recorded.step(state), block_ticks))
    return np.concatenate(times["plain"]), np.concatenate(times["recorded"])


def dropped_by_recorders(logs: list[Path]) -> int:
    """Messages the recorders of these (closed) logs counted as dropped (their metadata)."""
    dropped = 0
    for log in logs:
        with open(log, "rb") as file:
            for record in make_reader(file).iter_metadata():
                if record.name == "poise_recorder":
                    dropped += int(record.metadata["dropped"])
    return dropped


def report(label: str, plain: np.ndarray, recorded: np.ndarray, logs: list[Path]) -> None:
    ratio = recorded.mean() / plain.mean()
    size = sum(log.stat().st_size for log in logs)
    dropped = dropped_by_recorders(logs)
    print(
        f"{label:<8}{plain.mean() * 1e6:>9.0f}µs{np.percentile(plain, 99) * 1e6:>9.0f}µs"
        f"{recorded.mean() * 1e6:>9.0f}µs{np.percentile(recorded, 99) * 1e6:>9.0f}µs"
        f"{ratio:>9.3f}x{dropped:>9}{size / 1e6:>8.1f} MB"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, default=10)
    parser.add_argument("--block-ticks", type=int, default=500)
    args = parser.parse_args()
    ticks = args.blocks * args.block_ticks
    print(f"{ticks} ticks per loop at 1 kHz, thesis_humanoid standing, momentum controller")
    print(
        f"{'side':<8}{'plain':>11}{'p99':>11}{'recorded':>11}{'p99':>11}{'ratio':>10}"
        f"{'dropped':>9}{'log':>11}"
    )
    with tempfile.TemporaryDirectory() as directory:
        client_log = Path(directory) / "client.mcap"
        with ServerProcess() as server:
            with (
                ControllerClient(server.endpoint, timeout_s=10.0) as plain,
                ControllerClient(server.endpoint, timeout_s=10.0, record=client_log) as recorded,
            ):
                plain.connect("thesis_humanoid", controller="momentum")
                recorded.connect("thesis_humanoid", controller="momentum")
                plain_s, recorded_s = compare(plain, recorded, args.blocks, args.block_ticks)
        report("client", plain_s, recorded_s, [client_log])

        server_logs = Path(directory) / "server"
        with (
            ServerProcess() as plain_server,
            ServerProcess(extra_args=["--record", str(server_logs)]) as recording_server,
            ControllerClient(plain_server.endpoint, timeout_s=10.0) as plain,
            ControllerClient(recording_server.endpoint, timeout_s=10.0) as recorded,
        ):
            plain.connect("thesis_humanoid", controller="momentum")
            recorded.connect("thesis_humanoid", controller="momentum")
            plain_s, recorded_s = compare(plain, recorded, args.blocks, args.block_ticks)
        report("server", plain_s, recorded_s, sorted(server_logs.glob("*.mcap")))


if __name__ == "__main__":
    main()
