"""Load on a real server: 8 clients paced at 1 kHz for 10 s, each gets its share.

Bounded (10 s of load on loopback), and it asserts no timing: every tick is
answered with a command or a typed error, none is lost, and no client is
starved (each gets at least half of what the best-served one gets).
"""

import pytest

from clients.load import run_clients
from protocol.messages import Hello

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

CLIENTS = 8
SECONDS = 10.0


def test_eight_clients_at_one_kilohertz_share_the_server(server):
    hello = Hello(model="thesis_humanoid", controller="momentum")
    loads = run_clients(
        server.endpoint, [(f"client {i}", hello, 1000.0) for i in range(CLIENTS)], SECONDS
    )
    print()
    for load in loads:
        print(
            f"{load.label}: {load.ticks} ticks, {load.commands} commands, p50 "
            f"{load.percentile_ms(50):.2f} ms, p99 {load.percentile_ms(99):.2f} ms, {load.errors}"
        )
    commands = [load.commands for load in loads]
    assert min(commands) > 0
    assert min(commands) >= 0.5 * max(commands), commands
    for load in loads:
        assert "timeout" not in load.errors, load  # every request got a reply
        assert set(load.errors) <= {"DEADLINE_EXCEEDED"}, load.errors
