"""Round-trip latency of `poise serve` against a raw pyzmq echo, in one run.

Both servers run in their own process on loopback; the client is this
process. For each: back-to-back round trips, then round trips paced at
1 kHz (send on each millisecond tick). The echo answers every request with
a reply of the command's size, so the two differ by the server's work only.
Server-side compute time comes from the server's own `stats`.

Usage: python bench/roundtrip.py [--model thesis_humanoid] [--count 2000]
"""

from __future__ import annotations

import argparse
import multiprocessing
import time

import numpy as np
import zmq
from baselines import echo_server

from clients import ControllerClient
from clients.server_process import ServerProcess
from clients.state import RobotState
from protocol import encode


def measure(round_trip, count: int, paced_hz: float | None) -> np.ndarray:
    """Latencies (s) of ``count`` calls, back-to-back or paced."""
    latencies = np.empty(count)
    period = 1.0 / paced_hz if paced_hz else 0.0
    next_tick = time.perf_counter()
    for i in range(count):
        if paced_hz:
            next_tick += period
            while time.perf_counter() < next_tick:
                pass
        start = time.perf_counter()
        round_trip()
        latencies[i] = time.perf_counter() - start
    return latencies


def summary(latencies: np.ndarray) -> tuple[float, float]:
    return float(np.percentile(latencies, 50)), float(np.percentile(latencies, 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="thesis_humanoid")
    parser.add_argument("--count", type=int, default=2000)
    args = parser.parse_args()

    with ServerProcess() as server, ControllerClient(server.endpoint, timeout_s=10.0) as client:
        welcome = client.connect(args.model)
        state = RobotState.standing(welcome).to_message(0.0, [True] * len(welcome.contacts))
        command = client.step(state)
        request_size, reply_size = len(encode(state)), len(encode(command))
        poise = {
            "back-to-back": measure(lambda: client.step(state), args.count, None),
            "paced 1 kHz": measure(lambda: client.step(state), args.count, 1000.0),
        }
        stats = next(s for s in client.stats() if s.session_id == welcome.session_id)

    queue: multiprocessing.Queue = multiprocessing.Queue()
    echo = multiprocessing.Process(target=echo_server, args=(queue, reply_size), daemon=True)
    echo.start()
    context = zmq.Context()
    socket = context.socket(zmq.DEALER)
    socket.connect(queue.get(timeout=30))
    request = encode(state)

    def echo_round_trip() -> None:
        socket.send(request)
        socket.recv()

    measure(echo_round_trip, 200, None)  # warm-up
    raw = {
        "back-to-back": measure(echo_round_trip, args.count, None),
        "paced 1 kHz": measure(echo_round_trip, args.count, 1000.0),
    }
    socket.send(b"stop")
    socket.close(linger=0)
    context.term()
    echo.join(5)

    print(f"model {args.model}: request {request_size} B, reply {reply_size} B, ", end="")
    print(f"{args.count} round trips per mode")
    print(
        f"{'mode':<14}{'echo p50':>11}{'echo p99':>11}{'poise p50':>11}{'poise p99':>11}"
        f"{'p50 ratio':>11}{'p99 ratio':>11}"
    )
    for mode in poise:
        e50, e99 = summary(raw[mode])
        p50, p99 = summary(poise[mode])
        print(
            f"{mode:<14}{e50 * 1e6:>9.0f}µs{e99 * 1e6:>9.0f}µs{p50 * 1e6:>9.0f}µs"
            f"{p99 * 1e6:>9.0f}µs{p50 / e50:>10.1f}x{p99 / e99:>10.1f}x"
        )
    compute_p50, compute_p99 = stats.compute_time_p50_s, stats.compute_time_p99_s
    echo_p50 = summary(raw["back-to-back"])[0]
    print(
        f"server compute per tick (stats, last 1000): p50 {compute_p50 * 1e6:.0f}µs, "
        f"p99 {compute_p99 * 1e6:.0f}µs; compute p50 / echo p50 = {compute_p50 / echo_p50:.1f}x"
    )


if __name__ == "__main__":
    main()
