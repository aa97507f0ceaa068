"""The client library every Poise client shares: connect, handshake, step.

A :class:`ControllerClient` owns one ZeroMQ DEALER socket. Every request
carries a fresh ``seq``; a reply with another ``seq`` (a late answer to a
request that timed out) is dropped. A request that gets no answer within
``timeout_s`` raises :class:`ServerTimeout` (a :class:`TimeoutError`); the
next request then reconnects on a fresh socket and repeats the handshake,
so a client survives a server restart.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from types import TracebackType
from typing import Any

import zmq

from protocol.codec import decode, encode
from protocol.errors import ErrorCode, PoiseError, ProtocolError
from protocol.messages import (
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

__all__ = ["ControllerClient", "ServerError", "ServerTimeout"]


class ServerTimeout(PoiseError, TimeoutError):
    """The server did not answer in time (is ``poise serve`` running at the endpoint?)."""


class ServerError(ProtocolError):
    """The server answered a request with an ``error`` message."""


class ControllerClient:
    """Blocking request/reply client for one robot session.

    Args:
        endpoint: Server endpoint, e.g. ``tcp://127.0.0.1:5555``.
        timeout_s: Time to wait for each reply.

    Example:
        >>> with ControllerClient("tcp://127.0.0.1:5555") as client:  # doctest: +SKIP
        ...     welcome = client.connect("thesis_humanoid")
        ...     command = client.step(state)
    """

    def __init__(self, endpoint: str, timeout_s: float = 1.0):
        self.endpoint = endpoint
        self.timeout_s = timeout_s
        self.welcome: Welcome | None = None
        self._context = zmq.Context()
        self._socket: zmq.Socket | None = None
        self._hello: Hello | None = None
        self._seq = 0
        self._pending_seq: int | None = None
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
        controller: str = "tracking",
        params: Mapping[str, Any] | None = None,
        contacts: list[ContactSpec] | None = None,
        expected_model_hash: str | None = None,
        client_name: str = "",
        diagnostics_period_ticks: int = 1,
    ) -> Welcome:
        """Open a session (``hello`` → ``welcome``); see :class:`protocol.Hello`.

        Raises:
            ServerError: The server refused the model, controller or parameters.
            ServerTimeout: No answer within ``timeout_s``.
        """
        self._hello = Hello(
            model=model,
            model_text=model_text,
            model_format=model_format,  # type: ignore[arg-type]
            controller=controller,
            params=dict(params or {}),
            contacts=contacts,
            expected_model_hash=expected_model_hash,
            client_name=client_name,
            diagnostics_period_ticks=diagnostics_period_ticks,
        )
        return self._handshake()

    @property
    def last_seq(self) -> int:
        """``seq`` of the last request sent (its reply echoes it)."""
        return self._seq

    def step(self, state: State) -> Command:
        """Send one state and return the command for it (``seq`` is set here)."""
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

    def receive_command(self) -> Command:
        """Wait for the reply to the state sent by :meth:`send_state`.

        Raises:
            ServerError: The server answered with an ``error``.
            ServerTimeout: No answer within ``timeout_s`` of this call.
        """
        seq, self._pending_seq = self._pending_seq, None
        if seq is None:
            raise PoiseError("send_state() before receive_command()")
        return self._await(seq, "state", Command, self.timeout_s)

    def set_params(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """Change controller parameters; returns every parameter in force."""
        return self._request(SetParams(params=dict(params)), Params).params

    def stats(self) -> list[SessionStats]:
        """Per-session statistics of the server."""
        return self._request(Stats(), Stats).sessions or []

    def reconnect(self) -> Welcome:
        """Open a fresh socket and repeat the handshake."""
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

    def _handshake(self) -> Welcome:
        if self._hello is None:
            raise PoiseError("call connect() before sending requests")
        self._needs_reconnect = False
        self.welcome = self._send(self._hello, Welcome, self.timeout_s)
        return self.welcome

    def _request(self, message: Message, reply_type: type[Any]) -> Any:
        if self._pending_seq is not None:
            raise PoiseError("receive_command() the outstanding state's reply first")
        if self._needs_reconnect:
            self.reconnect()
        return self._send(message, reply_type, self.timeout_s)

    def _open_socket(self) -> zmq.Socket:
        if self._socket is None:
            self._socket = self._context.socket(zmq.DEALER)
            self._socket.setsockopt(zmq.LINGER, 0)
            self._socket.connect(self.endpoint)
        return self._socket

    def _close_socket(self) -> None:
        self._pending_seq = None
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None

    def _send(self, message: Message, reply_type: type[Any], timeout_s: float) -> Any:
        return self._await(self._post(message), message.type, reply_type, timeout_s)

    def _post(self, message: Message) -> int:
        self._seq += 1
        self._open_socket().send(encode(message.model_copy(update={"seq": self._seq})))
        return self._seq

    def _await(self, seq: int, request_type: str, reply_type: type[Any], timeout_s: float) -> Any:
        socket = self._open_socket()
        deadline = time.monotonic() + timeout_s
        while (remaining_ms := (deadline - time.monotonic()) * 1000) > 0:
            if not socket.poll(max(1, int(remaining_ms)), zmq.POLLIN):
                break
            reply = decode(socket.recv())
            if reply.seq != seq:
                continue  # late reply to a request that already timed out
            if isinstance(reply, Error):
                raise ServerError(reply.code, reply.field, reply.detail, reply.seq)
            if not isinstance(reply, reply_type):
                raise ServerError(
                    ErrorCode.UNEXPECTED_MESSAGE,
                    "type",
                    f"expected {reply_type.__name__}, got {reply.type!r}",
                    seq,
                )
            return reply
        self._needs_reconnect = True
        raise ServerTimeout(
            f"no reply to {request_type!r} from {self.endpoint} within {timeout_s:.3g} s; "
            "check that `poise serve` is running there"
        )
