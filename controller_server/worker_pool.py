"""The broker's worker processes: started, written to, polled, replaced, stopped.

A :class:`WorkerPool` holds a :class:`~controller_server.routing.WorkerRecord` for
each worker process of the broker and registers its socket in the broker's
``zmq.Poller``. It starts workers (:func:`~controller_server.broker_setup.start_worker`)
and waits until each is ready; it sends to a worker without blocking, holding
what is sent before the worker is ready (a replacement warming up) and refusing
what would queue more than :data:`MAX_WORKER_BACKLOG_BYTES` for one that does not
read; it polls a worker's socket for output only while bytes wait for it; it looks
for exited workers at most every :data:`WORKER_CHECK_INTERVAL_S`; it kills a worker
and stops them all. What becomes of a replaced worker's sessions and requests is
the broker's business (:mod:`controller_server.server`).
"""

from __future__ import annotations

import itertools
import logging
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import zmq

from controller_server.broker_setup import ServerStartError, start_worker
from controller_server.config import ServeConfig
from controller_server.routing import WorkerRecord

__all__ = [
    "MAX_WORKER_BACKLOG_BYTES",
    "WORKER_CHECK_INTERVAL_S",
    "WORKER_START_TIMEOUT_S",
    "WorkerPool",
]

log = logging.getLogger("poise.server")

WORKER_CHECK_INTERVAL_S = 0.1
"""How often the broker looks for dead workers (a system call per worker)."""
WORKER_START_TIMEOUT_S = 120.0
MAX_WORKER_BACKLOG_BYTES = 256 * 1024 * 1024
"""Bytes queued for a worker that does not read (stuck) beyond which requests are refused."""
_POLLIN, _POLLOUT = int(zmq.POLLIN), int(zmq.POLLOUT)
"""Plain ints: pyzmq's flags are enums, and combining them costs an enum call each."""


class WorkerPool:
    """The worker processes of one broker, and their sockets in its poller.

    Args:
        config: The server's options (each worker gets them).
        poller: The broker's poller: each worker's socket is registered there.
    """

    def __init__(self, config: ServeConfig, poller: zmq.Poller):
        self.config = config
        self.workers: dict[bytes, WorkerRecord] = {}
        """The workers by identity (``w0``, ``w1`` …; a replacement gets a new one)."""
        self.by_fd: dict[int, WorkerRecord] = {}
        """The workers whose sockets are polled, by file descriptor."""
        self._poller = poller
        self._generation = itertools.count()
        self._next_check_s = 0.0

    def spawn(self, assets_directory: Path) -> None:
        """Start a worker (it reads uploaded files from ``assets_directory``); poll its socket."""
        identity = f"w{next(self._generation)}".encode()
        worker = start_worker(identity, self.config, assets_directory)
        self.workers[identity] = worker
        self.by_fd[worker.fd] = worker
        self._poller.register(worker.fd, _POLLIN)

    def wait_ready(self, serve: Callable[[WorkerRecord], None]) -> None:
        """Serve the workers' messages (``serve``) until every worker is ready.

        Raises:
            ServerStartError: A worker exited or did not report ready in time.
        """
        deadline = time.monotonic() + WORKER_START_TIMEOUT_S
        while not all(worker.ready for worker in self.workers.values()):
            for worker in self.workers.values():
                if worker.process.poll() is not None:
                    raise ServerStartError(
                        f"worker {worker.identity.decode()} exited with {worker.process.returncode}"
                    )
            if time.monotonic() > deadline:
                raise ServerStartError("workers did not start in time")
            for fd, _ in self._poller.poll(100):
                if fd in self.by_fd:
                    serve(self.by_fd[fd])

    def ready(self, worker: WorkerRecord) -> None:
        """A worker reported ready: send it what was held for it."""
        worker.ready = True
        log.info("worker %s ready", worker.identity.decode())
        backlog, worker.backlog = worker.backlog, []
        for message in backlog:
            self.send(worker.identity, message)

    def send(self, identity: bytes, frames: list[bytes]) -> bool:
        """Send to a worker (held until it is ready); ``False`` if it cannot take it now."""
        worker = self.workers.get(identity)
        if worker is None:
            return False
        if not worker.ready:
            worker.backlog.append(frames)
            return True
        if len(worker.channel.outgoing) > MAX_WORKER_BACKLOG_BYTES:
            log.warning("worker %s does not read: request refused", identity.decode())
            return False
        try:
            worker.channel.send(frames)
        except OSError as exc:  # dead: it is replaced
            log.warning("worker %s unreachable: %s", identity.decode(), exc)
            return False
        self._poll_output(worker)
        return True

    def flush(self, worker: WorkerRecord) -> None:
        """Write what waits for a worker's socket (it can take more)."""
        try:
            worker.channel.flush()
        except OSError as exc:
            log.warning("worker %s unreachable: %s", worker.identity.decode(), exc)
            worker.channel.outgoing.clear()
        self._poll_output(worker)

    def _poll_output(self, worker: WorkerRecord) -> None:
        """Poll the worker's socket for output while bytes wait for it, else not."""
        writing = bool(worker.channel.outgoing)
        if writing != worker.writing:
            worker.writing = writing
            self._poller.modify(worker.fd, _POLLIN | (_POLLOUT if writing else 0))

    def exited(self, worker: WorkerRecord, now: float) -> bool:
        """Whether the worker's process has exited, looked at once a check interval.

        Call :meth:`checked` after asking about every worker at ``now``.
        """
        if now > self._next_check_s and worker.process.poll() is not None:
            log.error("worker %s died (%s)", worker.identity.decode(), worker.process.returncode)
            return True
        return False

    def checked(self, now: float) -> None:
        """Every worker was asked :meth:`exited` at ``now``: the next check is due later."""
        if now > self._next_check_s:
            self._next_check_s = now + WORKER_CHECK_INTERVAL_S

    def kill(self, worker: WorkerRecord) -> None:
        """Kill a worker's process, close its socket and forget it."""
        worker.process.kill()
        worker.process.wait()
        self.detach(worker)
        worker.channel.close()
        del self.workers[worker.identity]

    def detach(self, worker: WorkerRecord) -> None:
        """Stop polling the worker's socket."""
        if self.by_fd.get(worker.fd) is worker:
            self._poller.unregister(worker.fd)
            del self.by_fd[worker.fd]

    def stop(self) -> None:
        """Ask every worker to stop, close their sockets, wait for them (kill after 2 s)."""
        for worker in self.workers.values():
            if worker.ready and worker.process.poll() is None:
                try:
                    worker.channel.send([b"stop"])
                except OSError:
                    pass
            self.detach(worker)
            worker.channel.close()  # a worker still warming up reads EOF and exits
        for worker in self.workers.values():
            try:
                worker.process.wait(2.0)
            except subprocess.TimeoutExpired:
                worker.process.kill()
                worker.process.wait()
        self.workers.clear()
        self.by_fd.clear()
