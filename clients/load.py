"""Load generators for a server: many clients at once, paced or at full rate.

Each client is a thread with its own DEALER socket and session (ZeroMQ
releases the GIL while it waits, and a client's own work is one pre-encoded
state per request). Used by ``bench/load.py`` and the load test; the states
are the standing pose, so every tick costs the controller the same.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable

import msgpack
import numpy as np
import zmq

from clients.state import RobotState
from protocol.codec import decode, encode
from protocol.errors import ErrorCode
from protocol.messages import Bye, Hello, Welcome

__all__ = ["ClientLoad", "from_source", "run_clients", "standing_request"]

REPLY_TIMEOUT_S = 5.0
"""A reply later than this ends the client's run (``errors["timeout"]``)."""
HELLO_TIMEOUT_S = 30.0
COMMAND_PREFIX = msgpack.packb("type") + msgpack.packb("command")
ERROR_NAMES = {int(code): code.name for code in ErrorCode}


@dataclasses.dataclass
class ClientLoad:
    """What one client sent and got back."""

    label: str
    ticks: int = 0
    """Ticks the client had (paced) or requests it sent (full rate)."""
    commands: int = 0
    errors: dict[str, int] = dataclasses.field(default_factory=dict)
    round_trip_s: list[float] = dataclasses.field(default_factory=list)
    """Round-trip time of every command received."""

    def percentile_ms(self, q: float) -> float:
        """The ``q``-th percentile round trip in ms (NaN without commands)."""
        return float(np.percentile(self.round_trip_s, q) * 1e3) if self.round_trip_s else np.nan

    def within(self, limit_s: float) -> int:
        """Commands received within ``limit_s`` of sending the state."""
        return int(np.sum(np.asarray(self.round_trip_s) <= limit_s))


def standing_request(welcome: Welcome) -> bytes:
    """An encoded ``state``: the neutral pose standing, at rest, both feet supporting."""
    state = RobotState.standing(welcome).to_message(0.0, [True] * len(welcome.contacts))
    return encode(state)


def from_source(endpoint: str, source: str) -> str:
    """``endpoint``, connected to from the local address ``source``.

    Another client to a server that tells clients apart by address: libzmq's
    ``tcp://SOURCE:0;HOST:PORT``.
    """
    return endpoint.replace("tcp://", f"tcp://{source}:0;", 1)


def _client(
    endpoint: str,
    hello: Hello | None,
    rate_hz: float | None,
    duration_s: float,
    start: threading.Barrier,
    load: ClientLoad,
    request: bytes | None,
    source: str | None = None,
) -> None:
    context = zmq.Context()
    socket = context.socket(zmq.DEALER)
    socket.setsockopt(zmq.LINGER, 0)
    socket.connect(endpoint if source is None else from_source(endpoint, source))
    try:
        if hello is not None:
            socket.send(encode(hello))
            if not socket.poll(int(HELLO_TIMEOUT_S * 1000)):
                raise TimeoutError(f"{load.label}: no welcome")
            welcome = decode(socket.recv())
            if not isinstance(welcome, Welcome):
                raise RuntimeError(f"{load.label}: {welcome}")
            request = standing_request(welcome)
        assert request is not None
        start.wait(HELLO_TIMEOUT_S)
        period = 1.0 / rate_hz if rate_hz else 0.0
        begin = time.perf_counter()
        end = begin + duration_s
        next_tick = begin
        while (now := time.perf_counter()) < end:
            if rate_hz:  # paced: one state per tick, a tick missed while a reply is awaited
                if now < next_tick:
                    time.sleep(min(next_tick - now, 0.0005))
                    continue
                load.ticks += int((now - next_tick) // period) + 1
                next_tick += (int((now - next_tick) // period) + 1) * period
            else:
                load.ticks += 1
            sent = time.perf_counter()
            socket.send(request)
            if not socket.poll(int(REPLY_TIMEOUT_S * 1000)):
                load.errors["timeout"] = 1  # a late reply would be taken for the next one's
                break
            data = socket.recv()
            # A command begins {"type": "command", …}: no need to decode the rest (the echo's
            # replies are counted as they are).
            if hello is None or COMMAND_PREFIX in data[:16]:
                load.commands += 1
                load.round_trip_s.append(time.perf_counter() - sent)
            else:
                reply = msgpack.unpackb(data)
                code = reply.get("code")
                key = (
                    ERROR_NAMES.get(code, str(code)) if code is not None else str(reply.get("type"))
                )
                load.errors[key] = load.errors.get(key, 0) + 1
        if hello is not None:  # close the session; late replies before the bye are skipped
            socket.send(encode(Bye(seq=1)))
            while socket.poll(1000) and msgpack.unpackb(socket.recv()).get("type") != "bye":
                pass
    except BaseException:
        start.abort()  # the other clients stop waiting for this one
        raise
    finally:
        socket.close(linger=0)
        context.term()


def run_clients(
    endpoint: str,
    clients: list[tuple[str, Hello | None, float | None]],
    duration_s: float,
    request: bytes | None = None,
    progress: Callable[[str], None] | None = None,
    sources: dict[str, str] | None = None,
) -> list[ClientLoad]:
    """Run clients at once for ``duration_s`` and return what each got.

    Args:
        endpoint: Server (or echo) endpoint.
        clients: Per client: label, the ``hello`` opening its session (``None``
            for an echo server, with ``request`` given), and its rate in Hz
            (``None``: full rate, the next request as soon as the reply is in).
        duration_s: How long every client sends, from a common start.
        request: The bytes to send when a client has no ``hello``.
        progress: Optional callable told what runs.
        sources: Source IP address by label (a loopback one, ``127.0.0.2``): the
            server tells clients apart by address (without CURVE).
    """
    loads = [ClientLoad(label) for label, _, _ in clients]
    start = threading.Barrier(len(clients))
    threads = [
        threading.Thread(
            target=_client,
            args=(endpoint, hello, rate, duration_s, start, load, request),
            kwargs={"source": (sources or {}).get(load.label)},
            daemon=True,
        )
        for (_, hello, rate), load in zip(clients, loads, strict=True)
    ]
    if progress is not None:
        progress(f"{len(clients)} clients for {duration_s:g} s")
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return loads
