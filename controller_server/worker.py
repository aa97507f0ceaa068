"""A worker process: the sessions the broker gives it, one request at a time.

Started by the broker (:mod:`controller_server.server`) as
``python -m controller_server.worker IDENTITY BACKEND CONFIG_JSON``, with
single-threaded BLAS (:data:`~controller_server.config.SINGLE_THREADED_BLAS`).
It connects a DEALER to the broker's backend ROUTER and speaks in frames
(each list is one multipart message; the broker's ROUTER adds and strips the
worker's identity):

========================================================  ================================
broker → worker                                           worker → broker
========================================================  ================================
                                                          ``ready``
``req``, :data:`REQUEST_HEADER` (id, session key,         ``rep``, :data:`REPLY_HEADER` (id,
deadline), request                                        session open after it), reply
                                                          — or ``late``, id (past deadline)
``drop``, session key, …                                  —
``stats``, id, session key, …                             ``stats``, id, msgpack list
``stop``                                                  (exits)
========================================================  ================================

The worker checks the deadline before it starts a request, so a queue behind
a slow tick is skipped rather than computed for states nobody waits for.
"""

from __future__ import annotations

import logging
import os
import signal
import struct
import sys
import time

import msgpack
import zmq

from controller_server.config import ServeConfig
from controller_server.session_table import SessionTable
from protocol.codec import encode
from protocol.errors import ErrorCode
from protocol.messages import Error, Hello

__all__ = ["REPLY_HEADER", "REQUEST_HEADER", "WARM_UP_HELLO", "run_worker"]

log = logging.getLogger("poise.worker")

REQUEST_HEADER = struct.Struct("<8s8sd")
"""Request id, session key, deadline on ``time.monotonic()`` (system-wide on Linux)."""
REPLY_HEADER = struct.Struct("<8s?")
"""Request id, whether the session is open after the request."""
WARM_UP_HELLO = Hello(model="thesis_humanoid", controller="momentum")
"""Opened and closed before ``ready``, so imports and the model cache are warm
and a client's first request is answered at once."""
PARENT_CHECK_INTERVAL_MS = 1000


def _warm_up(max_model_bytes: int) -> None:
    """Open and close one session in a table of its own (imports and model cache are global)."""
    table = SessionTable(max_model_bytes=max_model_bytes)
    reply = table.handle(b"warm-up", encode(WARM_UP_HELLO))
    if isinstance(reply, Error):
        log.warning("warm-up failed: %s", reply.detail)
    table.drop([b"warm-up"])


def _serve_request(table: SessionTable, header: bytes, payload: bytes) -> list[bytes]:
    request_id, key, deadline_s = REQUEST_HEADER.unpack(header)
    if time.monotonic() > deadline_s:
        return [b"late", request_id]
    try:
        reply = encode(table.handle(key, payload))
    except Exception as exc:  # encoding the reply failed: still a typed answer
        log.exception("could not encode a reply")
        reply = encode(Error(code=ErrorCode.INTERNAL, detail=f"{type(exc).__name__}: {exc}"))
    return [b"rep", REPLY_HEADER.pack(request_id, key in table.sessions), reply]


def run_worker(identity: bytes, backend: str, config: ServeConfig) -> None:
    """Serve the broker at ``backend`` until told to stop or the broker is gone."""
    from controller_server.files import set_model_directories
    from controller_server.models.robot_model import set_model_cache_size

    set_model_directories(config.model_dirs, max_file_bytes=config.max_model_bytes)
    set_model_cache_size(config.model_cache_entries)
    _warm_up(config.max_model_bytes)  # its drop returns the warm-up session's memory
    table = SessionTable(max_model_bytes=config.max_model_bytes, record_dir=config.record_dir)
    parent = os.getppid()
    context = zmq.Context()
    socket = context.socket(zmq.DEALER)
    socket.setsockopt(zmq.LINGER, 0)
    socket.setsockopt(zmq.ROUTING_ID, identity)
    socket.setsockopt(zmq.RCVTIMEO, PARENT_CHECK_INTERVAL_MS)
    socket.connect(backend)
    socket.send(b"ready")
    try:
        while True:
            try:
                frames = socket.recv_multipart()
            except zmq.Again:  # a quiet second: is the broker still there?
                if os.getppid() != parent:
                    log.warning("broker gone: worker exits")
                    return
                continue
            kind = frames[0]
            if kind == b"req" and len(frames) == 3:
                socket.send_multipart(_serve_request(table, frames[1], frames[2]))
            elif kind == b"drop":
                table.drop(frames[1:])
            elif kind == b"stats" and len(frames) >= 2:
                stats = [s.model_dump() for s in table.session_stats(frames[2:])]
                socket.send_multipart([b"stats", frames[1], msgpack.packb(stats)])
            elif kind == b"stop":
                return
    finally:
        table.close()
        socket.close(linger=0)
        context.term()


def main(argv: list[str]) -> int:
    """``python -m controller_server.worker IDENTITY BACKEND CONFIG_JSON``."""
    identity, backend, config_json = argv
    config = ServeConfig.from_json(config_json)
    # The broker decides when workers stop: a Ctrl-C or a service manager's SIGTERM
    # reaches the whole process group, and the broker still drains through us.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    logging.basicConfig(
        level=config.log_level,
        format=f"%(asctime)s %(name)s[{identity}] %(levelname)s %(message)s",
    )
    run_worker(identity.encode(), backend, config)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
