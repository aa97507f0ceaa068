"""The client library every Poise client shares: connect, handshake, step.

A :class:`ControllerClient` owns one ZeroMQ DEALER socket. Every request
carries a fresh ``seq``; a reply with another ``seq`` (a late answer to a
request that timed out) is dropped. A request that gets no answer within
``timeout_s`` raises :class:`ServerTimeout` (a :class:`TimeoutError`); the
next request then reconnects on a fresh socket and repeats the handshake,
so a client survives a server restart.

The repeated handshake restores every parameter in force: the ``hello``
parameters with every change the server accepted through
:meth:`ControllerClient.set_params` merged in (a ``None`` value, which removes
e.g. a ``point:<name>`` target, drops the key). A session the server let
expire (idle longer than ``poise serve --session-timeout``) answers ``state``
and ``set_params`` with ``NO_SESSION``; the client then re-creates it the same
way, once, logs a warning on the ``poise.client`` logger and repeats the
request.

With :class:`CurveKeys` the connection is encrypted and authenticated with
ZeroMQ's CURVE mechanism; a server that refuses the client's key does not
answer at all, so that shows as a :class:`ServerTimeout`.

The files a sent model names (``model_assets``: includes, meshes) travel by
content: the ``hello`` names each by its SHA-256 (``model_asset_hashes``), a
server that lacks some answers ``ASSETS_MISSING`` listing them, the client
uploads those with ``asset`` messages in chunks that fit the server's
``max_message_bytes`` and repeats the ``hello``. The server keeps them, so a
reconnect or the next run uploads nothing, and a robot's meshes reach the
server whatever their size. :attr:`ControllerClient.uploaded_asset_bytes`
counts what was sent.

An ``error`` with ``seq`` −1 (the server could not read the request: too
large, garbled) is the answer to the one request in flight: it raises
:class:`ServerError` with the server's code and detail, not a timeout.

With ``record=PATH`` every request sent and every reply received (errors and
late replies included) is written to an MCAP log by a
:class:`~protocol.recording.Recorder` (see :mod:`protocol.recording`); the
recording never raises into the caller and is closed by :meth:`close`. The
``hello`` is recorded as the caller gave it, files inline, with the reply
that settled it; the file transfer (``asset`` uploads, ``ASSETS_MISSING``)
is not recorded, so the log replays on any server.
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
from collections.abc import Mapping
from types import TracebackType
from typing import Any, NoReturn

import zmq
import zmq.auth

from clients.curve_keys import CurveKeys, InvalidKeyFile
from protocol.codec import decode, encode
from protocol.endpoints import check_endpoint
from protocol.errors import ErrorCode, PoiseError, ProtocolError
from protocol.messages import (
    Asset,
    AssetReceived,
    Bye,
    Command,
    ContactSpec,
    Error,
    Hello,
    Message,
    Params,
    SessionStats,
    SetParams,
    State,
    Stats,
    Welcome,
)
from protocol.recording import Recorder

__all__ = [
    "ControllerClient",
    "CurveKeys",
    "InvalidKeyFile",
    "ServerError",
    "ServerTimeout",
]

log = logging.getLogger("poise.client")

ASSET_CHUNK_BYTES = 256 * 1024
"""Largest chunk of a file per ``asset`` message. The server's broker decodes, hashes and
writes each between other clients' requests: 0.6 ms per 256 KiB chunk (3.0 ms per MiB)
on the development machine, a pause its 1 kHz clients can take."""
ASSET_MESSAGE_OVERHEAD_BYTES = 4096
"""Room left in the server's ``max_message_bytes`` for an ``asset`` message's other keys."""
SMALLEST_MESSAGE_CAP_BYTES = 64 * 1024
"""The smallest ``poise serve --max-message-bytes``: a larger request may be dropped unanswered
(by ZeroMQ, beyond twice the cap), which a timeout's message then says."""
ASSET_ROUNDS = 3
"""Uploads before a ``hello`` that still misses files gives up (another client's uploads
may evict files of a cache too small for both)."""


class ServerTimeout(PoiseError, TimeoutError):
    """The server did not answer in time (is ``poise serve`` running at the endpoint?)."""


class ServerError(ProtocolError):
    """The server answered a request with an ``error`` message.

    Attributes:
        reply: The ``error`` message as received (``missing_asset_hashes``,
            ``max_message_bytes``); ``None`` if the client made the error up.
    """

    reply: Error | None = None

    @classmethod
    def of(cls, reply: Error, seq: int) -> ServerError:
        """The error for ``reply``, the answer to the request ``seq``."""
        error = cls(reply.code, reply.field, reply.detail, seq)
        error.reply = reply
        return error


class ControllerClient:
    """Blocking request/reply client for one robot session.

    Args:
        endpoint: Server endpoint, e.g. ``tcp://127.0.0.1:5555``.
        timeout_s: Time to wait for each reply.
        curve: Keys to encrypt and authenticate the connection (ZeroMQ
            CURVE); ``None`` for a plain connection.
        record: MCAP log file of the whole conversation (see
            :mod:`protocol.recording`); ``None`` records nothing.

    Raises:
        InvalidEndpoint: ``endpoint`` is not ``tcp://HOST:PORT``, ``ipc://PATH``, ….
        PoiseError: ``curve`` is given but this libzmq lacks CURVE support.
        OSError: The ``record`` file cannot be created.

    Example:
        >>> with ControllerClient("tcp://127.0.0.1:5555") as client:  # doctest: +SKIP
        ...     welcome = client.connect("thesis_humanoid")
        ...     command = client.step(state)
    """

    def __init__(
        self,
        endpoint: str,
        timeout_s: float = 1.0,
        *,
        curve: CurveKeys | None = None,
        record: str | os.PathLike[str] | None = None,
    ):
        if curve is not None and not zmq.has("curve"):
            raise PoiseError(
                f"libzmq {zmq.zmq_version()} was built without CURVE; "
                "install the pyzmq wheel, which bundles libsodium"
            )
        self.endpoint = check_endpoint(endpoint)
        self.recorder = Recorder(record) if record is not None else None
        self.timeout_s = timeout_s
        self.curve = curve
        self.welcome: Welcome | None = None
        self._context = zmq.Context()
        self._socket: zmq.Socket | None = None
        self._receive_timeout_ms = -1
        self._hello: Hello | None = None
        self._files_by_hash: dict[str, bytes] = {}
        self._hash_of_path: dict[str, str] = {}
        self.uploaded_asset_bytes = 0
        """Bytes of model files uploaded to the server (``asset`` chunks) by this client."""
        self.uploaded_assets = 0
        """Files whose upload completed."""
        self._seq = 0
        self._sent_bytes = 0
        self._pending_seq: int | None = None
        self._pending_state: State | None = None
        self._needs_reconnect = False

    def __enter__(self) -> ControllerClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def connect(
        self,
        model: str | None = None,
        *,
        model_text: str | None = None,
        model_format: str = "mjcf",
        model_assets: dict[str, bytes] | None = None,
        model_asset_hashes: dict[str, str] | None = None,
        keyframe: str | None = None,
        controller: str = "momentum",
        params: Mapping[str, Any] | None = None,
        contacts: list[ContactSpec] | None = None,
        expected_model_hash: str | None = None,
        client_name: str = "",
        diagnostics_period_ticks: int = 1,
        imu_frame: str | None = None,
        imu_position_in_frame: tuple[float, float, float] = (0.0, 0.0, 0.0),
        imu_orientation_in_frame_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
    ) -> Welcome:
        """Open a session (``hello`` → ``welcome``); see :class:`protocol.Hello`.

        ``model_assets`` go by hash, uploaded only if the server lacks them (see
        the module docstring); ``model_asset_hashes`` names files the server
        already holds for this client.

        Raises:
            ServerError: The server refused the model, controller or parameters.
            ServerTimeout: No answer within ``timeout_s``.
        """
        self._hello = Hello(
            model=model,
            model_text=model_text,
            model_format=model_format,  # type: ignore[arg-type]
            model_assets=model_assets,
            model_asset_hashes=model_asset_hashes,
            keyframe=keyframe,
            controller=controller,
            params=dict(params or {}),
            contacts=contacts,
            expected_model_hash=expected_model_hash,
            client_name=client_name,
            diagnostics_period_ticks=diagnostics_period_ticks,
            imu_frame=imu_frame,
            imu_position_in_frame=imu_position_in_frame,
            imu_orientation_in_frame_xyzw=imu_orientation_in_frame_xyzw,
        )
        self._files_by_hash = {}
        self._hash_of_path = {}
        for path, data in (model_assets or {}).items():
            sha256 = hashlib.sha256(data).hexdigest()
            self._files_by_hash[sha256] = data
            self._hash_of_path[path] = sha256
        return self._handshake()

    @property
    def last_seq(self) -> int:
        """``seq`` of the last request sent (its reply echoes it)."""
        return self._seq

    def step(self, state: State) -> Command:
        """Send one state and return the command for it (``seq`` is set here).

        An expired session is re-created once and the state sent again (see
        the module docstring).

        Raises:
            ServerError: The server answered with an ``error``.
            ServerTimeout: No answer within ``timeout_s``.
        """
        return self._request(state, Command)

    def send_state(self, state: State) -> None:
        """Send one state without waiting: the first half of :meth:`step`.

        The server computes while the caller works (a simulator steps its
        physics, a bridge drives its actuators); :meth:`receive_command`
        then returns the reply. One state may be outstanding at a time.
        """
        if self._pending_seq is not None:
            raise PoiseError("receive_command() the outstanding state's reply first")
        if self._needs_reconnect:
            self.reconnect()
        self._pending_seq = self._post(state)
        self._pending_state = state

    def receive_command(self) -> Command:
        """Wait for the reply to the state sent by :meth:`send_state`.

        If the session expired, it is re-created once and the state sent
        again; the ``hello`` and the repeated state may each take up to
        ``timeout_s`` more.

        Raises:
            ServerError: The server answered with an ``error``.
            ServerTimeout: No answer within ``timeout_s`` of this call.
        """
        seq, self._pending_seq = self._pending_seq, None
        state, self._pending_state = self._pending_state, None
        if seq is None or state is None:
            raise PoiseError("send_state() before receive_command()")
        try:
            return self._await(seq, "state", Command, self.timeout_s)
        except ServerError as exc:
            if not self._session_expired(exc):
                raise
        self._recreate_session()
        return self._send(state, Command, self.timeout_s)

    def set_params(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """Change controller parameters; returns every parameter in force.

        Once the server accepts the change, it is also remembered for the
        handshake that restores the session after a reconnect.

        Raises:
            ServerError: The server refused a parameter (nothing changed).
            ServerTimeout: No answer within ``timeout_s``.
        """
        request = SetParams(params=dict(params))
        reply = self._request(request, Params)
        self._remember_params(request.params)
        return reply.params

    def stats(self) -> list[SessionStats]:
        """Per-session statistics of the server."""
        return self._request(Stats(), Stats).sessions or []

    def reconnect(self) -> Welcome:
        """Open a fresh socket and repeat the handshake (with the parameters in force)."""
        self._close_socket()
        return self._handshake()

    def close(self) -> None:
        """Say ``bye`` (best effort, short wait) and release the socket."""
        if self._socket is not None and self.welcome is not None and not self._needs_reconnect:
            try:
                self._send(Bye(), Bye, timeout_s=min(self.timeout_s, 0.2))
            except (ServerTimeout, ServerError):
                pass
        self._close_socket()
        self._context.term()
        if self.recorder is not None:
            self.recorder.close()

    def _handshake(self) -> Welcome:
        if self._hello is None:
            raise PoiseError("call connect() before sending requests")
        self._needs_reconnect = False
        hello = self._hello
        wire = hello
        if self._hash_of_path:  # the files by hash: the hello stays small
            wire = hello.model_copy(
                update={
                    "model_assets": None,
                    "model_asset_hashes": {
                        **(hello.model_asset_hashes or {}),
                        **self._hash_of_path,
                    },
                }
            )
        uploads = 0
        while True:
            try:
                self.welcome = self._send_hello(wire, hello)
                return self.welcome
            except ServerError as exc:
                missing = exc.reply.missing_asset_hashes if exc.reply is not None else None
                if exc.code != ErrorCode.ASSETS_MISSING or not missing or exc.reply is None:
                    raise
                unknown = [sha256 for sha256 in missing if sha256 not in self._files_by_hash]
                if unknown:
                    detail = (
                        f"the server lacks {len(unknown)} files this client has not got (by "
                        f"SHA-256: {', '.join(h[:12] + '…' for h in unknown)}); send them in "
                        "model_assets"
                    )
                elif uploads == ASSET_ROUNDS:
                    detail = (
                        f"{len(missing)} files are still missing after {uploads} uploads: the "
                        "server's asset cache (`poise serve --asset-cache-bytes`) is too small "
                        "for them, or other clients' uploads keep evicting them"
                    )
                else:
                    self._upload(missing, exc.reply.max_message_bytes)
                    uploads += 1
                    continue
                raise ServerError(exc.code, exc.field, detail, exc.seq) from None

    def _send_hello(self, wire: Hello, logged: Hello) -> Welcome:
        """Send the ``hello`` on the wire; record it as the caller gave it (files inline).

        A hello answered ``ASSETS_MISSING`` is the file transfer's business: not recorded.
        """
        sent_ns = time.time_ns()
        seq = self._post(wire, record=False)
        reply: Message | None = None
        transfer = False
        try:
            reply = self._await(seq, "hello", Welcome, self.timeout_s, record=False)
            return reply  # type: ignore[return-value]
        except ServerError as exc:
            reply, transfer = exc.reply, exc.code == ErrorCode.ASSETS_MISSING
            raise
        finally:
            if self.recorder is not None and not transfer:
                self.recorder.record(logged.model_copy(update={"seq": seq}), "sent", sent_ns)
                if reply is not None:
                    self.recorder.record(reply, "received")

    def _upload(self, missing: list[str], max_message_bytes: int | None) -> None:
        """Upload each file in chunks that fit the server's ``max_message_bytes``."""
        chunk_bytes = ASSET_CHUNK_BYTES
        if max_message_bytes is not None:
            chunk_bytes = min(chunk_bytes, max_message_bytes - ASSET_MESSAGE_OVERHEAD_BYTES)
        if chunk_bytes <= 0:
            raise PoiseError(
                f"the server's max_message_bytes={max_message_bytes} leaves no room for a file "
                "chunk; ask its operator to raise `poise serve --max-message-bytes`"
            )
        total = sum(len(self._files_by_hash[sha256]) for sha256 in missing)
        log.info(
            "uploading %d files (%.1f MB) to the server at %s",
            len(missing),
            total / 1e6,
            self.endpoint,
        )
        for sha256 in missing:
            data = self._files_by_hash[sha256]
            offset = 0
            while True:
                chunk = data[offset : offset + chunk_bytes]
                request = Asset(
                    sha256=sha256, size_bytes=len(data), offset_bytes=offset, data=chunk
                )
                reply: AssetReceived = self._send(
                    request, AssetReceived, self.timeout_s, record=False
                )
                self.uploaded_asset_bytes += len(chunk)
                if reply.complete:
                    break
                if reply.received_bytes <= offset or reply.received_bytes > len(data):
                    raise ServerError(
                        ErrorCode.UNEXPECTED_MESSAGE,
                        "received_bytes",
                        f"the server acknowledged {reply.received_bytes} bytes of "
                        f"{sha256[:12]}… after a chunk at {offset}",
                        reply.seq,
                    )
                offset = reply.received_bytes
            self.uploaded_assets += 1

    def _remember_params(self, changes: Mapping[str, Any]) -> None:
        """Merge accepted changes into the ``hello`` that a reconnect repeats.

        ``None`` removes (a ``point:<name>`` target; the server refuses it
        for other parameters), so the key is dropped rather than sent.
        """
        if self._hello is None:
            return
        merged = {**self._hello.params, **changes}
        params = {key: value for key, value in merged.items() if value is not None}
        self._hello = self._hello.model_copy(update={"params": params})

    def _session_expired(self, error: ServerError) -> bool:
        return error.code == ErrorCode.NO_SESSION and self._hello is not None

    def _recreate_session(self) -> None:
        expired = self.welcome.session_id[:8] if self.welcome is not None else "?"
        welcome = self._handshake()
        log.warning(
            "session %s on %s expired on the server; re-created it as session %s",
            expired,
            self.endpoint,
            welcome.session_id[:8],
        )

    def _request(self, message: Message, reply_type: type[Any]) -> Any:
        if self._pending_seq is not None:
            raise PoiseError("receive_command() the outstanding state's reply first")
        if self._needs_reconnect:
            self.reconnect()
        try:
            return self._send(message, reply_type, self.timeout_s)
        except ServerError as exc:
            if not (isinstance(message, State | SetParams) and self._session_expired(exc)):
                raise
        self._recreate_session()
        return self._send(message, reply_type, self.timeout_s)

    def _open_socket(self) -> zmq.Socket:
        if self._socket is None:
            self._socket = self._context.socket(zmq.DEALER)
            self._socket.setsockopt(zmq.LINGER, 0)
            self._socket.setsockopt(zmq.SNDTIMEO, max(1, int(self.timeout_s * 1000)))
            self._receive_timeout_ms = -1  # a fresh socket waits forever
            # A random routing id: another peer cannot guess it to reach this session.
            self._socket.setsockopt(zmq.ROUTING_ID, b"c" + os.urandom(15))
            if self.curve is not None:
                self._socket.curve_serverkey = self.curve.server_public
                self._socket.curve_publickey = self.curve.client_public
                self._socket.curve_secretkey = self.curve.client_secret
            self._socket.connect(self.endpoint)
        return self._socket

    def _close_socket(self) -> None:
        self._pending_seq = None
        self._pending_state = None
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None

    def _send(
        self, message: Message, reply_type: type[Any], timeout_s: float, *, record: bool = True
    ) -> Any:
        seq = self._post(message, record=record)
        return self._await(seq, message.type, reply_type, timeout_s, record=record)

    def _post(self, message: Message, *, record: bool = True) -> int:
        self._seq += 1
        message = message.model_copy(update={"seq": self._seq})
        if self.recorder is not None and record:
            self.recorder.record(message, "sent")
        data = encode(message)
        self._sent_bytes = len(data)
        try:  # a DEALER with no connected peer (a refused CURVE handshake) blocks on send
            self._open_socket().send(data)
        except zmq.Again:
            self._timed_out(message.type, self.timeout_s)
        return self._seq

    def _await(
        self,
        seq: int,
        request_type: str,
        reply_type: type[Any],
        timeout_s: float,
        *,
        record: bool = True,
    ) -> Any:
        socket = self._open_socket()
        deadline = time.monotonic() + timeout_s
        wait_ms = max(1, int(timeout_s * 1000))
        while wait_ms > 0:
            if wait_ms != self._receive_timeout_ms:  # one call (a receive with a timeout)
                socket.setsockopt(zmq.RCVTIMEO, wait_ms)
                self._receive_timeout_ms = wait_ms
            try:
                data = socket.recv()
            except zmq.Again:
                break
            reply = decode(data)
            if self.recorder is not None and record:
                self.recorder.record(reply, "received")
            # seq -1: the server could not read the request; with one request in flight
            # (this client never has more), it answers that one.
            unreadable = isinstance(reply, Error) and reply.seq == -1
            if reply.seq != seq and not unreadable:  # late reply to a request that timed out
                wait_ms = int((deadline - time.monotonic()) * 1000)
                continue
            if isinstance(reply, Error):
                raise ServerError.of(reply, seq)
            if not isinstance(reply, reply_type):
                raise ServerError(
                    ErrorCode.UNEXPECTED_MESSAGE,
                    "type",
                    f"expected {reply_type.__name__}, got {reply.type!r}",
                    seq,
                )
            return reply
        self._timed_out(request_type, timeout_s)

    def _timed_out(self, request_type: str, timeout_s: float) -> NoReturn:
        self._needs_reconnect = True
        check = "is `poise serve` running there"
        if self.curve is not None:
            check += ", with the server key given, and does it accept this client's CURVE key"
        size = ""
        if self._sent_bytes > 2 * SMALLEST_MESSAGE_CAP_BYTES:
            size = (
                f" (The request was {self._sent_bytes} bytes: a server drops one over twice its "
                "`poise serve --max-message-bytes` unanswered.)"
            )
        raise ServerTimeout(
            f"nothing answers at {self.endpoint}: no reply to {request_type!r} within "
            f"{timeout_s:.3g} s; {check}?{size}"
        )
