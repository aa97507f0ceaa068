"""A run's outputs: one run per output directory, partial reports, raw time series."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from clients.log_info import summarize_log
from clients.sim.app import run_scenarios
from clients.sim.output import OutputDirectory
from protocol.recording import BadLog, read_log

pytestmark = pytest.mark.e2e


def poise(*args: str) -> list[str]:
    return [sys.executable, "-m", "controller_server.cli", "--log-level", "WARNING", *args]


def test_a_second_run_into_a_busy_output_directory_is_refused_in_one_line(server, tmp_path):
    with OutputDirectory(tmp_path):
        result = subprocess.run(
            poise("sim", "stand", "--connect", server.endpoint, "--output", str(tmp_path)),
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert result.returncode == 2
    assert "being written by another run" in result.stderr and "--output" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "report.json").exists()
    with OutputDirectory(tmp_path):  # free again once the holder is done
        pass


def test_sigterm_mid_run_leaves_a_partial_report_and_plot(server, tmp_path):
    scenario = tmp_path / "long_stand.toml"
    scenario.write_text('name = "long_stand"\nmodel = "thesis_humanoid"\nduration_s = 30.0\n')
    output, logs = tmp_path / "out", tmp_path / "logs"
    child = subprocess.Popen(
        poise(
            "sim",
            str(scenario),
            "--connect",
            server.endpoint,
            *["--output", str(output)],
            *["--record", str(logs)],
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and child.poll() is None:
            time.sleep(0.2)
            if _states_on_disk(logs / "long_stand.mcap") >= 200:
                break
        child.send_signal(signal.SIGTERM)
        stdout, stderr = child.communicate(timeout=60)
    finally:
        child.kill()
    assert child.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    (report,) = json.loads((output / "report.json").read_text())
    assert report["complete"] is False and report["stopped"] == "interrupted"
    assert 0.2 <= report["simulated_s"] < 30.0 and not report["fell"]
    assert (output / "long_stand.png").stat().st_size > 10_000
    assert "stopped" in stdout


def _states_on_disk(path) -> int:
    try:
        return summarize_log(path).counts["state sent"]
    except (BadLog, FileNotFoundError):
        return 0


def test_series_hold_the_states_and_commands_the_run_exchanged(server, tmp_path):
    scenario = tmp_path / "short.toml"
    scenario.write_text(
        'name = "short"\nmodel = "thesis_humanoid"\n'
        "duration_s = 0.05\ndiagnostics_period_ticks = 5\n"
    )
    (report,) = run_scenarios(
        [str(scenario)], tmp_path, server.endpoint, progress=False, record_dir=tmp_path, series=True
    )
    series = np.load(report["series"])
    logged = [entry.message for entry in read_log(tmp_path / "short.mcap")]
    states = [m for m in logged if m.type == "state"]
    commands = [m for m in logged if m.type == "command"]
    assert len(series["time_s"]) == len(states) == len(commands) == 50
    np.testing.assert_array_equal(series["joint_torque"], [c.joint_torque for c in commands])
    np.testing.assert_array_equal(series["joint_position"], [s.joint_position for s in states])
    np.testing.assert_array_equal(series["contact_flags"], [s.contact_flags for s in states])
    assert series["contact_wrench_in_world"].shape == (50, len(states[0].contact_flags), 6)
    np.testing.assert_array_equal(series["diagnosed_tick"], np.arange(0, 50, 5))
    com = [c.diagnostics.position_com_in_world for c in commands if c.diagnostics is not None]
    np.testing.assert_array_equal(series["diagnosed_position_com_in_world"], com)
    assert len(series["dof_names"]) == series["joint_torque"].shape[1]
