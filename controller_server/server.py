"""The ZeroMQ ROUTER server: one session per client identity.

Every request frame is decoded at the edge (:func:`protocol.decode`); every
problem becomes a typed ``error`` reply naming the field, and no request can
stop the loop or disturb another session. ``hello`` creates (or replaces)
the sender's session, ``state`` → ``command``, ``set_params`` → ``params``,
``stats`` → ``stats``, ``bye`` closes the session. Sessions idle longer than
``session_timeout_s`` expire.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence

import zmq

from controller_server.session import Session
from protocol.codec import MAX_MESSAGE_BYTES, decode, encode
from protocol.errors import ErrorCode, ProtocolError
from protocol.messages import Bye, Error, Hello, Message, SetParams, State, Stats

__all__ = ["ControllerServer"]

log = logging.getLogger("poise.server")

POLL_INTERVAL_MS = 100
EXPIRY_CHECK_INTERVAL_S = 1.0


class ControllerServer:
    """Serve controllers to many clients over ZeroMQ.

    Args:
        endpoints: ZeroMQ endpoints to bind, e.g. ``tcp://127.0.0.1:5555`` or
            ``ipc:///tmp/poise.sock``.
        session_timeout_s: Idle time after which a session is dropped.
    """

    def __init__(self, endpoints: Sequence[str], session_timeout_s: float = 30.0):
        self.endpoints = list(endpoints)
        self.session_timeout_s = session_timeout_s
        self.sessions: dict[bytes, Session] = {}
        self.stop_event = threading.Event()
        self._context = zmq.Context()
        self._socket = self._context.socket(zmq.ROUTER)
        self._socket.setsockopt(zmq.LINGER, 0)
        self._socket.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES + 1024)
        self.bound_endpoints: list[str] = []
        for endpoint in self.endpoints:
            self._socket.bind(endpoint)
            self.bound_endpoints.append(self._socket.getsockopt_string(zmq.LAST_ENDPOINT))

    def handle(self, identity: bytes, payload: bytes) -> Message:
        """Answer one request from ``identity``; never raises for bad input."""
        seq = -1
        try:
            request = decode(payload)
            seq = request.seq
            return self._dispatch(identity, request)
        except ProtocolError as exc:
            session = self.sessions.get(identity)
            if session is not None:
                session.errors += 1
            return Error(
                seq=exc.seq if exc.seq >= 0 else seq,
                code=exc.code,
                field=exc.field,
                detail=exc.detail,
            )
        except Exception as exc:  # a controller bug must not take the server down
            log.exception("internal error while serving %r", identity)
            return Error(seq=seq, code=ErrorCode.INTERNAL, detail=f"{type(exc).__name__}: {exc}")

    def _dispatch(self, identity: bytes, request: Message) -> Message:
        if isinstance(request, Hello):
            try:
                session = Session(request)
            except ProtocolError as exc:
                exc.seq = request.seq
                raise
            self.sessions[identity] = session
            log.info(
                "session %s: model %s, controller %s",
                session.session_id[:8],
                session.robot.name,
                session.controller.name,
            )
            return session.welcome(request.seq)
        if isinstance(request, Stats):
            if request.sessions is not None:
                raise ProtocolError(
                    ErrorCode.UNEXPECTED_MESSAGE,
                    "sessions",
                    "a stats request carries no sessions",
                    request.seq,
                )
            now = time.monotonic()
            return Stats(seq=request.seq, sessions=[s.stats(now) for s in self.sessions.values()])
        if not isinstance(request, State | SetParams | Bye):
            raise ProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE,
                "type",
                f"{request.type!r} is a reply; send hello, state, set_params, stats or bye",
                request.seq,
            )
        session = self.sessions.get(identity)
        if session is None:
            raise ProtocolError(
                ErrorCode.NO_SESSION,
                "type",
                "no session for this client: send hello first",
                request.seq,
            )
        session.last_seen_s = time.monotonic()
        if isinstance(request, Bye):
            del self.sessions[identity]
            return Bye(seq=request.seq)
        try:
            if isinstance(request, State):
                return session.step(request)
            return session.set_params(request)
        except ProtocolError as exc:
            exc.seq = request.seq
            raise

    def expire_sessions(self, now_s: float) -> list[str]:
        """Drop sessions idle longer than the timeout; return their ids."""
        expired = [
            identity
            for identity, session in self.sessions.items()
            if now_s - session.last_seen_s > self.session_timeout_s
        ]
        for identity in expired:
            log.info("session %s expired", self.sessions[identity].session_id[:8])
        return [self.sessions.pop(identity).session_id for identity in expired]

    def serve_forever(self) -> None:
        """Serve until :attr:`stop_event` is set, then close the socket."""
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        last_expiry_check = time.monotonic()
        log.info("serving on %s", ", ".join(self.bound_endpoints))
        try:
            while not self.stop_event.is_set():
                if poller.poll(POLL_INTERVAL_MS):
                    self._serve_one()
                now = time.monotonic()
                if now - last_expiry_check > EXPIRY_CHECK_INTERVAL_S:
                    self.expire_sessions(now)
                    last_expiry_check = now
        finally:
            self.close()

    def _serve_one(self) -> None:
        frames = self._socket.recv_multipart(copy=True)
        identity, body = frames[0], frames[1:]
        if len(body) != 1:
            reply: Message = Error(
                code=ErrorCode.MALFORMED, detail=f"expected one frame per message, got {len(body)}"
            )
        else:
            reply = self.handle(identity, body[0])
        self._socket.send_multipart([identity, encode(reply)])

    def close(self) -> None:
        """Close the socket and the ZeroMQ context."""
        self._socket.close(linger=0)
        self._context.term()
