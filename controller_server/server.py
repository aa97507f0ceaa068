"""The ZeroMQ server: a broker in front of session worker processes.

The zguide's load-balancing broker, adapted to sessions that keep state: a
ROUTER faces the clients, and each worker process
(:mod:`controller_server.worker`, started and replaced by
:mod:`controller_server.worker_pool`) is reached over a Unix socket pair of its
own. A ``hello`` opens the client's session on a worker chosen by
:func:`controller_server.routing.place` (a client keeps to its share of the
workers); every later request of that session goes to the same worker. So
serving uses every core, and a slow session delays only the sessions of its own
worker. The broker polls the client socket and every worker's socket in one
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
  has not uploaded with ``ASSETS_MISSING`` (:mod:`controller_server.asset_requests`);
  the workers read the files from the cache's private directory, so an upload
  serves every worker;
- **identity**: a session belongs to the client's routing id *and* its CURVE
  key (or, without CURVE, its peer's IP address), so another peer reusing a
  routing id does not inherit it, and ``stats`` shows a client its own
  sessions (gathered from every worker, :mod:`controller_server.stats_gather`).
  Without CURVE every client on one host is one client: the per-client cap and
  ``stats`` count them together;
- **expiry**: idle sessions are dropped and their memory returned.
"""

from __future__ import annotations

import gc
import itertools
import logging
import threading
import time
from typing import Any

import zmq

from controller_server.asset_cache import AssetCache
from controller_server.asset_requests import check_assets, receive_asset
from controller_server.broker_setup import ServerStartError, enable_curve
from controller_server.compiled import CompiledCoreUnavailable, load_core
from controller_server.config import ServeConfig
from controller_server.memory import return_large_buffers_to_the_system
from controller_server.routing import Pending, Route, WorkerRecord, error_of, error_reply, place
from controller_server.session_table import SessionTable
from controller_server.stats_gather import StatsGathers
from controller_server.worker import REPLY_HEADER, REQUEST_HEADER
from controller_server.worker_pool import WorkerPool
from protocol.codec import encode, peek
from protocol.errors import ErrorCode
from protocol.messages import Error, Message

__all__ = ["ControllerServer", "ServerStartError"]

log = logging.getLogger("poise.server")

POLL_INTERVAL_S = 0.05
EXPIRY_CHECK_INTERVAL_S = 1.0
DRAIN_S = 1.0
"""After SIGTERM, requests already received are still answered for this long."""
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
        self._serving = False
        self._ids = itertools.count(1)
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
        self._pool = WorkerPool(config, self._poller)
        self.workers = self._pool.workers
        self._stats = StatsGathers(config, self._local, self._ids, self._pool.send, self._reply)
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
            self._pool.spawn(self.assets.directory)
        self._pool.wait_ready(self._serve_worker)

    @property
    def assets(self) -> AssetCache:
        """The asset cache (made once the endpoints are bound)."""
        if self._assets is None:
            raise RuntimeError("the server is closed")
        return self._assets

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
            worker = self._pool.by_fd.get(socket_or_fd)
            if worker is None:
                continue
            if event & _POLLOUT:
                self._pool.flush(worker)
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
            busy = any(w.pending for w in self.workers.values()) or self._stats.gathers
            if not busy and not self._frontend.poll(0):
                break
            self._turn()
        for worker in self.workers.values():
            for pending in worker.pending.values():
                self._answer_late(pending, "the server is stopping")
        self._stats.answer_now()

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
            self._stats.start(identity, client, payload, self.routes.values())
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
            worker = place(
                self.workers.values(), self.routes, client, self.config.workers_per_client
            )
            old = self.routes.pop(identity, None)
            if old is not None:  # a different peer's session on this routing id
                self._drop_route(identity, old)
            route = Route(next(self._ids).to_bytes(8, "little"), worker.identity, client, now)
            self.routes[identity] = route
            worker.routes.add(identity)
        self._forward(identity, route, seq, payload, self.config.hello_deadline_s)

    def _receive_asset(self, identity: bytes, client: str, payload: bytes) -> Message:
        limit = self.config.max_message_bytes
        return receive_asset(self.assets, self._local, identity, client, payload, limit)

    def _check_assets(self, client: str, payload: bytes) -> Error | None:
        return check_assets(self.assets, client, payload, self.config.max_message_bytes)

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
        if not self._pool.send(worker.identity, [b"req", header, payload]):
            self._answer_late(worker.pending.pop(request_id), "its worker cannot take it now")

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
                self._pool.detach(worker)
            return
        for frames in messages:
            kind = frames[0]
            if kind == b"rep":
                request_id, session_open = REPLY_HEADER.unpack(frames[1])
                pending = worker.pending.pop(request_id, None)
                if pending is not None:
                    self._settle(pending, session_open, reply=frames[2])
            elif kind == b"ready":
                self._pool.ready(worker)
            elif kind == b"late":  # the worker skipped it: past its deadline before it started
                pending = worker.pending.pop(frames[1], None)
                if pending is not None:
                    self._answer_late(pending, DEADLINE_DETAIL)
            elif kind == b"stats":
                self._stats.collect(worker.identity, frames[1], frames[2])

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
            self._pool.send(pending.route.worker, [b"drop", pending.route.key])
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
            elif self._pool.exited(worker, now):
                self._recycle(worker)
        self._pool.checked(now)
        self._stats.expire(now)

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
        self._pool.kill(worker)
        for pending in worker.pending.values():
            self._answer_late(pending, "the worker serving this session failed; send hello")
        for identity in list(worker.routes):
            route = self.routes.get(identity)
            if route is not None and route.worker == worker.identity:
                self._unroute(identity, route)
        self._stats.worker_lost(worker.identity)
        if not self.stop_event.is_set():
            self._pool.spawn(self.assets.directory)

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
            self._pool.send(route.worker, [b"drop", route.key])

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
                self._pool.send(worker, [b"drop", *keys])
        count = sum(map(len, expired.values()))
        if count:
            log.info("%d sessions expired", count)
        if self._assets is not None and self._assets.expire(now_s):
            log.info("idle asset uploads dropped")
        return count

    # ----------------------------------------------------------------- shutdown

    def close(self) -> None:
        """Stop the workers, close the sockets and the ZeroMQ context."""
        self._pool.stop()
        if self._authenticator is not None:
            self._authenticator.stop()
        self._frontend.close(linger=0)
        self._context.term()
        if self._assets is not None:
            self._assets.close()
            self._assets = None
