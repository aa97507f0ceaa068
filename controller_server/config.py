"""What ``poise serve`` is told: endpoints, workers, deadlines, caps, files, keys.

One frozen record, built by the CLI (or by code), handed to the broker and,
as JSON, to every worker process.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

from controller_server.blas import BLAS_THREAD_VARIABLES
from protocol.codec import MAX_MESSAGE_BYTES

__all__ = ["MIN_MESSAGE_BYTES", "SINGLE_THREADED_BLAS", "ServeConfig"]

MIN_MESSAGE_BYTES = 64 * 1024
"""Smallest ``max_message_bytes``: a state of a large robot and an ``asset`` chunk of
useful size (the client leaves a few kB of the cap to the message around the chunk) fit."""

SINGLE_THREADED_BLAS = BLAS_THREAD_VARIABLES
"""Environment of worker processes: linear algebra on one thread each, whatever the
user set for ``poise`` itself. numpy's multithreaded BLAS made one 38 × 102 SVD take
321 ms instead of 0.85 ms on a shared 2-core machine; the workers are the parallelism."""


@dataclass(frozen=True)
class ServeConfig:
    """Options of one server (``poise serve --help`` documents each).

    Attributes:
        endpoints: ZeroMQ endpoints the clients connect to.
        workers: Worker processes; each session lives in one of them.
        session_timeout_s: Idle time after which a session expires.
        deadline_s: Time from receipt within which a ``state``, ``set_params``
            or ``bye`` is answered; later, the client gets ``DEADLINE_EXCEEDED``.
        hello_deadline_s: The same for ``hello`` (model load, controller creation).
        recycle_after_s: A worker still busy with one request this long past its
            deadline is killed and replaced (its sessions are lost).
        max_sessions: Sessions on the server.
        max_sessions_per_client: Sessions per client: per CURVE key, or per
            peer address without CURVE.
        max_workers_per_client: Workers one client's sessions may occupy (``None``:
            all but one, at least one), so a client arriving later finds a worker
            no other client floods: a client's sessions share the client's share.
        max_in_flight: Requests of one session not yet answered; more are refused
            (a flooding client). A request answered ``DEADLINE_EXCEEDED`` no
            longer counts: its worker skips it if it has not started it.
        max_message_bytes: Largest request answered; larger ones get
            ``LIMIT_EXCEEDED`` up to twice this size, beyond which ZeroMQ drops
            the connection. At least :data:`MIN_MESSAGE_BYTES`.
        stalled_message_timeout_s: A connection that completes no message (nor
            heartbeat) within this long of a heartbeat is dropped, and the part
            of a message it sent freed: ZeroMQ heartbeats, a ping every
            :func:`heartbeat_interval_s`.
        max_model_bytes: Largest ``hello.model_text``, file sent with it (inline or
            uploaded), and model or clip file.
        asset_cache_bytes: Bytes of uploaded model files the server keeps (least recently
            used out), uploads in progress included.
        max_upload_bytes_per_client: Declared sizes of one client's unfinished uploads.
        model_cache_entries: Parsed models each worker keeps (least recently used out).
        model_dirs: Directories whose files a client may name as model or clip.
        curve_secret_key: Server certificate (``poise keygen``) for CurveZMQ;
            ``None``: plain TCP, for loopback only.
        allow_client_keys: Directory of client public keys allowed with CURVE;
            ``None``: any client key (encryption without authentication).
        stats_all: ``stats`` lists every session, not only the client's own.
        record_dir: Directory where each session's conversation is recorded
            (one MCAP file per session, :mod:`protocol.recording`); ``None``: none.
        log_level: Logging level of the workers.
    """

    endpoints: tuple[str, ...] = ("tcp://127.0.0.1:5555",)
    workers: int = 2
    session_timeout_s: float = 30.0
    deadline_s: float = 0.5
    hello_deadline_s: float = 10.0
    recycle_after_s: float = 5.0
    max_sessions: int = 128
    max_sessions_per_client: int = 32
    max_workers_per_client: int | None = None
    max_in_flight: int = 2
    max_message_bytes: int = MAX_MESSAGE_BYTES
    stalled_message_timeout_s: float = 30.0
    max_model_bytes: int = 4 * 1024 * 1024
    asset_cache_bytes: int = 256 * 1024 * 1024
    max_upload_bytes_per_client: int = 64 * 1024 * 1024
    model_cache_entries: int = 16
    model_dirs: tuple[str, ...] = ()
    curve_secret_key: str | None = None
    allow_client_keys: str | None = None
    stats_all: bool = False
    record_dir: str | None = None
    log_level: str = "INFO"

    def __post_init__(self) -> None:
        positive = {
            "workers": self.workers,
            "session_timeout_s": self.session_timeout_s,
            "deadline_s": self.deadline_s,
            "hello_deadline_s": self.hello_deadline_s,
            "recycle_after_s": self.recycle_after_s,
            "max_sessions": self.max_sessions,
            "max_sessions_per_client": self.max_sessions_per_client,
            "max_in_flight": self.max_in_flight,
            "max_message_bytes": self.max_message_bytes,
            "stalled_message_timeout_s": self.stalled_message_timeout_s,
            "max_model_bytes": self.max_model_bytes,
            "asset_cache_bytes": self.asset_cache_bytes,
            "max_upload_bytes_per_client": self.max_upload_bytes_per_client,
            "model_cache_entries": self.model_cache_entries,
        }
        if self.max_workers_per_client is not None:
            positive["max_workers_per_client"] = self.max_workers_per_client
        for name, value in positive.items():
            if not value > 0 or value != value or value == float("inf"):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if self.max_message_bytes < MIN_MESSAGE_BYTES:
            raise ValueError(
                f"max_message_bytes must be at least {MIN_MESSAGE_BYTES}, got "
                f"{self.max_message_bytes}"
            )
        if not self.endpoints:
            raise ValueError("give at least one endpoint to bind")

    @property
    def workers_per_client(self) -> int:
        """How many workers one client's sessions may occupy (see ``max_workers_per_client``)."""
        if self.max_workers_per_client is None:
            return max(1, self.workers - 1)
        return min(self.workers, self.max_workers_per_client)

    @property
    def heartbeat_interval_s(self) -> float:
        """How often the server pings each connection: a fifth of the stall timeout, ≤ 5 s."""
        return min(5.0, self.stalled_message_timeout_s / 5)

    def to_json(self) -> str:
        """The record as JSON (for a worker's command line)."""
        return json.dumps(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, text: str) -> ServeConfig:
        """Inverse of :meth:`to_json`."""
        fields = json.loads(text)
        fields["endpoints"] = tuple(fields["endpoints"])
        fields["model_dirs"] = tuple(fields["model_dirs"])
        return cls(**fields)
