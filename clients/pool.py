"""Where simulator runs execute: in this process, a local process pool, or a Dask cluster.

Push sweeps and scenario batteries are many independent runs, each a client
of a server. A :class:`RunPool` runs them:

- ``workers=1`` (no ``dask``): one after the other in this process, each
  when it is submitted, so a run keeps its per-tick progress bar and Ctrl-C
  stops it as it stops a single scenario;
- ``workers=N``: ``N`` worker processes (``spawn``: no forked ZeroMQ
  context) sharing one ``poise serve --workers N``, started here unless
  ``endpoint`` names a running one. The server is a broker in front of
  worker processes and opens each new session on its least loaded worker
  (:mod:`controller_server.server`), so each client gets a server core of
  its own: one server serves ``N`` clients as fast as ``N`` servers would,
  and starts once;
- ``dask="tcp://scheduler:8786"``: the tasks of a ``dask.distributed``
  cluster (``concurrent.futures``-style, through ``Client.get_executor``).
  The runs use ``endpoint`` if given (it must be reachable from every Dask
  worker); otherwise each Dask worker starts its own loopback
  ``poise serve`` (as many server workers as it has threads) for as long as
  this pool is open (:class:`WorkerServer`).

A task is a module-level function called as ``fn(*args, endpoint=…,
curve=…, **kwargs)`` (the server to use, as :func:`~clients.sim.runner.run_scenario`
takes it). :meth:`RunPool.run` keeps up to :attr:`RunPool.capacity` tasks in
flight and hands each result back in the parent, where the caller decides what
runs next (a bisection's next force). Which task finishes first does not
change what a run computes: the simulation is deterministic given its inputs.
"""

from __future__ import annotations

import concurrent.futures as cf
import ctypes
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol, cast

from clients.client import CurveKeys
from clients.server_process import ServerProcess
from protocol.errors import PoiseError

if TYPE_CHECKING:
    from distributed import Client

__all__ = [
    "BATCH_DEADLINE_S",
    "DASK_CONNECT_TIMEOUT_S",
    "ClusterUnavailable",
    "RunPool",
    "Task",
    "TaskSource",
    "WorkerServer",
    "batch_server",
    "default_workers",
]

DASK_CONNECT_TIMEOUT_S = 10.0
"""How long to wait for a Dask scheduler to answer."""
BATCH_DEADLINE_S = 10.0
"""``--deadline`` of the servers a pool starts (``poise serve``'s default is 0.5 s): on a busy
machine a tick answered late would be ``DEADLINE_EXCEEDED``, which a run reads as a fall, so a
batch's results would depend on the load. A run that hangs still ends (the client's timeout)."""
WORKER_SERVER_PLUGIN = "poise-worker-server"
PR_SET_PDEATHSIG = 1
"""``prctl`` option (linux/prctl.h): the signal a process gets when its parent dies."""


class ClusterUnavailable(PoiseError, ConnectionError):
    """``--dask`` cannot be used: no scheduler answers, or ``dask.distributed`` is missing."""


def default_workers() -> int:
    """Worker processes of ``--workers``' default: the cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


@dataclass
class Task:
    """One run for the pool: ``fn(*args, endpoint=…, curve=…, **kwargs)``, tagged ``key``."""

    key: Any
    fn: Callable[..., Any]
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = field(default_factory=dict)


class TaskSource(Protocol):
    """What :meth:`RunPool.run` asks for work and tells of results."""

    def next_task(self) -> Task | None:
        """The next task that can start now, or ``None`` (none yet, or none left)."""

    def finished(self, task: Task, result: Any) -> None:
        """``task`` returned ``result`` (called in this process, one at a time)."""


class RunPool:
    """Runs tasks in this process, a local process pool or a Dask cluster (module docstring).

    Use as a context manager; leaving it stops the workers and the server it
    started (on an exception, e.g. Ctrl-C, running tasks are abandoned: local
    workers are terminated, Dask tasks cancelled).

    Args:
        workers: Local worker processes (1: in this process). Ignored with ``dask``.
        dask: Address of a Dask scheduler (``tcp://host:8786``).
        endpoint: A running server for every run (``None``: start one, see above).
        curve: CURVE keys for ``endpoint``.

    Raises:
        ClusterUnavailable: On entry, ``dask`` answers no scheduler or
            ``dask.distributed`` is not installed.
        ValueError: ``workers`` < 1.
    """

    def __init__(
        self,
        workers: int = 1,
        dask: str | None = None,
        endpoint: str | None = None,
        curve: CurveKeys | None = None,
    ):
        if workers < 1:
            raise ValueError(f"{workers=}: at least 1")
        self.workers = workers
        self.dask = dask
        self.endpoint = endpoint
        self.curve = curve
        self._server: ServerProcess | None = None
        self._executor: cf.Executor | None = None
        self._client: Client | None = None
        self._worker_servers = False
        self.capacity = 1
        """Tasks :meth:`run` keeps in flight: one per worker (thread, for Dask)."""

    @property
    def in_process(self) -> bool:
        """True if tasks run in this process, one at a time (a progress callback works)."""
        return self._executor is None

    def __enter__(self) -> RunPool:
        try:
            if self.dask is not None:
                self._client = _dask_client(self.dask)
                if self.endpoint is None:
                    self._client.register_plugin(WorkerServer(), name=WORKER_SERVER_PLUGIN)
                    self._worker_servers = True
                self._executor = self._client.get_executor(pure=False)
                self.capacity = max(1, sum(self._client.nthreads().values()))
            else:
                if self.endpoint is None:
                    self._server = batch_server(self.workers)
                    self.endpoint = self._server.start().endpoint
                if self.workers > 1:
                    self._executor = cf.ProcessPoolExecutor(
                        self.workers,
                        mp_context=multiprocessing.get_context("spawn"),
                        initializer=_start_worker,
                    )
                    self.capacity = self.workers
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        abandon = exc_type is not None
        if isinstance(self._executor, cf.ProcessPoolExecutor):
            if abandon:  # Python 3.11 has no terminate_workers(): a run may last minutes
                for process in list(getattr(self._executor, "_processes", {}).values()):
                    process.terminate()
            self._executor.shutdown(wait=True, cancel_futures=True)
        if self._client is not None:
            if self._executor is not None:
                self._executor.shutdown(wait=not abandon)
            if self._worker_servers:
                _quietly(self._client.unregister_worker_plugin, WORKER_SERVER_PLUGIN)
            self._client.close()
        if self._server is not None:
            self._server.stop()
        self._executor = self._client = self._server = None
        self._worker_servers = False

    def submit(self, task: Task) -> cf.Future[Any]:
        """Start ``task`` (in this process: run it now) and return its future."""
        kwargs = {"endpoint": self.endpoint, "curve": self.curve, **task.kwargs}
        if self._executor is None:
            future: cf.Future[Any] = cf.Future()
            try:
                future.set_result(task.fn(*task.args, **kwargs))
            except Exception as exc:
                future.set_exception(exc)
            return future
        if self._client is not None:
            return self._executor.submit(_on_dask_worker, task.fn, task.args, kwargs)
        return self._executor.submit(task.fn, *task.args, **kwargs)

    def run(self, source: TaskSource) -> None:
        """Run ``source``'s tasks, up to :attr:`capacity` at a time, until it has none left.

        Results are handed to ``source.finished`` as they come, in submission
        order among those that finished together.

        Raises:
            Exception: The first exception a task raised.
        """
        in_flight: dict[cf.Future[Any], Task] = {}
        while True:
            while len(in_flight) < self.capacity and (task := source.next_task()) is not None:
                in_flight[self.submit(task)] = task
            if not in_flight:
                return
            done, _ = cf.wait(in_flight, return_when=cf.FIRST_COMPLETED)
            for future in [f for f in in_flight if f in done]:
                source.finished(in_flight.pop(future), future.result())


def batch_server(workers: int) -> ServerProcess:
    """A loopback ``poise serve`` (not started) for ``workers`` clients at once.

    One session worker per client (all on this host, so one client to the server:
    it may occupy every worker), and a deadline of :data:`BATCH_DEADLINE_S`.
    """
    workers = max(1, workers)
    return ServerProcess(
        extra_args=[
            *("--workers", str(workers), "--max-workers-per-client", str(workers)),
            *("--deadline", f"{BATCH_DEADLINE_S:g}"),
        ]
    )


def _start_worker() -> None:
    """A local worker ignores the terminal's Ctrl-C: the parent stops it (no traceback each).

    On Linux it also gets SIGTERM if the parent dies (``PR_SET_PDEATHSIG``), so a
    ``poise sim`` killed outright leaves no worker running on.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM))
        if os.getppid() == 1:  # the parent died before prctl
            os._exit(1)


def _quietly(call: Callable[..., Any], *args: Any) -> None:
    try:
        call(*args)
    except Exception:  # cleanup of a cluster that may be gone already
        pass


def _dask_client(address: str) -> Client:
    try:
        from distributed import Client
    except ImportError:
        raise ClusterUnavailable(
            "--dask needs dask.distributed: pip install 'poise[dask]'"
        ) from None
    try:
        return Client(address, timeout=DASK_CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, ValueError, TypeError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ClusterUnavailable(
            f"--dask {address}: no Dask scheduler answered within "
            f"{DASK_CONNECT_TIMEOUT_S:g} s ({detail}); is `dask scheduler` running there?"
        ) from None


def _on_dask_worker(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    """Run a task on a Dask worker, against the worker's own server unless one was given."""
    if kwargs["endpoint"] is None:
        from distributed import get_worker

        worker = get_worker()
        plugin = cast(WorkerServer, worker.plugins[WORKER_SERVER_PLUGIN])
        kwargs = {**kwargs, "endpoint": plugin.endpoint(worker)}
    return fn(*args, **kwargs)


def _worker_plugin_base() -> type:
    try:
        from distributed.diagnostics.plugin import WorkerPlugin
    except ImportError:  # without the extra: never registered, see _dask_client
        return object
    return WorkerPlugin  # type: ignore[no-any-return]


class WorkerServer(_worker_plugin_base()):  # type: ignore[misc]
    """A Dask worker plugin: each worker runs a loopback ``poise serve`` while registered.

    The server has one session worker per thread of the Dask worker, so every
    task in flight there has a server core; it stops when the plugin is
    unregistered (:class:`RunPool` does on exit) or the worker closes.
    """

    def __init__(self) -> None:
        self._servers: dict[str, ServerProcess] = {}

    def setup(self, worker: Any) -> None:
        """Start the worker's server."""
        self._servers[worker.address] = batch_server(worker.state.nthreads).start()

    def teardown(self, worker: Any) -> None:
        """Stop the worker's server."""
        server = self._servers.pop(worker.address, None)
        if server is not None:
            server.stop()

    def endpoint(self, worker: Any) -> str:
        """The endpoint of ``worker``'s server."""
        return self._servers[worker.address].endpoint
