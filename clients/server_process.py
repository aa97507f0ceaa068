"""Start and stop a real ``poise serve`` process (demo, tests, benchmarks)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from types import TracebackType

__all__ = ["ServerProcess"]

READY_PREFIX = "poise serve: listening on "
"""Printed by ``poise serve`` once it answers at once (``controller_server.cli``)."""


class ServerProcess:
    """``poise serve`` in a child process, bound to a free loopback port.

    Use as a context manager; :attr:`endpoint` is known once it is entered.
    Leaving the block sends SIGTERM and waits for a clean exit.

    Args:
        bind: Endpoints to bind; the default picks a free TCP port.
        extra_args: More ``poise serve`` options.
        start_timeout_s: How long to wait for the server to listen.
    """

    def __init__(
        self,
        bind: Sequence[str] = ("tcp://127.0.0.1:*",),
        extra_args: Sequence[str] = (),
        start_timeout_s: float = 60.0,
    ):
        self.command = [
            sys.executable,
            "-m",
            "controller_server.cli",
            "--log-level",
            "WARNING",
            "serve",
        ]
        for endpoint in bind:
            self.command += ["--bind", endpoint]
        self.command += list(extra_args)
        self.start_timeout_s = start_timeout_s
        self.process: subprocess.Popen[str] | None = None
        self.endpoints: list[str] = []

    @property
    def endpoint(self) -> str:
        """The first bound endpoint."""
        return self.endpoints[0]

    def start(self) -> ServerProcess:
        """Start the process and wait until it listens."""
        self.process = subprocess.Popen(
            self.command,
            stdout=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        deadline = time.monotonic() + self.start_timeout_s
        assert self.process.stdout is not None
        while time.monotonic() < deadline:
            line = self.process.stdout.readline()
            if line.startswith(READY_PREFIX):
                self.endpoints = line[len(READY_PREFIX) :].strip().split(", ")
                return self
            if not line and self.process.poll() is not None:
                break
        self.stop()
        raise RuntimeError(f"`{' '.join(self.command)}` did not start listening")

    def stop(self, timeout_s: float = 10.0) -> int | None:
        """SIGTERM, wait, and return the exit code (kill if it hangs)."""
        if self.process is None:
            return None
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()
        return self.process.returncode

    def __enter__(self) -> ServerProcess:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.stop()
