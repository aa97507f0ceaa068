"""What the benchmarks share: a raw pyzmq echo server and the tick floor (baselines measured in
the same run), and a per-call timer."""

from __future__ import annotations

import ctypes
import multiprocessing
import time
from collections.abc import Callable, Iterable
from typing import Any

import daqp
import numpy as np
import pinocchio as pin
import zmq


def timed(step: Callable[[Any], object], items: Iterable[Any]) -> list[float]:
    """Wall-clock seconds of ``step(item)`` for each item, in order."""
    times = []
    for item in items:
        start = time.perf_counter()
        step(item)
        times.append(time.perf_counter() - start)
    return times


def alternating_times(
    variants: dict[str, Callable[[Any], object]], items: list[Any], chunks: int, warmup: int
) -> dict[str, list[float]]:
    """:func:`timed` of every variant on ``items``, after ``warmup`` untimed calls each, in
    ``chunks`` alternating slices, so that all of them see the same machine load."""
    for step in variants.values():
        timed(step, items[:warmup])
    times: dict[str, list[float]] = {label: [] for label in variants}
    for chunk in range(chunks):
        part = slice(chunk * len(items) // chunks, (chunk + 1) * len(items) // chunks)
        for label, step in variants.items():
            times[label] += timed(step, items[part])
    return times


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


class Floor:
    """The tick floor: Pinocchio's dynamics terms and centroidal map, and one direct DAQP solve.

    The QP has the size of the ``momentum`` controller's problem: nv unknowns, 12 equality
    rows (two 6-D support constraints), a dense positive-definite Hessian.
    """

    def __init__(self, model: pin.Model, rng: np.random.Generator):
        self.model, self.data = model, model.createData()
        nv = model.nv
        self.hessian = np.eye(nv) + 0.1 * np.ones((nv, nv))
        self.rows = rng.normal(size=(12, nv))
        self.sense = np.full(12, 5, dtype=ctypes.c_int)  # equalities
        self.rng = rng

    def tick(self, control_input: Any) -> None:
        """One floor tick at ``control_input``'s ``q`` and ``v``."""
        q, v = control_input.q, control_input.v
        pin.computeAllTerms(self.model, self.data, q, v)
        pin.computeCentroidalMap(self.model, self.data, q)
        gradient, rhs = self.rng.normal(size=self.model.nv), self.rng.normal(size=12)
        daqp.solve(self.hessian, gradient, self.rows, rhs, rhs, self.sense)
