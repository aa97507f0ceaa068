"""``poise bridge`` through its command line: an emulated run, e-stops, one-line mistakes."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.e2e

EXAMPLE = Path(__file__).parents[3] / "examples" / "bridge" / "revolute_humanoid_mit.toml"


def poise(*args: str, **options) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "controller_server.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        **options,
    )


def test_an_emulated_run_prints_timing_and_links_and_writes_its_report(tmp_path, server):
    report, log = tmp_path / "report.json", tmp_path / "bridge.mcap"
    run = poise(
        "bridge", str(EXAMPLE), "--emulate", "--duration", "0.5",
        "--connect", server.endpoint, "--report", str(report), "--record", str(log),
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "stopped: duration; safe state latched 0 time(s)" in run.stdout
    assert "emulated robot: stayed up over 0.50 s simulated" in run.stdout
    assert "left_knee" in run.stdout and "loop: 250 ticks" in run.stdout
    data = json.loads(report.read_text())
    # every tick's state is answered in time or counted late (a busy machine: issue 33)
    assert data["ticks"] == 250 and data["commands"] + data["server_timeouts"] == 251
    assert data["server_timeouts"] <= 0.05 * 250 and data["latches"] == []
    assert len(data["links"]) == 22 and data["emulation"]["fell"] is False
    info = poise("log", "info", str(log))  # the session was recorded like any client's
    assert info.returncode == 0, info.stderr
    assert re.search(r"state sent\s+251\n", info.stdout), info.stdout
    received = int(re.search(r"command received\s+(\d+)\n", info.stdout).group(1))
    assert data["commands"] <= received <= 251, info.stdout


def test_estop_typed_on_stdin_holds_safe_disables_and_exits_1(server):
    run = poise(
        "bridge", str(EXAMPLE), "--emulate", "--duration", "0", "--connect", server.endpoint,
        input="estop\n",
    )  # fmt: skip
    assert run.returncode == 1, run.stderr
    assert "stopped: estop" in run.stdout and "e-stop: operator" in run.stdout


def test_sigterm_is_an_estop_with_exit_code_130(server):
    process = subprocess.Popen(
        [sys.executable, "-m", "controller_server.cli", "--log-level", "INFO", "bridge",
         str(EXAMPLE), "--emulate", "--duration", "0", "--connect", server.endpoint],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        assert process.stderr is not None
        while time.monotonic() < deadline:  # wait until the actuators are enabled
            if "enabled 22 actuators" in process.stderr.readline():
                break
        time.sleep(0.5)
        process.send_signal(signal.SIGTERM)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 130, stderr
    assert "stopped: interrupted" in stdout
    assert "e-stop: interrupted (SIGINT/SIGTERM)" in stdout


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (None, "no bridge file"),
        (
            "gear_ration = 2",
            "unknown key 'joints.left_knee.gear_ration'; did you mean 'gear_ratio'?",
        ),
        ('motor = "AK80_64"', "not a mit motor model; did you mean 'AK80-64'?"),
    ],
)
def test_a_users_mistake_in_the_map_is_one_line(tmp_path, edit, message):
    path = tmp_path / "map.toml"
    if edit is not None:
        text = EXAMPLE.read_text()
        anchor = '[joints.left_knee]\nbus = "left_leg"\nid = 4\nmotor = "AK80-64"\n'
        assert anchor in text
        if edit.startswith("motor"):  # the knee's motor line replaced
            edited = anchor.replace('motor = "AK80-64"', edit)
        else:  # a line added to the knee's table
            edited = anchor + edit + "\n"
        path.write_text(text.replace(anchor, edited))
    run = poise("bridge", str(path), "--emulate", "--connect", "tcp://127.0.0.1:1")
    assert run.returncode == 2, run.stderr
    assert message in run.stderr and "Traceback" not in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr


def test_hardware_that_is_not_there_is_one_line(tmp_path, server):
    text = EXAMPLE.read_text().replace('base_state = "simulator"', 'base_state = "fixed"')
    path = tmp_path / "map.toml"
    path.write_text(text.replace('channel = "can0"', 'channel = "poise-no-such-can"'))
    run = poise("bridge", str(path), "--connect", server.endpoint)
    assert run.returncode == 2, run.stderr
    assert "bus 'left_leg': cannot open CAN interface 'socketcan' channel 'poise-no-such-can'" in (
        run.stderr
    )
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr


def test_simulator_ground_truth_without_emulation_is_refused(server):
    run = poise("bridge", str(EXAMPLE), "--connect", server.endpoint)
    assert run.returncode == 2
    assert 'base_state = "simulator" is the emulated robot\'s ground truth' in run.stderr
