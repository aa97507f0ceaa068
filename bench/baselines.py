"""Baselines the benchmarks measure in the same run: a raw pyzmq echo server."""

from __future__ import annotations

import multiprocessing

import zmq


def echo_server(endpoint_queue: multiprocessing.Queue, reply_size: int) -> None:
    """A ROUTER on a free loopback port answering every request with ``reply_size`` bytes.

    Puts its endpoint on ``endpoint_queue``; a request ``b"stop"`` ends it.
    """
    context = zmq.Context()
    socket = context.socket(zmq.ROUTER)
    port = socket.bind_to_random_port("tcp://127.0.0.1")
    endpoint_queue.put(f"tcp://127.0.0.1:{port}")
    reply = b"\x00" * reply_size
    while True:
        identity, payload = socket.recv_multipart()
        if payload == b"stop":
            break
        socket.send_multipart([identity, reply])
    socket.close(linger=0)
    context.term()
