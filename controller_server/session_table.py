"""The sessions of one worker process and the answer to each request.

A :class:`SessionTable` turns the bytes of one request, for the session
named by an opaque key, into one reply message. It never raises for bad
input: every problem becomes a typed ``error`` naming the field. ``hello``
creates (or replaces) the key's session, ``state`` → ``command``,
``set_params`` → ``params``, ``stats`` → ``stats``, ``bye`` closes the
session. The server's own errors (:mod:`controller_server.errors`) become
wire codes here, at the edge. Which client a key belongs to, caps, deadlines
and expiry are the broker's business (:mod:`controller_server.server`).

A ``hello`` naming files by hash (``model_asset_hashes``) takes them from the
broker's asset cache (:mod:`controller_server.asset_cache`), each hashed again
as it is read; one that is not there is ``ASSETS_MISSING``.

With a ``record_dir``, every session's conversation (the requests it
received, the replies it sent) is recorded to its own MCAP file, opened by
its ``hello`` and closed when the session ends (:mod:`protocol.recording`).
Its ``hello`` is recorded with every file inline (``model_assets``), so the
log replays on a server that never saw them.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from controller_server.asset_cache import read_asset
from controller_server.errors import ServerFault, wire_code
from protocol.codec import MAX_MESSAGE_BYTES, decode
from protocol.errors import AssetsMissing, ErrorCode, ProtocolError
from protocol.messages import (
    Asset,
    Bye,
    Error,
    Hello,
    Message,
    SessionStats,
    SetParams,
    State,
    Stats,
)

if TYPE_CHECKING:
    from controller_server.session import Session
    from protocol.recording import Recorder

__all__ = ["DEFAULT_TICK_BUDGET_S", "SessionTable", "release_free_memory"]

log = logging.getLogger("poise.server")

DEFAULT_TICK_BUDGET_S = 0.5
"""Tick budget of a table not told the server's deadline (``poise serve --deadline``'s default)."""


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
    Objects a worker froze (:func:`gc.freeze`) are collected too, and the
    survivors frozen again.
    """
    frozen = gc.get_freeze_count()
    if frozen:
        gc.unfreeze()
    gc.collect()
    if frozen:
        gc.freeze()
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


class SessionTable:
    """Sessions by key, and the request handling of one process.

    Args:
        max_model_bytes: Largest ``hello.model_text`` (bytes of UTF-8) and file of
            ``hello.model_assets`` accepted.
        record_dir: Record each session to ``<UTC time>-<session id>.mcap`` here.
        max_message_bytes: Largest request decoded (the broker refuses larger ones first).
        asset_dir: The broker's asset cache, where ``hello.model_asset_hashes`` are
            looked up (``None``: every such file is missing).
        tick_budget_s: Longest a session's tick may take, the server's deadline
            (``ServeConfig.deadline_s``): a ``hello`` whose tick, timed on the standing
            state, would not fit is refused ``LIMIT_EXCEEDED``
            (:meth:`Session.__init__ <controller_server.session.Session>`); ``None``:
            ticks are not timed at ``hello``.
    """

    def __init__(
        self,
        max_model_bytes: int = 4 * 1024 * 1024,
        record_dir: str | Path | None = None,
        *,
        max_message_bytes: int = MAX_MESSAGE_BYTES,
        asset_dir: str | Path | None = None,
        tick_budget_s: float | None = DEFAULT_TICK_BUDGET_S,
    ):
        self.max_model_bytes = max_model_bytes
        self.tick_budget_s = tick_budget_s
        self.max_message_bytes = max_message_bytes
        self.asset_dir = asset_dir
        self.record_dir = None if record_dir is None else Path(record_dir)
        self.sessions: dict[bytes, Session] = {}
        self.recorders: dict[bytes, Recorder] = {}
        self.sessions_opened = 0
        """Sessions created so far (a worker freezes what a new one holds, see its docs)."""

    def handle(self, key: bytes, payload: bytes) -> Message:
        """Answer one request for session ``key``; never raises for bad input."""
        received_ns = time.time_ns()
        request, reply = self._answer(key, payload)
        recorder = self.recorders.get(key)
        if recorder is not None:
            if request is not None:
                recorder.record(request, "received", received_ns)
            recorder.record(reply, "sent")
        if isinstance(request, Bye) and isinstance(reply, Bye):
            self.drop([key])
        return reply

    def _answer(self, key: bytes, payload: bytes) -> tuple[Message | None, Message]:
        """The decoded request (``None`` if it does not decode) and the reply.

        A ``hello`` comes back with the files it named by hash inline.
        """
        seq = -1
        request = None
        try:
            request = decode(payload, self.max_message_bytes)
            seq = request.seq
            if isinstance(request, Hello) and request.model_asset_hashes:
                request = self._with_files_inline(request)
            return request, self._dispatch(key, request)
        except ProtocolError as exc:  # the request itself is malformed
            self._count_error(key)
            missing = exc.missing if isinstance(exc, AssetsMissing) else None
            error = Error(
                seq=exc.seq if exc.seq >= 0 else seq,
                code=exc.code,
                field=exc.field,
                detail=exc.detail,
                missing_asset_hashes=missing,
                max_message_bytes=self.max_message_bytes if missing is not None else None,
            )
            return request, error
        except ServerFault as exc:  # the server cannot serve it: mapped to a wire code here
            self._count_error(key)
            return request, Error(seq=seq, code=wire_code(exc), field=exc.field, detail=exc.detail)
        except Exception as exc:  # a controller bug must not take the server down
            log.exception("internal error while serving a request")
            error = Error(seq=seq, code=ErrorCode.INTERNAL, detail=f"{type(exc).__name__}: {exc}")
            return request, error

    def _with_files_inline(self, hello: Hello) -> Hello:
        """``hello`` with the files of ``model_asset_hashes`` read into ``model_assets``.

        Raises:
            AssetsMissing: A file is not in the asset cache (evicted since the broker
                looked, or no cache).
        """
        files = dict(hello.model_assets or {})
        missing = []
        for path, sha256 in (hello.model_asset_hashes or {}).items():
            data = read_asset(self.asset_dir, sha256)
            if data is None:
                missing.append(sha256)
            else:
                files[path] = data
        if missing:
            raise AssetsMissing(missing, hello.seq)
        return hello.model_copy(update={"model_assets": files, "model_asset_hashes": None})

    def _count_error(self, key: bytes) -> None:
        session = self.sessions.get(key)
        if session is not None:
            session.errors += 1

    def drop(self, keys: Iterable[bytes]) -> int:
        """Forget these sessions (expired, replaced, closed) and close their logs; how many."""
        dropped = 0
        for key in keys:
            dropped += self.sessions.pop(key, None) is not None
            self._stop_recording(key)
        if dropped:
            release_free_memory()
        return dropped

    def close(self) -> None:
        """Close every session's log (the worker stops)."""
        for key in list(self.recorders):
            self._stop_recording(key)

    def _start_recording(self, key: bytes, session: Session) -> None:
        self._stop_recording(key)
        if self.record_dir is None:
            return
        from protocol.recording import Recorder

        started = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        path = self.record_dir / f"{started}-{session.session_id[:8]}.mcap"
        try:
            self.recorders[key] = Recorder(path)
        except OSError as exc:  # the session goes on unrecorded
            log.error("cannot record session %s to %s: %s", session.session_id[:8], path, exc)

    def _stop_recording(self, key: bytes) -> None:
        recorder = self.recorders.pop(key, None)
        if recorder is not None:
            recorder.close()
            if recorder.dropped:
                log.warning("%s: %d messages were not recorded", recorder.path, recorder.dropped)

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
        for path, data in (request.model_assets or {}).items():
            if len(data) > self.max_model_bytes:
                raise ProtocolError(
                    ErrorCode.LIMIT_EXCEEDED,
                    "model_assets",
                    f"file {path[:100]!r} of {len(data)} bytes exceeds the server's limit of "
                    f"{self.max_model_bytes} bytes per file (`poise serve --max-model-bytes`)",
                    request.seq,
                )
        # Imported here: the broker keeps a table without sessions to answer requests
        # that have none, and never loads Pinocchio or a controller.
        from controller_server.models.description import MAX_ASSET_BYTES
        from controller_server.session import Session

        total = sum(len(data) for data in (request.model_assets or {}).values())
        if total > MAX_ASSET_BYTES:  # what the model may read of them: refused before parsing
            raise ProtocolError(
                ErrorCode.LIMIT_EXCEEDED,
                "model_assets",
                f"the files sent with the model hold {total} bytes; a model may read at most "
                f"{MAX_ASSET_BYTES} bytes of files (docs/serving.md)",
                request.seq,
            )
        try:
            session = Session(request, self.tick_budget_s)
        except ProtocolError as exc:
            exc.seq = request.seq
            raise
        replaced = self.sessions.get(key)
        self.sessions[key] = session
        self.sessions_opened += 1
        self._start_recording(key, session)
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
                (
                    "asset uploads are answered by the server (`poise serve`), not by a "
                    "session table"
                    if isinstance(request, Asset)
                    else f"{request.type!r} is a reply; send hello, state, set_params, stats or bye"
                ),
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
            return Bye(seq=request.seq)  # handle() drops the session once the bye is recorded
        try:
            if isinstance(request, State):
                return session.step(request)
            return session.set_params(request)
        except ProtocolError as exc:
            exc.seq = request.seq
            raise
