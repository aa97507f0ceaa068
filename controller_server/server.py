"""The ZeroMQ server: a broker in front of session worker processes.

The zguide's load-balancing broker, adapted to sessions that keep state: a
ROUTER faces the clients, and each worker process
(:mod:`controller_server.worker`) is reached over a Unix socket pair of its
own. A ``hello`` opens the client's session on a worker chosen by
:meth:`ControllerServer._place` (a client keeps to its share of the workers);
every later request of that session goes to the same worker. So serving uses
every core, and a slow session delays only the sessions of its own worker.
The broker polls the client socket and every worker's socket in one
``zmq.Poller``, and a request crosses it as it came (its bytes are not
decoded, only peeked at for ``type`` and ``seq`` by :func:`protocol.codec.peek`,
whose cost is bounded whatever the message's shape).

The broker never computes a tick. It enforces what a server in front of a
robot needs:

- **deadlines**: a request not answered within ``deadline_s`` of receipt is
  answered ``DEADLINE_EXCEEDED`` (the late reply is dropped); a worker still
  stuck ``recycle_after_s`` later is killed and replaced;
- **caps** (``LIMIT_EXCEEDED``): sessions per server and per client, requests
  in flight per session, message size;
- **the asset cache** (:mod:`controller_server.asset_cache`): it answers ``asset``
  uploads itself, and a ``hello`` naming files (``model_asset_hashes``) the client
  has not uploaded with ``ASSETS_MISSING``; the workers read the files from the
  cache's private directory, so an upload serves every worker;
- **identity**: a session belongs to the client's routing id *and* its CURVE
  key (or, without CURVE, its peer's IP address), so another peer reusing a
  routing id does not inherit it, and ``stats`` shows a client its own
  sessions. Without CURVE every client on one host is one client: the
  per-client cap and ``stats`` count them together;
- **expiry**: idle sessions are dropped and their memory returned.
"""

from __future__ import annotations

import gc
import itertools
import logging
import subprocess
import threading
import time
from typing import Any

import msgpack
import zmq

from controller_server.asset_cache import AssetCache
from controller_server.broker_setup import ServerStartError, enable_curve, start_worker
from controller_server.compiled import CompiledCoreUnavailable, load_core
from controller_server.config import ServeConfig
from controller_server.memory import return_large_buffers_to_the_system
from controller_server.routing import Gather, Pending, Route, WorkerRecord, error_of, error_reply
from controller_server.session_table import SessionTable
from controller_server.worker import REPLY_HEADER, REQUEST_HEADER
from protocol.codec import decode, encode, peek
from protocol.errors import AssetsMissing, ErrorCode, ProtocolError
from protocol.messages import Asset, Error, Hello, Message, SessionStats, Stats

__all__ = ["ControllerServer", "ServerStartError"]

log = logging.getLogger("poise.server")

POLL_INTERVAL_S = 0.05
WORKER_CHECK_INTERVAL_S = 0.1
"""How often the broker looks for dead workers (a system call per worker)."""
EXPIRY_CHECK_INTERVAL_S = 1.0
DRAIN_S = 1.0
"""After SIGTERM, requests already received are still answered for this long."""
WORKER_START_TIMEOUT_S = 120.0
MAX_WORKER_BACKLOG_BYTES = 256 * 1024 * 1024
"""Bytes queued for a worker that does not read (stuck) beyond which requests are refused."""
_POLLIN, _POLLOUT, _POLLERR = int(zmq.POLLIN), int(zmq.POLLOUT), int(zmq.POLLERR)
"""Plain ints: pyzmq's flags are enums, and combining them costs an enum call each."""
DEADLINE_DETAIL = (
    "not served within the server's deadline (`poise serve --deadline`); "
    "nothing was computed for it that can reach an actuator"
)


class ControllerServer:
    """Serve controllers to many clients over ZeroMQ, sessions in worker processes.

    Args:
        config: Endpoints, workers, deadlines, caps, model directories, keys.

    Raises:
        ServerStartError: A key file is unreadable, an endpoint cannot be bound, or the
            compiled core (the controllers' default ``kernel``) cannot be imported.
    """

    def __init__(self, config: ServeConfig):
        try:  # a broken build fails here, in one line, not at a session's first tick
            load_core()
        except CompiledCoreUnavailable as error:
            raise ServerStartError(str(error)) from None
        return_large_buffers_to_the_system()  # a long message's buffers leave with it
        self.config = config
        self.stop_event = threading.Event()
        self.routes: dict[bytes, Route] = {}
        self.workers: dict[bytes, WorkerRecord] = {}
        self._workers_by_fd: dict[int, WorkerRecord] = {}
        self._serving = False
        self._gathers: dict[bytes, Gather] = {}
        self._ids = itertools.count(1)
        self._generation = itertools.count()
        self._next_worker_check_s = 0.0
        # Answers requests that have no session.
        self._local = SessionTable(max_message_bytes=config.max_message_bytes)
        self._assets: AssetCache | None = None
        self._context = zmq.Context()
        self._authenticator: Any = None
        self._frontend = self._context.socket(zmq.ROUTER)
        self._frontend.setsockopt(zmq.LINGER, 0)
        self._frontend.setsockopt(zmq.MAXMSGSIZE, 2 * config.max_message_bytes)
        # A peer that stalls mid-message holds that message's memory; heartbeats drop it.
        self._frontend.setsockopt(zmq.HEARTBEAT_IVL, int(config.heartbeat_interval_s * 1000))
        self._frontend.setsockopt(
            zmq.HEARTBEAT_TIMEOUT, int(config.stalled_message_timeout_s * 1000)
        )
        self._curve = config.curve_secret_key is not None
        if self._curve:
            self._enable_curve()
        self.bound_endpoints: list[str] = []
        self._poller = zmq.Poller()
        self._poller.register(self._frontend, zmq.POLLIN)
        try:
            for endpoint in config.endpoints:
                self._frontend.bind(endpoint)
                self.bound_endpoints.append(self._frontend.getsockopt_string(zmq.LAST_ENDPOINT))
        except zmq.ZMQError as exc:
            self.close()
            hint = ""
            if exc.errno == zmq.EADDRINUSE:
                hint = (
                    "; another process (another `poise serve`?) listens there: stop it, or "
                    "bind another port (port * picks a free one)"
                )
            raise ServerStartError(f"cannot bind {endpoint!r}: {exc}{hint}") from None
        self._assets = AssetCache(
            config.asset_cache_bytes,
            max_file_bytes=config.max_model_bytes,
            max_upload_bytes_per_client=config.max_upload_bytes_per_client,
            idle_timeout_s=config.session_timeout_s,
        )

    # ----------------------------------------------------------------- set-up

    def _enable_curve(self) -> None:
        self._authenticator = enable_curve(self._context, self._frontend, self.config)

    def start_workers(self) -> None:
        """Start every worker and wait until each is ready (warm: first replies are fast).

        Raises:
            ServerStartError: A worker exited or did not report ready in time.
        """
        for _ in range(self.config.workers):
            self._spawn_worker()
        deadline = time.monotonic() + WORKER_START_TIMEOUT_S
        while not all(worker.ready for worker in self.workers.values()):
            for worker in self.workers.values():
                if worker.process.poll() is not None:
                    raise ServerStartError(
                        f"worker {worker.identity.decode()} exited with {worker.process.returncode}"
                    )
            if time.monotonic() > deadline:
                raise ServerStartError("workers did not start in time")
            for fd, _ in self._poller.poll(100):
                if fd in self._workers_by_fd:
                    self._serve_worker(self._workers_by_fd[fd])

    @property
    def assets(self) -> AssetCache:
        """The asset cache (made once the endpoints are bound)."""
        if self._assets is None:
            raise RuntimeError("the server is closed")
        return self._assets

    def _spawn_worker(self) -> None:
        identity = f"w{next(self._generation)}".encode()
        worker = start_worker(identity, self.config, self.assets.directory)
        self.workers[identity] = worker
        self._workers_by_fd[worker.fd] = worker
        self._poller.register(worker.fd, _POLLIN)

    # ----------------------------------------------------------------- loop

    def serve_forever(self) -> None:
        """Serve until :attr:`stop_event` is set, drain for up to a second, then close."""
        last_expiry_check = time.monotonic()
        log.info("serving on %s", ", ".join(self.bound_endpoints))
        gc.freeze()  # what start-up made is never garbage: collections skip it
        self._serving = True
        try:
            while not self.stop_event.is_set():
                self._turn()
                now = time.monotonic()
                if now - last_expiry_check > EXPIRY_CHECK_INTERVAL_S:
                    self.expire_sessions(now)
                    last_expiry_check = now
            self._drain()
        finally:
            self.close()

    def _turn(self) -> None:
        frontend = False
        for socket_or_fd, event in self._poller.poll(self._poll_timeout_ms()):
            if socket_or_fd is self._frontend:
                frontend = True
                continue
            worker = self._workers_by_fd.get(socket_or_fd)
            if worker is None:
                continue
            if event & _POLLOUT:
                self._flush(worker)
            if event & (_POLLIN | _POLLERR):  # replies first: they free clients
                self._serve_worker(worker)
        if frontend:
            for _ in range(100):  # what has arrived, then look at the workers again
                self._serve_frontend()
                if not self._frontend.getsockopt(zmq.EVENTS) & _POLLIN:
                    break
        self._enforce_deadlines(time.monotonic())

    def _drain(self) -> None:
        """Answer what has arrived and what is in flight, for at most :data:`DRAIN_S`."""
        end = time.monotonic() + DRAIN_S
        while time.monotonic() < end:
            busy = any(w.pending for w in self.workers.values()) or self._gathers
            if not busy and not self._frontend.poll(0):
                break
            self._turn()
        for worker in self.workers.values():
            for pending in worker.pending.values():
                self._answer_late(pending, "the server is stopping")
        for request_id, gather in list(self._gathers.items()):
            gather.deadline_s = 0.0  # answered now, with what has come
            self._finish_gather(request_id)

    def _poll_timeout_ms(self) -> int:
        soonest = time.monotonic() + POLL_INTERVAL_S
        for worker in self.workers.values():
            for pending in worker.pending.values():
                if not pending.answered:
                    soonest = min(soonest, pending.deadline_s)
        return max(0, int((soonest - time.monotonic()) * 1000) + 1)

    # ----------------------------------------------------------------- clients

    def _serve_frontend(self) -> None:
        """Serve one client message (one has arrived)."""
        try:
            frames = self._frontend.recv_multipart(zmq.NOBLOCK, copy=False)
        except zmq.Again:
            return
        identity = frames[0].bytes
        if len(frames) != 2:
            detail = f"expected one frame per message, got {len(frames) - 1}"
            self._reply(identity, error_reply(-1, ErrorCode.MALFORMED, "", detail))
            return
        frame = frames[1]
        payload = frame.bytes
        try:
            client = (frame.get("User-Id") if self._curve else "") or frame.get("Peer-Address")
        except zmq.ZMQError:  # no such property on this transport (inproc)
            client = ""
        if len(payload) > self.config.max_message_bytes:
            self._reply(
                identity,
                error_reply(
                    -1,
                    ErrorCode.LIMIT_EXCEEDED,
                    "",
                    f"message of {len(payload)} bytes exceeds the server's limit of "
                    f"{self.config.max_message_bytes} (`poise serve --max-message-bytes`)",
                    max_message_bytes=self.config.max_message_bytes,
                ),
            )
            return
        self._route(identity, client, payload)

    def _route(self, identity: bytes, client: str, payload: bytes) -> None:
        kind, seq, by_hash, refusal = peek(payload)
        if refusal is not None:  # over a cap: answered here, never decoded anywhere
            self._reply(identity, error_of(refusal, self.config.max_message_bytes))
            return
        route = self.routes.get(identity)
        if route is not None and route.client != client:
            route = None  # another peer reusing this routing id: not its session
        if kind == "asset":
            self._reply(identity, self._receive_asset(identity, client, payload))
        elif kind == "hello":
            refusal = self._check_assets(client, payload) if by_hash else None
            if refusal is not None:
                self._reply(identity, refusal)
            else:
                self._open(identity, client, route, seq, payload)
        elif kind == "stats":
            self._gather_stats(identity, client, payload)
        elif route is not None:
            self._forward(identity, route, seq, payload, self.config.deadline_s)
        else:  # no session: the local table says what is wrong (NO_SESSION at least)
            self._reply(identity, self._local.handle(identity, payload))

    def _open(
        self, identity: bytes, client: str, route: Route | None, seq: int, payload: bytes
    ) -> None:
        now = time.monotonic()
        if route is None:
            refusal = self._session_cap_refusal(client)
            if refusal:
                self._reply(identity, error_reply(seq, ErrorCode.LIMIT_EXCEEDED, "", refusal))
                return
            if not self.workers:  # stopping: a recycled worker is not replaced
                self._reply(identity, error_reply(seq, ErrorCode.LIMIT_EXCEEDED, "", "stopping"))
                return
            worker = self._place(client)
            old = self.routes.pop(identity, None)
            if old is not None:  # a different peer's session on this routing id
                self._drop_route(identity, old)
            route = Route(next(self._ids).to_bytes(8, "little"), worker.identity, client, now)
            self.routes[identity] = route
            worker.routes.add(identity)
        self._forward(identity, route, seq, payload, self.config.hello_deadline_s)

    def _place(self, client: str) -> WorkerRecord:
        """The worker for a new session of ``client``.

        A client's sessions occupy at most ``workers_per_client`` workers (all but
        one by default): a client that opens a session per worker and floods them
        would otherwise leave a client arriving later only workers where it waits
        behind a tick of the flood's (non-preemptive), whereas on a worker of its own
        the operating system shares the cores between the processes. Within that,
        the worker with the fewest other clients' sessions, then the fewest
        sessions; ready workers first (a replacement still warming up gets the
        request queued).
        """
        others: dict[bytes, int] = {}
        held = set()
        for worker in self.workers.values():
            clients = [
                route.client for identity in worker.routes if (route := self.routes.get(identity))
            ]
            others[worker.identity] = sum(c != client for c in clients)
            if client in clients:
                held.add(worker.identity)
        candidates = [
            worker
            for worker in self.workers.values()
            if len(held) < self.config.workers_per_client or worker.identity in held
        ]
        return min(
            candidates,
            key=lambda w: (not w.ready, others[w.identity], len(w.routes), len(w.pending)),
        )

    def _receive_asset(self, identity: bytes, client: str, payload: bytes) -> Message:
        """The answer to an ``asset`` request: the cache's, or an error."""
        try:
            request = decode(payload, self.config.max_message_bytes)
            if not isinstance(request, Asset):  # a peeked type that was not the real one
                return self._local.handle(identity, payload)
            return self.assets.receive(identity, client, request)
        except ProtocolError as exc:
            return error_of(exc, self.config.max_message_bytes)
        except OSError as exc:  # the cache's disk: full, or gone
            log.error("asset cache: %s", exc)
            detail = f"the server cannot store the file now ({exc.strerror or exc}); retry later"
            return error_reply(-1, ErrorCode.LIMIT_EXCEEDED, "", detail)

    def _check_assets(self, client: str, payload: bytes) -> Error | None:
        """The refusal of a ``hello`` naming files by hash: invalid, or files missing.

        ``None``: every file is in the cache for this client; the worker serves it.
        """
        try:
            request = decode(payload, self.config.max_message_bytes)
        except ProtocolError as exc:
            return error_of(exc, self.config.max_message_bytes)
        if not isinstance(request, Hello) or not request.model_asset_hashes:
            return None
        missing = self.assets.missing(client, request.model_asset_hashes.values())
        if not missing:
            return None
        return error_of(AssetsMissing(missing, request.seq), self.config.max_message_bytes)

    def _session_cap_refusal(self, client: str) -> str:
        if len(self.routes) >= self.config.max_sessions:
            return (
                f"the server holds {len(self.routes)} sessions, its limit "
                "(`poise serve --max-sessions`); retry later"
            )
        own = sum(route.client == client for route in self.routes.values())
        if own >= self.config.max_sessions_per_client:
            return (
                f"this client holds {own} sessions, the limit per client "
                "(`poise serve --max-sessions-per-client`); close some with bye"
            )
        return ""

    def _forward(
        self, identity: bytes, route: Route, seq: int, payload: bytes, deadline_s: float
    ) -> None:
        worker = self.workers[route.worker]
        if route.in_flight >= self.config.max_in_flight:
            self._reply(
                identity,
                error_reply(
                    seq,
                    ErrorCode.LIMIT_EXCEEDED,
                    "",
                    f"{route.in_flight} requests of this session are still being served "
                    "(`poise serve --max-in-flight`); wait for their replies",
                ),
            )
            return
        now = time.monotonic()
        route.last_seen_s = now
        route.in_flight += 1
        request_id = next(self._ids).to_bytes(8, "little")
        worker.pending[request_id] = Pending(
            identity, seq, route, now + deadline_s, now + deadline_s + self.config.recycle_after_s
        )
        header = REQUEST_HEADER.pack(request_id, route.key, now + deadline_s, route.client_tag)
        if not self._to_worker(worker.identity, [b"req", header, payload]):
            self._answer_late(worker.pending.pop(request_id), "its worker cannot take it now")

    def _to_worker(self, identity: bytes, frames: list[bytes]) -> bool:
        """Send to a worker (held until it is ready); ``False`` if it cannot take it now."""
        worker = self.workers.get(identity)
        if worker is None:
            return False
        if not worker.ready:
            worker.backlog.append(frames)
            return True
        if len(worker.channel.outgoing) > MAX_WORKER_BACKLOG_BYTES:
            log.warning("worker %s does not read: request refused", identity.decode())
            return False
        try:
            worker.channel.send(frames)
        except OSError as exc:  # dead: it is replaced
            log.warning("worker %s unreachable: %s", identity.decode(), exc)
            return False
        self._poll_output(worker)
        return True

    def _flush(self, worker: WorkerRecord) -> None:
        try:
            worker.channel.flush()
        except OSError as exc:
            log.warning("worker %s unreachable: %s", worker.identity.decode(), exc)
            worker.channel.outgoing.clear()
        self._poll_output(worker)

    def _poll_output(self, worker: WorkerRecord) -> None:
        """Poll the worker's socket for output while bytes wait for it, else not."""
        writing = bool(worker.channel.outgoing)
        if writing != worker.writing:
            worker.writing = writing
            self._poller.modify(worker.fd, _POLLIN | (_POLLOUT if writing else 0))

    def _reply(self, identity: bytes, message: Message) -> None:
        self._send(identity, encode(message))

    def _send(self, identity: bytes, data: bytes) -> None:
        try:
            self._frontend.send_multipart([identity, data], zmq.NOBLOCK)
        except zmq.Again:
            log.warning("client's queue is full: reply dropped")

    # ----------------------------------------------------------------- workers

    def _serve_worker(self, worker: WorkerRecord) -> None:
        messages = worker.channel.receive()
        if messages is None:  # its end closed: it exited
            if self._serving:
                log.error("worker %s died (%s)", worker.identity.decode(), worker.process.poll())
                self._recycle(worker)
            else:  # start_workers reports it
                self._detach(worker)
            return
        for frames in messages:
            kind = frames[0]
            if kind == b"rep":
                request_id, session_open = REPLY_HEADER.unpack(frames[1])
                pending = worker.pending.pop(request_id, None)
                if pending is not None:
                    self._settle(pending, session_open, reply=frames[2])
            elif kind == b"ready":
                worker.ready = True
                log.info("worker %s ready", worker.identity.decode())
                backlog, worker.backlog = worker.backlog, []
                for message in backlog:
                    self._to_worker(worker.identity, message)
            elif kind == b"late":  # the worker skipped it: past its deadline before it started
                pending = worker.pending.pop(frames[1], None)
                if pending is not None:
                    self._answer_late(pending, DEADLINE_DETAIL)
            elif kind == b"stats":
                self._collect_stats(worker.identity, frames[1], frames[2])

    def _settle(self, pending: Pending, session_open: bool, reply: bytes) -> None:
        """Answer a worker's reply and keep the route in step with the worker's session.

        The last reply of a route decides: a session the worker closed (bye,
        refused hello) loses its route; one the worker opened for a route that
        is gone meanwhile is dropped, so no session lives on without a route.
        A reply that comes back past its deadline is answered
        ``DEADLINE_EXCEEDED`` as if the broker had woken in time: whether a
        late command reaches the client never depends on how busy the
        machine is.
        """
        if time.monotonic() > pending.deadline_s:
            self._answer_late(pending, DEADLINE_DETAIL)
        self._answer(pending, reply)
        current = self.routes.get(pending.identity) is pending.route
        if session_open and not current:
            self._to_worker(pending.route.worker, [b"drop", pending.route.key])
        elif not session_open and current and pending.route.in_flight == 0:
            self._unroute(pending.identity, pending.route)

    def _answer(self, pending: Pending, data: bytes) -> None:
        """Send the one answer a request gets (reply or error); later ones are dropped."""
        if not pending.answered:
            pending.answered = True
            pending.route.in_flight -= 1
            self._send(pending.identity, data)

    def _enforce_deadlines(self, now: float) -> None:
        for worker in list(self.workers.values()):
            for pending in worker.pending.values():
                if not pending.answered and now > pending.deadline_s:
                    self._answer_late(pending, DEADLINE_DETAIL)
            first = next(iter(worker.pending.values()), None)
            if first is not None and now > first.recycle_s:
                self._recycle(worker)
            elif now > self._next_worker_check_s and worker.process.poll() is not None:
                log.error(
                    "worker %s died (%s)", worker.identity.decode(), worker.process.returncode
                )
                self._recycle(worker)
        if now > self._next_worker_check_s:
            self._next_worker_check_s = now + WORKER_CHECK_INTERVAL_S
        for request_id in [rid for rid, g in self._gathers.items() if now > g.deadline_s]:
            self._finish_gather(request_id)

    def _answer_late(self, pending: Pending, detail: str) -> None:
        if not pending.answered:
            self._answer(
                pending, encode(error_reply(pending.seq, ErrorCode.DEADLINE_EXCEEDED, "", detail))
            )

    def _recycle(self, worker: WorkerRecord) -> None:
        """Kill a stuck or dead worker, forget its sessions, start a fresh one."""
        log.warning(
            "worker %s stuck or dead: replaced; its %d sessions are lost",
            worker.identity.decode(),
            len(worker.routes),
        )
        worker.process.kill()
        worker.process.wait()
        self._detach(worker)
        worker.channel.close()
        for pending in worker.pending.values():
            self._answer_late(pending, "the worker serving this session failed; send hello")
        for identity in list(worker.routes):
            route = self.routes.get(identity)
            if route is not None and route.worker == worker.identity:
                self._unroute(identity, route)
        del self.workers[worker.identity]
        for request_id, gather in list(self._gathers.items()):
            if worker.identity in gather.waiting:
                gather.waiting.discard(worker.identity)
                self._finish_gather(request_id)
        if not self.stop_event.is_set():
            self._spawn_worker()

    def _detach(self, worker: WorkerRecord) -> None:
        """Stop polling the worker's socket."""
        if self._workers_by_fd.get(worker.fd) is worker:
            self._poller.unregister(worker.fd)
            del self._workers_by_fd[worker.fd]

    # ----------------------------------------------------------------- sessions

    def _unroute(self, identity: bytes, route: Route) -> None:
        if self.routes.get(identity) is route:
            del self.routes[identity]
        worker = self.workers.get(route.worker)
        if worker is not None:
            worker.routes.discard(identity)

    def _drop_route(self, identity: bytes, route: Route) -> None:
        self._unroute(identity, route)
        if route.worker in self.workers:
            self._to_worker(route.worker, [b"drop", route.key])

    def expire_sessions(self, now_s: float) -> int:
        """Drop sessions idle longer than the timeout (none in flight); return how many.

        Each worker gets one ``drop`` with all its expired keys, so it returns
        their memory in one pass.
        """
        expired: dict[bytes, list[bytes]] = {}
        for identity, route in list(self.routes.items()):
            if route.in_flight == 0 and now_s - route.last_seen_s > self.config.session_timeout_s:
                self._unroute(identity, route)
                expired.setdefault(route.worker, []).append(route.key)
        for worker, keys in expired.items():
            if worker in self.workers:
                self._to_worker(worker, [b"drop", *keys])
        count = sum(map(len, expired.values()))
        if count:
            log.info("%d sessions expired", count)
        if self._assets is not None and self._assets.expire(now_s):
            log.info("idle asset uploads dropped")
        return count

    def _gather_stats(self, identity: bytes, client: str, payload: bytes) -> None:
        # The session-less table checks the request as a worker would: a valid one
        # comes back as an empty ``stats``, anything else as the error to send.
        request = self._local.handle(identity, payload)
        if not isinstance(request, Stats):
            self._reply(identity, request)
            return
        if any(gather.identity == identity for gather in self._gathers.values()):
            detail = "a stats request of this client is still being answered; wait for it"
            self._reply(identity, error_reply(request.seq, ErrorCode.LIMIT_EXCEEDED, "", detail))
            return
        visible: dict[bytes, list[bytes]] = {}
        for route in self.routes.values():
            if self.config.stats_all or route.client == client:
                visible.setdefault(route.worker, []).append(route.key)
        request_id = next(self._ids).to_bytes(8, "little")
        gather = Gather(
            identity, request.seq, time.monotonic() + self.config.deadline_s, set(visible)
        )
        self._gathers[request_id] = gather
        for worker, keys in visible.items():
            self._to_worker(worker, [b"stats", request_id, *keys])
        self._finish_gather(request_id)

    def _collect_stats(self, worker: bytes, request_id: bytes, data: bytes) -> None:
        gather = self._gathers.get(request_id)
        if gather is None or worker not in gather.waiting:
            return
        gather.waiting.discard(worker)
        gather.sessions += [SessionStats.model_validate(s) for s in msgpack.unpackb(data)]
        self._finish_gather(request_id)

    def _finish_gather(self, request_id: bytes) -> None:
        gather = self._gathers[request_id]
        if gather.waiting and time.monotonic() < gather.deadline_s:
            return
        del self._gathers[request_id]
        if gather.waiting:
            self._reply(
                gather.identity,
                error_reply(gather.seq, ErrorCode.DEADLINE_EXCEEDED, "", "a worker did not report"),
            )
        else:
            self._reply(gather.identity, Stats(seq=gather.seq, sessions=gather.sessions))

    # ----------------------------------------------------------------- shutdown

    def close(self) -> None:
        """Stop the workers, close the sockets and the ZeroMQ context."""
        for worker in self.workers.values():
            if worker.ready and worker.process.poll() is None:
                try:
                    worker.channel.send([b"stop"])
                except OSError:
                    pass
            self._detach(worker)
            worker.channel.close()  # a worker still warming up reads EOF and exits
        for worker in self.workers.values():
            try:
                worker.process.wait(2.0)
            except subprocess.TimeoutExpired:
                worker.process.kill()
                worker.process.wait()
        self.workers.clear()
        self._workers_by_fd.clear()
        if self._authenticator is not None:
            self._authenticator.stop()
        self._frontend.close(linger=0)
        self._context.term()
        if self._assets is not None:
            self._assets.close()
            self._assets = None
