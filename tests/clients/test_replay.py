"""Replay: a recorded simulator run against a real server is a regression test."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from clients.log_info import summarize_log
from clients.replay import ReplayError, replay_log
from clients.sim.runner import run_scenario
from clients.sim.scenario import load_scenario
from protocol.messages import Hello
from protocol.recording import Recorder
from tests.protocol.samples import sample_messages

pytestmark = pytest.mark.e2e

TICKS = 150


@pytest.fixture(scope="module")
def recorded_run(server, tmp_path_factory):
    """`stand` for 0.15 s in the reference simulator, recorded by the client."""
    path = tmp_path_factory.mktemp("logs") / "stand.mcap"
    scenario = load_scenario("stand", duration_s=TICKS / 1000)
    record = run_scenario(scenario, server.endpoint, log_path=path)
    assert not record.fell
    return path


def test_the_same_code_reproduces_every_command(server, recorded_run):
    report = replay_log(recorded_run, server.endpoint)
    assert report.compared == TICKS
    assert not report.regression
    assert report.max_abs_error <= 1e-9


def test_a_changed_gain_is_a_regression_naming_seq_and_fields(server, recorded_run):
    report = replay_log(recorded_run, server.endpoint, params={"stiffness": 40.0})
    assert report.regression
    assert report.first_divergent_seq is not None and report.first_divergent_seq >= 2
    assert "joint_torque" in report.divergent_fields
    assert report.max_abs_error > 1e-3


def command(*args):
    return subprocess.run(
        [sys.executable, "-m", "controller_server.cli", "--log-level", "WARNING", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_poise_replay_exit_codes_and_report(server, recorded_run, tmp_path):
    clean = command("replay", str(recorded_run), "--connect", server.endpoint)
    assert clean.returncode == 0, clean.stderr
    assert f"compared {TICKS} commands" in clean.stdout
    report_path = tmp_path / "report.json"
    changed = command(
        "replay", str(recorded_run), "--connect", server.endpoint,
        "--set", "stiffness=40", "--json", str(report_path),
    )  # fmt: skip
    assert changed.returncode == 1
    assert "REGRESSION" in changed.stdout and "joint_torque" in changed.stdout
    assert json.loads(report_path.read_text())["regression"] is True


@pytest.mark.parametrize("content", [b"", b"not a log at all\n"])
def test_a_bad_log_is_one_line_and_exit_code_2(server, tmp_path, content):
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    result = command("replay", str(path), "--connect", server.endpoint)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "Traceback" not in result.stderr


def test_a_log_of_another_model_is_refused_saying_why(server, tmp_path):
    welcome = next(m for m in sample_messages() if m.type == "welcome")
    path = tmp_path / "other.mcap"
    with Recorder(path) as recorder:
        recorder.record(Hello(seq=1, model="thesis_humanoid"), "sent")
        recorder.record(welcome.model_copy(update={"model_hash": "0" * 64}), "received")
    with pytest.raises(ReplayError, match=r"MODEL_MISMATCH.*recorded with"):
        replay_log(path, server.endpoint)


FIXTURES = sorted((Path(__file__).parents[1] / "fixtures").glob("*.mcap"))


@pytest.mark.parametrize("fixture", FIXTURES, ids=[path.stem for path in FIXTURES])
def test_committed_fixtures_replay_clean(server, fixture):
    """README "When replay fails": a change meant to keep behaviour keeps these passing."""
    report = replay_log(fixture, server.endpoint)
    states = summarize_log(fixture).counts["state sent"]
    assert states > 0 and report.compared == states
    assert not report.regression, report


def test_poise_log_info_reads_the_fixtures():
    assert len(FIXTURES) >= 2
    for fixture in FIXTURES:
        result = command("log", "info", str(fixture))
        assert result.returncode == 0, result.stderr
        assert "session 1: model thesis_humanoid" in result.stdout
        assert "state sent" in result.stdout
