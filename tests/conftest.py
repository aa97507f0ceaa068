import pytest

from clients.server_process import ServerProcess
from controller_server import files


@pytest.fixture(scope="module")
def server():
    """A real `poise serve` process on a free loopback port, stopped after the module."""
    with ServerProcess() as process:
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
