"""A ``stats`` request answered from every worker: the broker gathers the parts.

A client's sessions live on several workers, and each worker knows only its own.
:class:`StatsGathers` asks each worker holding a session the client may see (its
own, or every one with ``poise serve --stats-all``) for those sessions' stats,
collects the parts as they come back and answers the client once every worker has
answered, or ``DEADLINE_EXCEEDED`` when one did not within the server's deadline
or a worker was replaced meanwhile. A client has one ``stats`` request answered at
a time.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable, Iterator

import msgpack

from controller_server.config import ServeConfig
from controller_server.routing import Route, error_reply
from controller_server.session_table import SessionTable
from protocol.errors import ErrorCode
from protocol.messages import Message, SessionStats, Stats

__all__ = ["Gather", "StatsGathers"]


@dataclasses.dataclass
class Gather:
    """A ``stats`` request waiting for the workers' answers."""

    identity: bytes
    seq: int
    deadline_s: float
    waiting: set[bytes]
    sessions: list[SessionStats] = dataclasses.field(default_factory=list)


class StatsGathers:
    """The ``stats`` requests of clients being gathered from the workers.

    Args:
        config: Its deadline (``deadline_s``) and whether a client sees every session
            (``stats_all``).
        local: The broker's session-less table: it checks a request as a worker would.
        ids: The broker's request ids (shared with the requests it forwards).
        to_worker: Sends frames to a worker by identity.
        reply: Answers a client by routing id.
    """

    def __init__(
        self,
        config: ServeConfig,
        local: SessionTable,
        ids: Iterator[int],
        to_worker: Callable[[bytes, list[bytes]], bool],
        reply: Callable[[bytes, Message], None],
    ):
        self.config = config
        self.gathers: dict[bytes, Gather] = {}
        """The requests still waiting, by request id."""
        self._local = local
        self._ids = ids
        self._to_worker = to_worker
        self._reply = reply

    def start(self, identity: bytes, client: str, payload: bytes, routes: Iterable[Route]) -> None:
        """Ask the workers for the sessions of ``routes`` that ``client`` may see."""
        # The session-less table checks the request as a worker would: a valid one
        # comes back as an empty ``stats``, anything else as the error to send.
        request = self._local.handle(identity, payload)
        if not isinstance(request, Stats):
            self._reply(identity, request)
            return
        if any(gather.identity == identity for gather in self.gathers.values()):
            detail = "a stats request of this client is still being answered; wait for it"
            self._reply(identity, error_reply(request.seq, ErrorCode.LIMIT_EXCEEDED, "", detail))
            return
        visible: dict[bytes, list[bytes]] = {}
        for route in routes:
            if self.config.stats_all or route.client == client:
                visible.setdefault(route.worker, []).append(route.key)
        request_id = next(self._ids).to_bytes(8, "little")
        gather = Gather(
            identity, request.seq, time.monotonic() + self.config.deadline_s, set(visible)
        )
        self.gathers[request_id] = gather
        for worker, keys in visible.items():
            self._to_worker(worker, [b"stats", request_id, *keys])
        self._finish(request_id)

    def collect(self, worker: bytes, request_id: bytes, data: bytes) -> None:
        """A worker's part (its sessions' stats, msgpack): answer when it was the last."""
        gather = self.gathers.get(request_id)
        if gather is None or worker not in gather.waiting:
            return
        gather.waiting.discard(worker)
        gather.sessions += [SessionStats.model_validate(s) for s in msgpack.unpackb(data)]
        self._finish(request_id)

    def expire(self, now: float) -> None:
        """Answer the requests past their deadline ``DEADLINE_EXCEEDED``."""
        for request_id in [rid for rid, g in self.gathers.items() if now > g.deadline_s]:
            self._finish(request_id)

    def worker_lost(self, worker: bytes) -> None:
        """A worker was replaced: the requests waiting for it are answered now."""
        for request_id, gather in list(self.gathers.items()):
            if worker in gather.waiting:
                gather.waiting.discard(worker)
                self._finish(request_id)

    def answer_now(self) -> None:
        """Answer every request now: the server is stopping (a worker has not reported)."""
        for request_id, gather in list(self.gathers.items()):
            gather.deadline_s = 0.0
            self._finish(request_id)

    def _finish(self, request_id: bytes) -> None:
        gather = self.gathers[request_id]
        if gather.waiting and time.monotonic() < gather.deadline_s:
            return
        del self.gathers[request_id]
        if gather.waiting:
            self._reply(
                gather.identity,
                error_reply(gather.seq, ErrorCode.DEADLINE_EXCEEDED, "", "a worker did not report"),
            )
        else:
            self._reply(gather.identity, Stats(seq=gather.seq, sessions=gather.sessions))
