"""`poise sim` exit codes: 0 when every robot stayed up, 1 when one fell (as `poise demo`)."""

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.e2e

FALLS = """
name = "falls"
description = "A 1500 N shove to the chest from the front for 0.2 s: the robot falls at once."
duration_s = 1.0

[[pushes]]
body = "chest"
force_in_world_N = [-1500.0, 0.0, 0.0]
start_s = 0.0
duration_s = 0.2
"""


def poise_sim(tmp_path, endpoint, *scenarios):
    options = ["--connect", endpoint, "--output", str(tmp_path / "out")]
    return subprocess.run(
        [sys.executable, "-m", "controller_server.cli", "sim", *scenarios, *options],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_sim_exits_1_when_a_robot_fell(server, tmp_path):
    falls = tmp_path / "falls.toml"
    falls.write_text(FALLS)
    result = poise_sim(tmp_path, server.endpoint, str(falls))
    assert result.returncode == 1, result.stderr
    assert "fell" in result.stdout
    (report,) = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["fell"]


def test_sim_exits_0_when_every_robot_stayed_up(server, tmp_path):
    stand = tmp_path / "short_stand.toml"
    stand.write_text('name = "short_stand"\nduration_s = 0.2\n')
    result = poise_sim(tmp_path, server.endpoint, str(stand))
    assert result.returncode == 0, result.stderr
    assert "stayed up" in result.stdout
