"""Round-trip latency of `poise serve` against a raw pyzmq echo, in one run.

Three servers, each in its own processes on loopback; the client is this
process:

- **poise**: ``poise serve`` (broker and workers), the ``momentum`` controller;
- **echo**: a pyzmq ROUTER answering every request with a reply of the
  command's size (``baselines.echo_server``);
- **broker floor**: the same ROUTER, forwarding each request over a Unix
  socket pair to another process that answers it, and the answer back — the
  hops of ``poise serve`` with none of its work.

For each mode — back-to-back round trips, then round trips paced at 1 kHz
(send on each millisecond tick) — they are measured in alternating chunks,
so all see the same machine load. The server's compute time per tick is the
``diagnostics.compute_time_s`` of each command (what ``stats`` reports).

Prints, per mode, the overhead ratio of issue 15's goal 4:
(poise RTT p50 − server compute p50) / echo RTT p50, goal ≤ 1.3x.

Usage: python bench/roundtrip.py [--model thesis_humanoid] [--count 2000] [--chunks 10]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import multiprocessing
import os
import socket
import struct
import time
from collections.abc import Callable

import numpy as np
import zmq
from baselines import echo_server

from clients import ControllerClient
from clients.server_process import ServerProcess
from clients.state import RobotState
from protocol import encode

GOAL_RATIO = 1.3
"""Issue 15, goal 4: poise RTT minus server compute ≤ 1.3 x the echo RTT."""
MODES = {"back-to-back": None, "paced 1 kHz": 1000.0}
_LENGTH = struct.Struct("<I")


def _read_exactly(sock: socket.socket, size: int) -> bytes:
    data = b""
    while len(data) < size:
        chunk = sock.recv(size - len(data))
        if not chunk:
            raise EOFError
        data += chunk
    return data


def _answering_process(sock: socket.socket, brokers_end: socket.socket, reply_size: int) -> None:
    brokers_end.close()  # a forked copy: the broker closing its own must reach us as EOF
    reply = b"\x00" * reply_size
    try:
        while True:
            (size,) = _LENGTH.unpack(_read_exactly(sock, _LENGTH.size))
            identity = _read_exactly(sock, size)[:16]
            sock.sendall(_LENGTH.pack(len(identity) + reply_size) + identity + reply)
    except EOFError:
        pass


def broker_floor(endpoint_queue: multiprocessing.Queue, reply_size: int) -> None:
    """A ROUTER forwarding to a process over a socket pair, and back; ``b"stop"`` ends it."""
    ours, theirs = socket.socketpair()
    answering = multiprocessing.Process(target=_answering_process, args=(theirs, ours, reply_size))
    answering.start()
    theirs.close()
    context = zmq.Context()
    router = context.socket(zmq.ROUTER)
    port = router.bind_to_random_port("tcp://127.0.0.1")
    endpoint_queue.put(f"tcp://127.0.0.1:{port}")
    poller = zmq.Poller()
    poller.register(router, zmq.POLLIN)
    poller.register(ours.fileno(), zmq.POLLIN)
    identities: dict[bytes, bytes] = {}
    while True:
        events = dict(poller.poll(50))
        if ours.fileno() in events:
            (size,) = _LENGTH.unpack(_read_exactly(ours, _LENGTH.size))
            message = _read_exactly(ours, size)
            router.send_multipart([identities[message[:16]], message[16:]])
        if router in events:
            identity, payload = router.recv_multipart()
            if payload == b"stop":
                break
            key = identity.ljust(16, b"\x00")[:16]
            identities[key] = identity
            ours.sendall(_LENGTH.pack(len(key) + len(payload)) + key + payload)
    ours.close()
    answering.join(5)
    router.close(linger=0)
    context.term()


def measure(round_trip: Callable[[], float], count: int, paced_hz: float | None) -> np.ndarray:
    """Latency (s) and what ``round_trip`` returns, of ``count`` calls, back-to-back or paced."""
    samples = np.empty((count, 2))
    period = 1.0 / paced_hz if paced_hz else 0.0
    next_tick = time.perf_counter()
    for i in range(count):
        if paced_hz:
            next_tick += period
            while time.perf_counter() < next_tick:
                pass
        start = time.perf_counter()
        value = round_trip()
        samples[i] = time.perf_counter() - start, value
    return samples


def load() -> str:
    return " ".join(f"{value:.2f}" for value in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="thesis_humanoid")
    parser.add_argument("--count", type=int, default=2000, help="round trips per mode and server")
    parser.add_argument("--chunks", type=int, default=10, help="alternations per mode")
    args = parser.parse_args()
    chunk = max(1, args.count // args.chunks)
    load_start = load()

    with ServerProcess() as server, ControllerClient(server.endpoint, timeout_s=10.0) as client:
        welcome = client.connect(args.model)
        state = RobotState.standing(welcome).to_message(0.0, [True] * len(welcome.contacts))
        command = client.step(state)
        request = encode(state)
        request_size, reply_size = len(request), len(encode(command))

        def poise_round_trip() -> float:
            diagnostics = client.step(state).diagnostics
            return diagnostics.compute_time_s if diagnostics is not None else np.nan

        context = zmq.Context()
        baselines: dict[str, tuple[multiprocessing.Process, zmq.Socket]] = {}
        for name, target in (("echo", echo_server), ("broker floor", broker_floor)):
            queue: multiprocessing.Queue = multiprocessing.Queue()
            # Not a daemon: the broker floor starts a process of its own.
            process = multiprocessing.Process(target=target, args=(queue, reply_size))
            process.start()
            dealer = context.socket(zmq.DEALER)
            dealer.connect(queue.get(timeout=30))
            baselines[name] = process, dealer

        def raw_round_trip(dealer: zmq.Socket) -> Callable[[], float]:
            def round_trip() -> float:
                dealer.send(request)
                dealer.recv()
                return 0.0

            return round_trip

        trips = {"poise": poise_round_trip}
        trips.update({name: raw_round_trip(dealer) for name, (_, dealer) in baselines.items()})
        for round_trip in trips.values():
            measure(round_trip, 200, None)  # warm-up
        samples: dict[str, dict[str, list[np.ndarray]]] = {
            name: {mode: [] for mode in MODES} for name in trips
        }
        for mode, paced_hz in MODES.items():
            for _ in range(args.chunks):
                for name, round_trip in trips.items():
                    samples[name][mode].append(measure(round_trip, chunk, paced_hz))
        stats = next(s for s in client.stats() if s.session_id == welcome.session_id)
        for process, dealer in baselines.values():
            dealer.send(b"stop")
            dealer.close(linger=0)
            process.join(5)
            if process.is_alive():
                process.terminate()
        context.term()

    print(
        f"model {args.model}: request {request_size} B, reply {reply_size} B; "
        f"{chunk * args.chunks} round trips per mode and server in {args.chunks} alternating "
        f"chunks; load average {load_start} at start, {load()} at end"
    )
    print(
        f"{'mode':<14}{'echo p50':>10}{'floor p50':>11}{'poise p50':>11}{'poise p99':>11}"
        f"{'compute p50':>13}{'overhead':>10}{'ratio':>8}  goal ≤ {GOAL_RATIO}x"
    )
    for mode in MODES:
        echo_p50 = np.percentile(np.concatenate(samples["echo"][mode])[:, 0], 50)
        floor_p50 = np.percentile(np.concatenate(samples["broker floor"][mode])[:, 0], 50)
        poise = np.concatenate(samples["poise"][mode])
        poise_p50, poise_p99 = np.percentile(poise[:, 0], [50, 99])
        compute_p50 = np.nanpercentile(poise[:, 1], 50)
        overhead = poise_p50 - compute_p50
        ratio = overhead / echo_p50
        print(
            f"{mode:<14}{echo_p50 * 1e6:>8.0f}µs{floor_p50 * 1e6:>9.0f}µs{poise_p50 * 1e6:>9.0f}µs"
            f"{poise_p99 * 1e6:>9.0f}µs{compute_p50 * 1e6:>11.0f}µs{overhead * 1e6:>8.0f}µs"
            f"{ratio:>7.2f}x  {'met' if ratio <= GOAL_RATIO else 'not met'}"
            f" (floor / echo {floor_p50 / echo_p50:.2f}x)"
        )
    print(
        "overhead = poise RTT p50 − server compute p50 (each command's "
        "diagnostics.compute_time_s); ratio = overhead / echo RTT p50; floor = a ROUTER "
        "forwarding over a socket pair to a process that answers (poise's hops, none of its work)"
    )
    print(
        f"server compute per tick (stats, last 1000): p50 {stats.compute_time_p50_s * 1e6:.0f}µs, "
        f"p99 {stats.compute_time_p99_s * 1e6:.0f}µs"
    )


if __name__ == "__main__":
    main()
