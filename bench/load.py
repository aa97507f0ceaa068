"""Serving under load: workers, fairness and many paced clients, against a raw pyzmq echo.

One run prints:

1. aggregate replies/s of 4 clients at full rate, with 1 worker and with 2
   (goal on a 2-core machine: ≥ 1.7×), for `momentum` and `prioritized`,
   beside a raw pyzmq echo answering the same 4 clients (the transport's own
   ceiling);
2. 8 clients paced at 1 kHz each for 10 s: ticks answered, p50/p99 round trip;
3. a `tracking` client at 200 Hz beside a `prioritized` client at full rate
   (goal: the tracking client gets ≥ 95 % of its ticks within 5 ms);
4. the same beside one client's four `prioritized` sessions at full rate
   (same goal).

Parts 1 and 2 let one client use every worker (`--max-workers-per-client`):
their clients all come from this host, which the server counts as one
client. In parts 3 and 4 the tracking client comes from another address,
127.0.0.2: the server shares its workers between clients, not sessions.

Usage: python bench/load.py [--seconds 10] [--parts 1 2 3 4]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import multiprocessing
import os
import sys
import time
from pathlib import Path

import zmq
from baselines import echo_server

from clients.load import ClientLoad, run_clients, standing_request
from clients.server_process import ServerProcess
from protocol.messages import Hello


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def server_cpu_seconds(server: ServerProcess) -> tuple[float, float]:
    """CPU seconds of the broker and of all its workers."""
    assert server.process is not None
    children = Path(f"/proc/{server.process.pid}/task/{server.process.pid}/children")
    workers = [int(pid) for pid in children.read_text().split()]
    return cpu_seconds(server.process.pid), sum(map(cpu_seconds, workers))


def rate(loads: list[ClientLoad], seconds: float) -> float:
    return sum(load.commands for load in loads) / seconds


def log(text: str) -> None:
    print(f"  … {text}", file=sys.stderr, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each part")
    parser.add_argument(
        "--parts", type=int, nargs="+", choices=(1, 2, 3, 4), default=[1, 2, 3, 4],
        metavar="N", help="which parts to run (default: 1 2 3 4)",
    )  # fmt: skip
    args = parser.parse_args()
    parts = (throughput, paced, tracking_beside_one, tracking_beside_four)
    for number, part in enumerate(parts, start=1):
        if number in args.parts:
            part(args.seconds)


def throughput(seconds: float) -> None:
    """Part 1."""
    hello = Hello(model="thesis_humanoid", controller="momentum")
    print(f"1. four clients at full rate, {seconds:g} s each")
    rates, cpu = {}, {}
    for controller in ("momentum", "prioritized"):
        clients = [
            (f"client {i}", Hello(model="thesis_humanoid", controller=controller), None)
            for i in range(4)
        ]
        for workers in (1, 2):
            # One host is one client: it may use every worker here (throughput).
            all_workers = ["--workers", str(workers), "--max-workers-per-client", str(workers)]
            with ServerProcess(extra_args=all_workers) as server:
                before, client_before = server_cpu_seconds(server), time.process_time()
                loads = run_clients(server.endpoint, clients, seconds, progress=log)
                after, client_after = server_cpu_seconds(server), time.process_time()
                rates[controller, workers] = rate(loads, seconds)
                replies = max(1, sum(load.commands for load in loads))
                cpu[controller, workers] = [
                    (after[0] - before[0]) / replies,
                    (after[1] - before[1]) / replies,
                    (client_after - client_before) / replies,
                ]
                if controller == "momentum" and workers == 1:
                    request = standing_request(run_welcome(server.endpoint, hello))
    queue: multiprocessing.Queue = multiprocessing.Queue()
    echo = multiprocessing.Process(target=echo_server, args=(queue, 900), daemon=True)
    echo.start()
    echo_endpoint = queue.get(timeout=30)
    echo_clients = [(f"client {i}", None, None) for i in range(4)]
    echo_rate = rate(
        run_clients(echo_endpoint, echo_clients, seconds, request=request, progress=log), seconds
    )
    stop = zmq.Context.instance().socket(zmq.DEALER)
    stop.connect(echo_endpoint)
    stop.send(b"stop")
    echo.join(5)
    stop.close(linger=0)
    print(f"{'':<28}{'replies/s':>12}{'vs echo':>10}   CPU µs per reply: broker, workers, clients")
    print(f"{'raw pyzmq echo':<28}{echo_rate:>12.0f}{1.0:>9.3f}x")
    for controller in ("momentum", "prioritized"):
        for workers in (1, 2):
            value = rates[controller, workers]
            label = f"{controller}, {workers} worker{'s' * (workers > 1)}"
            broker, work, client = (x * 1e6 for x in cpu[controller, workers])
            print(
                f"{label:<28}{value:>12.0f}{value / echo_rate:>9.3f}x   "
                f"{broker:.0f}, {work:.0f}, {client:.0f}"
            )
        ratio = rates[controller, 2] / rates[controller, 1]
        print(f"{controller}: 2 workers / 1 worker = {ratio:.2f}x (goal ≥ 1.7x)")


def paced(seconds: float) -> None:
    """Part 2."""
    hello = Hello(model="thesis_humanoid", controller="momentum")
    print(f"\n2. eight clients paced at 1 kHz, `momentum`, {seconds:g} s, 2 workers")
    with ServerProcess(extra_args=["--workers", "2", "--max-workers-per-client", "2"]) as server:
        loads = run_clients(
            server.endpoint, [(f"client {i}", hello, 1000.0) for i in range(8)], seconds,
            progress=log,
        )  # fmt: skip
    print(f"{'client':<12}{'ticks':>8}{'answered':>10}{'rate Hz':>9}{'p50 ms':>9}{'p99 ms':>9}"
          f"  errors")  # fmt: skip
    for load in loads:
        print(
            f"{load.label:<12}{load.ticks:>8}{load.commands:>10}{load.commands / seconds:>9.0f}"
            f"{load.percentile_ms(50):>9.2f}{load.percentile_ms(99):>9.2f}  {load.errors or ''}"
        )
    print(f"all: {rate(loads, seconds):.0f} replies/s")


def tracking_beside_one(seconds: float) -> None:
    """Part 3."""
    print(
        f"\n3. `tracking` at 200 Hz (from 127.0.0.2) beside `prioritized` at full rate, "
        f"{seconds:g} s, 2 workers"
    )
    with ServerProcess(extra_args=["--workers", "2"]) as server:
        tracking, prioritized = run_clients(
            server.endpoint,
            [
                ("tracking", Hello(model="thesis_humanoid", controller="tracking"), 200.0),
                ("prioritized", Hello(model="thesis_humanoid", controller="prioritized"), None),
            ],
            seconds,
            progress=log,
            sources={"tracking": "127.0.0.2"},
        )
    print_fairness(tracking, [prioritized], seconds)


def tracking_beside_four(seconds: float) -> None:
    """Part 4."""
    print(
        f"\n4. `tracking` at 200 Hz (from 127.0.0.2) beside one client's four `prioritized` "
        f"sessions at full rate, {seconds:g} s, 2 workers"
    )
    with ServerProcess(extra_args=["--workers", "2"]) as server:
        prioritized_hello = Hello(model="thesis_humanoid", controller="prioritized")
        tracking, *flood = run_clients(
            server.endpoint,
            [
                ("tracking", Hello(model="thesis_humanoid", controller="tracking"), 200.0),
                *((f"flood {i}", prioritized_hello, None) for i in range(4)),
            ],
            seconds,
            progress=log,
            sources={"tracking": "127.0.0.2"},
        )
    print_fairness(tracking, flood, seconds)


def print_fairness(tracking: ClientLoad, others: list[ClientLoad], seconds: float) -> None:
    """The tracking client's share of ticks within 5 ms, and what the others got."""
    within = tracking.within(0.005)
    print(
        f"tracking: {tracking.ticks} ticks, {tracking.commands} answered, {within} within 5 ms "
        f"({within / max(1, tracking.ticks):.1%}; goal ≥ 95 %), "
        f"p50 {tracking.percentile_ms(50):.2f} ms, p99 {tracking.percentile_ms(99):.2f} ms"
    )
    for other in others:
        print(
            f"{other.label}: {other.commands} answered ({other.commands / seconds:.0f}/s), "
            f"p50 {other.percentile_ms(50):.2f} ms, p99 {other.percentile_ms(99):.2f} ms"
            f"  {other.errors or ''}"
        )


def run_welcome(endpoint: str, hello: Hello):
    from clients import ControllerClient

    with ControllerClient(endpoint, timeout_s=30.0) as client:
        return client.connect(hello.model, controller=hello.controller)


if __name__ == "__main__":
    main()
