"""Shared fixtures; BLAS on one thread; the tests must leave the tree as they found it."""

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before anything imports numpy (`poise` does the same)

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
import zmq  # noqa: E402
from hypothesis import settings  # noqa: E402

from clients.pool import BATCH_DEADLINE_S  # noqa: E402
from clients.server_process import ServerProcess  # noqa: E402
from controller_server import files  # noqa: E402
from tests.worktree import changes, tree_status  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _close_without_term(context: zmq.Context) -> None:
    """What a ZeroMQ context left to the garbage collector does in the tests.

    pyzmq's ``Context.__del__`` closes the context's sockets and calls ``term()``,
    which waits for every socket of the context to close. A clean-clone run hung
    there for good, in a hypothesis test long after the test that had left the
    context behind (one that failed before closing its peers). Here the sockets
    are closed with linger 0 and the context is left to the process's exit: a
    test that leaks a context fails or leaks, it does not hang the suite.
    """
    for socket in list(getattr(context, "_sockets", None) or []):
        if socket is not None and not socket.closed:
            socket.close(linger=0)


zmq.Context.__del__ = _close_without_term  # type: ignore[method-assign]

settings.register_profile("default", max_examples=100)
settings.register_profile("nightly", max_examples=1000)
"""``pytest --hypothesis-profile nightly``: every property and fuzz test at its full count
(:func:`tests.helpers.examples`), ten times what every run draws."""
_TREE_AT_START = pytest.StashKey[frozenset[str] | None]()


def pytest_sessionstart(session):
    session.config.stash[_TREE_AT_START] = tree_status(ROOT)


def pytest_sessionfinish(session, exitstatus):
    """Fail the run if it wrote into the working tree (compared with its start, not with HEAD)."""
    before = session.config.stash.get(_TREE_AT_START, None)
    after = tree_status(ROOT)
    if before is None or after is None:
        return
    changed = changes(before, after)
    if not changed:
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    message = "the tests changed the working tree (`git status`): " + "; ".join(changed)
    if reporter is not None:
        reporter.line("")
        reporter.write_line(message, red=True, bold=True)
    if session.exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


@pytest.fixture(scope="module")
def server():
    """A real `poise serve` process on a free loopback port, stopped after the module.

    Its deadline is a batch's (``BATCH_DEADLINE_S``, as ``poise sim`` gives its own server):
    the tests run simulations in lockstep, where a tick answered late on a busy machine
    costs the robot nothing, but under the 0.5 s default it would be a ``DEADLINE_EXCEEDED``
    that a run reads as a fall. Tests of the deadline start servers of their own.
    """
    with ServerProcess(extra_args=["--deadline", f"{BATCH_DEADLINE_S:g}"]) as process:
        yield process


@pytest.fixture
def allow_model_dir():
    """``allow(*dirs, max_file_bytes=...)`` sets the server's model directories for one test.

    The policy in force before the test is restored after it.
    """
    saved = (files.model_directories(), files.max_file_bytes())

    def allow(*dirs, max_file_bytes=files.DEFAULT_MAX_FILE_BYTES):
        files.set_model_directories(dirs, max_file_bytes=max_file_bytes)

    yield allow
    files.set_model_directories(saved[0], max_file_bytes=saved[1])
