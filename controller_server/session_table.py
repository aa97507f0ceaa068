"""The sessions of one worker process and the answer to each request.

A :class:`SessionTable` turns the bytes of one request, for the session
named by an opaque key, into one reply message. It never raises for bad
input: every problem becomes a typed ``error`` naming the field. ``hello``
creates (or replaces) the key's session, ``state`` → ``command``,
``set_params`` → ``params``, ``stats`` → ``stats``, ``bye`` closes the
session. Which client a key belongs to, caps, deadlines and expiry are the
broker's business (:mod:`controller_server.server`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING

from protocol.codec import decode
from protocol.errors import ErrorCode, ProtocolError
from protocol.messages import Bye, Error, Hello, Message, SessionStats, SetParams, State, Stats

if TYPE_CHECKING:
    from controller_server.session import Session

__all__ = ["SessionTable", "release_free_memory"]

log = logging.getLogger("poise.server")


def _load_libc_trim():  # type: ignore[no-untyped-def]
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):
        return None  # not glibc


_MALLOC_TRIM = _load_libc_trim()


def release_free_memory() -> None:
    """Collect cycles and hand freed heap pages back to the OS (glibc ``malloc_trim``).

    Without it a process that once held 500 sessions keeps their pages after
    they are dropped: glibc returns memory only from the top of the heap.
    """
    gc.collect()
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


class SessionTable:
    """Sessions by key, and the request handling of one process.

    Args:
        max_model_bytes: Largest ``hello.model_text`` accepted (bytes of UTF-8).
    """

    def __init__(self, max_model_bytes: int = 4 * 1024 * 1024):
        self.max_model_bytes = max_model_bytes
        self.sessions: dict[bytes, Session] = {}

    def handle(self, key: bytes, payload: bytes) -> Message:
        """Answer one request for session ``key``; never raises for bad input."""
        seq = -1
        try:
            request = decode(payload)
            seq = request.seq
            return self._dispatch(key, request)
        except ProtocolError as exc:
            session = self.sessions.get(key)
            if session is not None:
                session.errors += 1
            return Error(
                seq=exc.seq if exc.seq >= 0 else seq,
                code=exc.code,
                field=exc.field,
                detail=exc.detail,
            )
        except Exception as exc:  # a controller bug must not take the server down
            log.exception("internal error while serving a request")
            return Error(seq=seq, code=ErrorCode.INTERNAL, detail=f"{type(exc).__name__}: {exc}")

    def drop(self, keys: Iterable[bytes]) -> int:
        """Forget these sessions (expired, replaced, or closed elsewhere); return how many."""
        dropped = sum(self.sessions.pop(key, None) is not None for key in keys)
        if dropped:
            release_free_memory()
        return dropped

    def session_stats(self, keys: Iterable[bytes] | None = None) -> list[SessionStats]:
        """Counters of the given sessions (all if ``None``) that live here."""
        now = time.monotonic()
        chosen = self.sessions.values() if keys is None else map(self.sessions.get, keys)
        return [session.stats(now) for session in chosen if session is not None]

    def _open(self, key: bytes, request: Hello) -> Message:
        text = request.model_text
        if text is not None and len(text.encode()) > self.max_model_bytes:
            raise ProtocolError(
                ErrorCode.LIMIT_EXCEEDED,
                "model_text",
                f"model text of {len(text.encode())} bytes exceeds the server's limit of "
                f"{self.max_model_bytes} bytes (`poise serve --max-model-bytes`)",
                request.seq,
            )
        # Imported here: the broker keeps a table without sessions to answer requests
        # that have none, and never loads Pinocchio or a controller.
        from controller_server.session import Session

        try:
            session = Session(request)
        except ProtocolError as exc:
            exc.seq = request.seq
            raise
        replaced = self.sessions.get(key)
        self.sessions[key] = session
        if replaced is not None:
            del replaced
            release_free_memory()
        log.info(
            "session %s: model %s, controller %s",
            session.session_id[:8],
            session.robot.name,
            session.controller.name,
        )
        return session.welcome(request.seq)

    def _dispatch(self, key: bytes, request: Message) -> Message:
        if isinstance(request, Hello):
            return self._open(key, request)  # a refused hello keeps the session it had
        if isinstance(request, Stats):
            if request.sessions is not None:
                raise ProtocolError(
                    ErrorCode.UNEXPECTED_MESSAGE,
                    "sessions",
                    "a stats request carries no sessions",
                    request.seq,
                )
            return Stats(seq=request.seq, sessions=self.session_stats())
        if not isinstance(request, State | SetParams | Bye):
            raise ProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE,
                "type",
                f"{request.type!r} is a reply; send hello, state, set_params, stats or bye",
                request.seq,
            )
        session = self.sessions.get(key)
        if session is None:
            raise ProtocolError(
                ErrorCode.NO_SESSION,
                "type",
                "no session for this client (never opened, expired or closed): send hello",
                request.seq,
            )
        session.last_seen_s = time.monotonic()
        if isinstance(request, Bye):
            self.drop([key])
            return Bye(seq=request.seq)
        try:
            if isinstance(request, State):
                return session.step(request)
            return session.set_params(request)
        except ProtocolError as exc:
            exc.seq = request.seq
            raise
