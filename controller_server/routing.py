"""What the broker keeps track of: where each session lives, what is in flight, its workers.

A client's :class:`Route` leads to the worker holding its session (chosen by :func:`place`);
a :class:`Pending` is a request forwarded there and not yet answered (with the deadline it
must be answered by); a :class:`WorkerRecord` is one worker process and its channel.
:func:`error_reply` and :func:`error_of` are the broker's own ``error`` replies.
"""

from __future__ import annotations

import dataclasses
import subprocess
from collections.abc import Iterable, Mapping

from controller_server.worker import Channel, client_tag
from protocol.errors import AssetsMissing, ErrorCode, ProtocolError
from protocol.messages import Error

__all__ = ["Pending", "Route", "WorkerRecord", "error_of", "error_reply", "place"]


@dataclasses.dataclass(slots=True)
class Route:
    """Where a client's session lives, and who may use it."""

    key: bytes
    """Session key on the worker (opaque, never reused)."""
    worker: bytes
    client: str
    """CURVE key (z85) of the client, or its peer address without CURVE."""
    last_seen_s: float
    in_flight: int = 0
    client_tag: bytes = b""
    """The client's tag in request headers: its requests share one turn at the worker."""

    def __post_init__(self) -> None:
        self.client_tag = client_tag(self.client)


@dataclasses.dataclass(slots=True)
class Pending:
    """A request forwarded to a worker and not yet answered by it."""

    identity: bytes
    seq: int
    route: Route
    deadline_s: float
    recycle_s: float
    answered: bool = False


@dataclasses.dataclass
class WorkerRecord:
    """A worker process, its channel, and what the broker holds for it."""

    identity: bytes
    process: subprocess.Popen[bytes]
    channel: Channel
    ready: bool = False
    writing: bool = False
    """Whether the broker waits for its socket to take more (polls it for output)."""
    routes: set[bytes] = dataclasses.field(default_factory=set)
    """Routing ids of the clients whose sessions live here."""
    pending: dict[bytes, Pending] = dataclasses.field(default_factory=dict)
    """Forwarded requests by id, in the order sent (and served)."""
    backlog: list[list[bytes]] = dataclasses.field(default_factory=list)
    """Messages for it held until it reports ready (a replacement warming up)."""

    @property
    def fd(self) -> int:
        """The channel's file descriptor (polled by the broker)."""
        return self.channel.fileno()


def place(
    workers: Iterable[WorkerRecord],
    routes: Mapping[bytes, Route],
    client: str,
    workers_per_client: int,
) -> WorkerRecord:
    """The worker for a new session of ``client`` (``routes``: every route, by routing id).

    A client's sessions occupy at most ``workers_per_client`` workers (all but
    one by default): a client that opens a session per worker and floods them
    would otherwise leave a client arriving later only workers where it waits
    behind a tick of the flood's (non-preemptive), whereas on a worker of its own
    the operating system shares the cores between the processes. Within that,
    the worker with the fewest other clients' sessions, then the fewest
    sessions; ready workers first (a replacement still warming up gets the
    request queued).
    """
    workers = list(workers)
    others: dict[bytes, int] = {}
    held = set()
    for worker in workers:
        clients = [route.client for identity in worker.routes if (route := routes.get(identity))]
        others[worker.identity] = sum(c != client for c in clients)
        if client in clients:
            held.add(worker.identity)
    candidates = [
        worker for worker in workers if len(held) < workers_per_client or worker.identity in held
    ]
    return min(
        candidates,
        key=lambda w: (not w.ready, others[w.identity], len(w.routes), len(w.pending)),
    )


def error_reply(
    seq: int, code: ErrorCode, field: str, detail: str, max_message_bytes: int | None = None
) -> Error:
    """An ``error`` reply (``seq`` −1 when the request's is unknown)."""
    return Error(
        seq=max(seq, -1),
        code=code,
        field=field,
        detail=detail,
        max_message_bytes=max_message_bytes,
    )


def error_of(exc: ProtocolError, max_message_bytes: int) -> Error:
    """The ``error`` reply of a refused request (with what ``ASSETS_MISSING`` adds)."""
    missing = exc.missing if isinstance(exc, AssetsMissing) else None
    return Error(
        seq=max(exc.seq, -1),
        code=exc.code,
        field=exc.field,
        detail=exc.detail,
        missing_asset_hashes=missing,
        max_message_bytes=max_message_bytes if missing is not None else None,
    )
