"""A worker process: the sessions the broker gives it, one request at a time.

Started by the broker (:mod:`controller_server.server`) as
``python -m controller_server.worker IDENTITY FD CONFIG_JSON ASSET_DIR``, with
single-threaded BLAS (:data:`~controller_server.config.SINGLE_THREADED_BLAS`),
``FD`` its end of a Unix socket pair with the broker, ``ASSET_DIR`` the
broker's asset cache (:mod:`controller_server.asset_cache`), whose files a
``hello`` names by hash. The two speak in
messages of frames over it (:class:`Channel`):

========================================================  ================================
broker → worker                                           worker → broker
========================================================  ================================
                                                          ``ready``
``req``, :data:`REQUEST_HEADER` (id, session key,         ``rep``, :data:`REPLY_HEADER` (id,
deadline, client), request                                session open after it), reply
                                                          — or ``late``, id (past deadline)
``drop``, session key, …                                  —
``stats``, id, session key, …                             ``stats``, id, msgpack list
``stop``                                                  (exits)
========================================================  ================================

A plain socket pair rather than ZeroMQ: a ZeroMQ hop wakes an I/O thread on
each side, four thread switches per round trip that a busy machine pays
with tens of µs each. The worker exits when the broker's end closes (the
broker stopped or died).

Requests wait in one queue per client and are served one client at a time
in turn (round robin), reading what has arrived between any two: a client's
request waits behind at most one request of each other client with work
here, however many sessions and requests in flight a flooding client has
(issue 32: one client's four ``prioritized`` sessions starved a ``tracking``
client, served in arrival order). The worker checks the deadline before it
starts a request, so a queue behind a slow tick is skipped rather than
computed for states nobody waits for.
Once warm, and after each new session, it moves every object it holds to
the garbage collector's permanent generation (:func:`gc.freeze`), so the
collections a tick's garbage triggers never walk the robot models and
imports (a full collection took 15 ms).
"""

from __future__ import annotations

import collections
import gc
import hashlib
import logging
import signal
import socket
import struct
import sys
import time
from collections.abc import Sequence

import msgpack

from controller_server.config import ServeConfig
from controller_server.session_table import SessionTable
from protocol.codec import encode
from protocol.errors import ErrorCode
from protocol.messages import Error, Hello

__all__ = [
    "REPLY_HEADER",
    "REQUEST_HEADER",
    "WARM_UP_HELLO",
    "Channel",
    "FairQueue",
    "client_tag",
    "run_worker",
]

log = logging.getLogger("poise.worker")

REQUEST_HEADER = struct.Struct("<8s8sd8s")
"""Request id, session key, deadline on ``time.monotonic()`` (system-wide on Linux), and
the client's tag (:func:`client_tag`), whose requests share one turn of the round robin."""
REPLY_HEADER = struct.Struct("<8s?")
"""Request id, whether the session is open after the request."""
WARM_UP_HELLO = Hello(model="thesis_humanoid", controller="momentum")
"""Opened and closed before ``ready``, so imports and the model cache are warm
and a client's first request is answered at once."""
_LENGTH = struct.Struct("<I")
_RECEIVE_BYTES = 64 * 1024
"""Bytes read per call: into a buffer kept for it (a fresh 1 MB one per call cost an mmap)."""


class Channel:
    """One end of the broker ↔ worker link: messages of frames over a Unix stream socket.

    A message is its length (``<I``), then each frame's length and bytes.
    The broker's end does not block: what the socket does not take at once
    waits in :attr:`outgoing` for :meth:`flush`. The worker's end blocks.

    Args:
        sock: A connected ``AF_UNIX`` ``SOCK_STREAM`` socket.
        blocking: Whether sending and receiving wait.
    """

    def __init__(self, sock: socket.socket, *, blocking: bool):
        self.socket = sock
        self.socket.setblocking(blocking)
        self.blocking = blocking
        self.outgoing = bytearray()
        """Bytes of messages sent that the socket has not taken yet (non-blocking end)."""
        self._incoming = bytearray()
        self._chunk = memoryview(bytearray(_RECEIVE_BYTES))

    def fileno(self) -> int:
        """The socket's file descriptor (for ``zmq.Poller``)."""
        return self.socket.fileno()

    @staticmethod
    def pack(frames: Sequence[bytes]) -> bytes:
        """The bytes of one message."""
        parts = []
        for frame in frames:
            parts += (_LENGTH.pack(len(frame)), frame)
        return b"".join([_LENGTH.pack(sum(map(len, parts))), *parts])

    def send(self, frames: Sequence[bytes]) -> None:
        """Send one message (the non-blocking end queues what the socket does not take).

        Raises:
            OSError: The other end is gone.
        """
        data = self.pack(frames)
        if self.blocking:
            self.socket.sendall(data)
        else:
            self.outgoing += data
            self.flush()

    def flush(self) -> bool:
        """Write what the socket takes of :attr:`outgoing`; ``True`` when nothing is left.

        Raises:
            OSError: The other end is gone.
        """
        while self.outgoing:
            try:
                sent = self.socket.send(self.outgoing)
            except BlockingIOError:
                return False
            del self.outgoing[:sent]
        return True

    def receive(self, wait: bool = True) -> list[list[bytes]] | None:
        """The messages that have arrived; ``None`` at EOF.

        The blocking end waits for one unless ``wait`` is false.
        """
        messages = self._complete()
        flags = 0 if self.blocking and wait else socket.MSG_DONTWAIT
        while not messages:
            try:
                size = self.socket.recv_into(self._chunk, 0, flags)
            except BlockingIOError:
                return messages
            except ConnectionError:
                return None
            if not size:
                return None
            self._incoming += self._chunk[:size]
            messages = self._complete()
            if flags:
                break
        return messages

    def _complete(self) -> list[list[bytes]]:
        """Take the complete messages off the incoming bytes."""
        messages = []
        buffer, offset = memoryview(self._incoming), 0
        while len(buffer) - offset >= _LENGTH.size:
            (length,) = _LENGTH.unpack_from(buffer, offset)
            end = offset + _LENGTH.size + length
            if len(buffer) < end:
                break
            frames, offset = [], offset + _LENGTH.size
            while offset < end:
                (size,) = _LENGTH.unpack_from(buffer, offset)
                offset += _LENGTH.size
                frames.append(bytes(buffer[offset : offset + size]))
                offset += size
            messages.append(frames)
        buffer.release()
        if offset:
            del self._incoming[:offset]
        return messages

    def close(self) -> None:
        """Close the socket."""
        self.socket.close()


def client_tag(client: str) -> bytes:
    """The 8 bytes that stand for a client (CURVE key or peer address) in a request header."""
    return hashlib.blake2b(client.encode(), digest_size=8).digest()


class FairQueue:
    """Requests by client, taken one client at a time in turn (round robin)."""

    def __init__(self) -> None:
        self._by_client: dict[bytes, collections.deque[list[bytes]]] = {}
        self._turns: collections.deque[bytes] = collections.deque()

    def __bool__(self) -> bool:
        return bool(self._turns)

    def put(self, frames: list[bytes]) -> None:
        """Queue a ``req`` message behind its client's earlier ones."""
        tag = REQUEST_HEADER.unpack(frames[1])[3]
        queue = self._by_client.get(tag)
        if queue is None:
            queue = self._by_client[tag] = collections.deque()
            self._turns.append(tag)
        queue.append(frames)

    def take(self) -> list[bytes]:
        """The next client's oldest request; that client goes to the back of the turns."""
        tag = self._turns.popleft()
        queue = self._by_client[tag]
        frames = queue.popleft()
        if queue:
            self._turns.append(tag)
        else:
            del self._by_client[tag]
        return frames


def _warm_up(max_model_bytes: int) -> None:
    """Open and close one session in a table of its own (imports and model cache are global)."""
    table = SessionTable(max_model_bytes=max_model_bytes, tick_budget_s=None)
    reply = table.handle(b"warm-up", encode(WARM_UP_HELLO))
    if isinstance(reply, Error):
        log.warning("warm-up failed: %s", reply.detail)
    table.drop([b"warm-up"])


def _serve_request(table: SessionTable, header: bytes, payload: bytes) -> list[bytes]:
    request_id, key, deadline_s, _ = REQUEST_HEADER.unpack(header)
    if time.monotonic() > deadline_s:
        return [b"late", request_id]
    try:
        reply = encode(table.handle(key, payload))
    except Exception as exc:  # encoding the reply failed: still a typed answer
        log.exception("could not encode a reply")
        reply = encode(Error(code=ErrorCode.INTERNAL, detail=f"{type(exc).__name__}: {exc}"))
    return [b"rep", REPLY_HEADER.pack(request_id, key in table.sessions), reply]


def run_worker(
    identity: bytes, channel: Channel, config: ServeConfig, asset_dir: str | None = None
) -> None:
    """Serve the broker over ``channel`` until told to stop or the broker is gone.

    Args:
        identity: The worker's name in the broker's logs.
        channel: Its end of the link with the broker.
        config: The server's options.
        asset_dir: Directory of the broker's asset cache (``None``: none).
    """
    from controller_server.files import set_model_directories
    from controller_server.memory import return_large_buffers_to_the_system
    from controller_server.models.robot_model import set_model_cache_size

    return_large_buffers_to_the_system()  # a long request's buffers leave with it
    set_model_directories(config.model_dirs, max_file_bytes=config.max_model_bytes)
    set_model_cache_size(config.model_cache_entries)
    _warm_up(config.max_model_bytes)  # its drop returns the warm-up session's memory
    table = SessionTable(
        max_model_bytes=config.max_model_bytes,
        record_dir=config.record_dir,
        max_message_bytes=config.max_message_bytes,
        asset_dir=asset_dir,
        tick_budget_s=config.deadline_s,  # a session whose tick could not meet it is refused
    )
    gc.freeze()
    requests = FairQueue()
    try:
        channel.send([b"ready"])
        while True:
            messages = channel.receive(wait=not requests)  # between requests: what is there
            if messages is None:
                log.warning("broker gone: worker %s exits", identity.decode())
                return
            for frames in messages:
                kind = frames[0]
                if kind == b"req" and len(frames) == 3:
                    requests.put(frames)
                elif kind == b"drop":
                    table.drop(frames[1:])
                elif kind == b"stats" and len(frames) >= 2:
                    stats = [s.model_dump() for s in table.session_stats(frames[2:])]
                    channel.send([b"stats", frames[1], msgpack.packb(stats)])
                elif kind == b"stop":
                    return
            if requests:
                _, header, payload = requests.take()
                opened = table.sessions_opened
                channel.send(_serve_request(table, header, payload))
                if table.sessions_opened != opened:  # a new session's model and controller
                    gc.freeze()
    except (BrokenPipeError, ConnectionError):
        log.warning("broker gone: worker %s exits", identity.decode())
    finally:
        table.close()
        channel.close()


def main(argv: list[str]) -> int:
    """``python -m controller_server.worker IDENTITY FD CONFIG_JSON [ASSET_DIR]``."""
    identity, fd, config_json, *rest = argv
    asset_dir = rest[0] if rest else None
    config = ServeConfig.from_json(config_json)
    # The broker decides when workers stop: a Ctrl-C or a service manager's SIGTERM
    # reaches the whole process group, and the broker still drains through us.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    logging.basicConfig(
        level=config.log_level,
        format=f"%(asctime)s %(name)s[{identity}] %(levelname)s %(message)s",
    )
    channel = Channel(socket.socket(fileno=int(fd)), blocking=True)
    run_worker(identity.encode(), channel, config, asset_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
