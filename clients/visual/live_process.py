"""The live view in a process of its own, for a loop that must never wait on it: the bridge's.

:class:`LiveViewProcess` serves the page of :class:`~clients.visual.live.LiveView`
from a child process (``python -m clients.visual.live_process``: it shares
nothing with this one but two pipes), so drawing never holds this
interpreter's lock while a control loop wants it. Its :meth:`~LiveViewProcess.observe` is a run
observer (:data:`~clients.track.RunObserver`) that takes a few microseconds
and never blocks: it keeps a tick only if the last kept one is
``1 / VIEW_HZ`` s old (:data:`~clients.visual.live.VIEW_HZ`), or if it
carries diagnostics and the last kept diagnostics are ``1 / DIAGNOSTICS_HZ``
s old, in a deque of ``QUEUE_TICKS`` that drops its oldest entry when full.
A thread of this process sends what the deque holds to the child
``SEND_HZ`` times a second through a pipe (each command as its wire bytes,
about 30 µs a tick with the state); the child adds the ticks to its own copy
of the track and shows it, at a lower scheduling priority. A slow child makes the
deque drop ticks; a child that stops makes the thread log one warning and
the page go still. The loop sees neither.
"""

from __future__ import annotations

import collections
import logging
import math
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from clients.track import Track
from protocol import codec
from protocol.errors import PoiseError
from protocol.messages import Command

__all__ = [
    "DIAGNOSTICS_HZ",
    "QUEUE_TICKS",
    "SEND_HZ",
    "LiveViewError",
    "LiveViewProcess",
]

log = logging.getLogger("poise.view")

DIAGNOSTICS_HZ = 50.0
"""Most ticks with diagnostics kept per second (the plots' points, the COP and CMP)."""
QUEUE_TICKS = 256
"""Ticks waiting for the sending thread at most; the oldest go first."""
SEND_HZ = 60.0
"""How often the sending thread sends what waits."""
CHILD_NICENESS = 19
"""How much lower the child's scheduling priority is (``nice``): the view is best effort."""
START_TIMEOUT_S = 60.0
"""How long the child may take to serve its page (it imports MuJoCo and viser)."""


class LiveViewError(PoiseError, RuntimeError):
    """The live view's process did not start serving."""


class LiveViewProcess:
    """``view = LiveViewProcess(port)``, ``view.observe(track)`` every tick, ``view.close()``.

    Args:
        host: Interface to serve on (default loopback only).
        port: TCP port of the page (the next free one if taken).
        start_timeout_s: How long to wait for the child to serve.

    Raises:
        LiveViewError: The child stopped, or did not serve in time.
    """

    def __init__(
        self, host: str = "127.0.0.1", port: int = 8080, start_timeout_s: float = START_TIMEOUT_S
    ):
        from clients.visual.live import VIEW_HZ

        self._pose_period_s = 1.0 / VIEW_HZ
        child_ticks, ticks_out = os.pipe()
        url_in, child_url = os.pipe()
        package_root = str(Path(__file__).resolve().parents[2])
        path = os.pathsep.join(filter(None, (package_root, os.environ.get("PYTHONPATH"))))
        self._process = subprocess.Popen(
            [sys.executable, "-m", __name__, host, str(port), str(child_ticks), str(child_url)],
            pass_fds=(child_ticks, child_url),
            stdin=subprocess.DEVNULL,
            env={**os.environ, "PYTHONPATH": path},
        )
        os.close(child_ticks)
        os.close(child_url)
        self._ticks_out = Connection(ticks_out, readable=False)
        url = Connection(url_in, writable=False)
        try:
            if not url.poll(start_timeout_s):
                raise LiveViewError(f"the live view did not serve its page in {start_timeout_s} s")
            self.url: str = url.recv()
        except (EOFError, LiveViewError) as exc:
            self._process.kill()
            code = self._process.wait(timeout=10)
            self._ticks_out.close()
            if isinstance(exc, LiveViewError):
                raise
            raise LiveViewError(
                f"the live view's process stopped (exit code {code}) before serving its page: "
                "its error is above"
            ) from None
        finally:
            url.close()
        self._runs: queue.SimpleQueue[tuple[int, Track]] = queue.SimpleQueue()
        self._queue: collections.deque[tuple[int, float, Any, Any]] = collections.deque(
            maxlen=QUEUE_TICKS
        )
        self._track: Track | None = None
        self._run = 0
        self._kept_s = self._kept_diagnostics_s = -math.inf
        self._stop = threading.Event()
        self._sender = threading.Thread(target=self._send, name="poise-view-sender", daemon=True)
        self._sender.start()

    def observe(self, track: Track) -> None:
        """A run observer: keep the track's last tick for the child, or drop it (never waits)."""
        if not track.states:
            return
        if track is not self._track:
            self._track = track
            self._run += 1
            self._runs.put((self._run, track.empty()))
        command = track.commands[-1]
        now = time.monotonic()
        if now - self._kept_s >= self._pose_period_s:
            self._kept_s = now
        elif command.diagnostics is None or now - self._kept_diagnostics_s < 1.0 / DIAGNOSTICS_HZ:
            return
        if command.diagnostics is not None:
            self._kept_diagnostics_s = now
        self._queue.append((self._run, track.time_s[-1], track.states[-1], command))

    def close(self) -> None:
        """Stop the sending thread and the child (it stops serving)."""
        self._stop.set()
        self._sender.join(timeout=10)
        self._ticks_out.close()  # the child reads the end of its input and stops
        try:
            self._process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait(timeout=10)

    def _send(self) -> None:
        """The sending thread: what waits, to the child, ``SEND_HZ`` times a second."""
        while not self._stop.wait(1.0 / SEND_HZ):
            runs = []
            while True:
                try:
                    runs.append(self._runs.get_nowait())
                except queue.Empty:
                    break
            ticks = []
            while self._queue:  # a command as its wire bytes: a tenth of pickle's time
                run, time_s, state, command = self._queue.popleft()
                ticks.append((run, time_s, state, codec.encode(command)))
            if not (runs or ticks):
                continue
            try:
                self._ticks_out.send((runs, ticks))
            except (OSError, ValueError) as exc:  # the child stopped: the run goes on
                log.warning("the live view stopped (%s); the run goes on without it", exc)
                return


def _serve(host: str, port: int, ticks: Connection, url: Connection) -> None:
    """The child: serve the page, add the ticks received to their run's track, show it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the parent, which stops this
    os.nice(CHILD_NICENESS)  # on a busy machine the loop's process gets the CPU first
    from clients.visual.live import LiveView

    view = LiveView(host, port)
    url.send(view.url)
    url.close()
    runs: dict[int, Track] = {}
    shown: Track | None = None
    try:
        while True:
            try:
                new_runs, batch = ticks.recv()
            except EOFError:  # the parent closed the pipe (or exited)
                return
            for run, track in new_runs:
                runs = {run: track}  # the newest run only
            for run, time_s, state, command in batch:
                track = runs.get(run)
                decoded = codec.decode(command)
                if track is not None and isinstance(decoded, Command):
                    track.add(time_s, state, decoded)
                    shown = track
            if shown is not None:
                view.observe(shown)
    finally:
        view.close()


if __name__ == "__main__":  # the child: HOST PORT TICKS_FD URL_FD
    host, port, ticks_fd, url_fd = sys.argv[1:5]
    _serve(
        host,
        int(port),
        Connection(int(ticks_fd), writable=False),
        Connection(int(url_fd), readable=False),
    )
