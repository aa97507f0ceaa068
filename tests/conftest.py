import pytest

from clients.server_process import ServerProcess


@pytest.fixture(scope="module")
def server():
    """A real `poise serve` process on a free loopback port, stopped after the module."""
    with ServerProcess() as process:
        yield process
