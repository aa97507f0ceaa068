"""Replay: a recorded simulator run against a real server is a regression test."""

import contextlib
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from clients.log_info import summarize_log
from clients.replay import ReplayError, replay_log
from clients.server_process import ServerProcess
from clients.sim.runner import run_scenario
from clients.sim.scenario import load_scenario
from protocol.messages import PROTOCOL_VERSION, Hello
from protocol.recording import BadLog, Recorder
from tests.protocol.samples import sample_messages

pytestmark = pytest.mark.e2e

TICKS = 700


@pytest.fixture(scope="module")
def recorded_run(server, tmp_path_factory):
    """`push_sequence` up to the end of its first push (0.5-0.6 s), recorded by the client."""
    path = tmp_path_factory.mktemp("logs") / "push_sequence.mcap"
    scenario = load_scenario("push_sequence", duration_s=TICKS / 1000)
    record = run_scenario(scenario, server.endpoint, log_path=path)
    assert not record.fell
    assert len(record.commands) == TICKS
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


@pytest.mark.slow
def test_poise_replay_exit_codes_and_report(server, recorded_run, tmp_path):
    clean = command("replay", str(recorded_run), "--connect", server.endpoint)
    assert clean.returncode == 0, clean.stderr
    assert f"sent {TICKS} requests, compared {TICKS} commands" in clean.stdout
    report_path = tmp_path / "report.json"
    changed = command(
        "replay", str(recorded_run), "--connect", server.endpoint,
        "--set", "stiffness=40", "--json", str(report_path),
    )  # fmt: skip
    assert changed.returncode == 1
    assert "REGRESSION" in changed.stdout and "joint_torque" in changed.stdout
    assert json.loads(report_path.read_text())["regression"] is True


def test_a_server_that_cannot_answer_in_time_is_exit_code_3_not_a_regression(tmp_path):
    """Issue 40: replay died on DEADLINE_EXCEEDED with exit 2, the code of an unusable log.

    Its own server gets ``--deadline`` (default a sweep's 10 s); one given 0.5 ms cannot
    answer a state, which is neither a match nor a regression."""
    fixture = str(FIXTURES[0])
    late = command("replay", fixture, "--deadline", "0.0005")
    assert late.returncode == 3, (late.stdout, late.stderr)
    assert late.stderr.count("\n") == 1 and "did not answer in time" in late.stderr, late.stderr
    assert "--deadline" in late.stderr and "REGRESSION" not in late.stdout
    with ServerProcess(extra_args=["--deadline", "0.0005"]) as server:
        assert command("replay", fixture, "--connect", server.endpoint).returncode == 3


@contextlib.contextmanager
def cpu_burners(count: int):
    """``count`` processes spinning on the CPU (a shared 2-core machine), killed after."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]
    try:
        yield
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()


@pytest.mark.slow
def test_the_readmes_replay_is_a_regression_on_a_busy_machine():
    """Issue 40: beside CPU burners the README's example died on DEADLINE_EXCEEDED, exit 2.

    Its own server answers within a sweep's deadline, so a changed gain is what it
    reports, however busy the machine: REGRESSION, exit code 1.
    """
    fixture = Path(__file__).parents[1] / "fixtures" / "replay_momentum_push.mcap"
    with cpu_burners(2):
        changed = command("replay", str(fixture), "--set", "stiffness=40")
    assert changed.returncode == 1, (changed.stdout, changed.stderr)
    assert "REGRESSION" in changed.stdout


@pytest.mark.parametrize("content", [b"", b"not a log at all\n"])
def test_a_bad_log_is_one_line_and_exit_code_2(server, tmp_path, content):
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    result = command("replay", str(path), "--connect", server.endpoint)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "Traceback" not in result.stderr


def test_a_log_of_another_protocol_version_is_refused_saying_what_to_do(server, tmp_path):
    welcome = next(m for m in sample_messages() if m.type == "welcome")
    path = tmp_path / "old.mcap"
    with Recorder(path) as recorder:
        recorder.record(Hello(seq=1, version=PROTOCOL_VERSION + 1, model="thesis_humanoid"), "sent")
        recorder.record(welcome, "received")
    result = command("replay", str(path), "--connect", server.endpoint)
    assert result.returncode == 2
    assert f"recorded with protocol version {PROTOCOL_VERSION + 1}" in result.stderr
    assert "re-record" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_a_log_of_another_model_is_refused_saying_why(server, tmp_path):
    welcome, state, reply = (
        next(m for m in sample_messages() if m.type == kind)
        for kind in ("welcome", "state", "command")
    )
    path = tmp_path / "other.mcap"
    with Recorder(path) as recorder:
        recorder.record(Hello(seq=1, model="thesis_humanoid"), "sent")
        recorder.record(welcome.model_copy(update={"model_hash": "0" * 64}), "received")
        recorder.record(state, "sent")  # a command to compare: a log a replay would check
        recorder.record(reply, "received")
    with pytest.raises(ReplayError, match=r"MODEL_MISMATCH.*recorded with"):
        replay_log(path, server.endpoint)


FIXTURES = sorted((Path(__file__).parents[1] / "fixtures").glob("*.mcap"))


@pytest.mark.parametrize("fixture", FIXTURES, ids=[path.stem for path in FIXTURES])
def test_committed_fixtures_replay_clean(server, fixture):
    """A change meant to keep behaviour keeps these passing (docs/recording.md)."""
    report = replay_log(fixture, server.endpoint)
    states = summarize_log(fixture).counts["state sent"]
    assert states > 0 and report.compared == states
    assert not report.regression, report


def test_poise_log_plot_draws_the_fixtures(tmp_path):
    result = command("log", "plot", *map(str, FIXTURES), "--output", str(tmp_path))
    assert result.returncode == 0, result.stderr
    for fixture in FIXTURES:
        png = (tmp_path / f"{fixture.stem}.png").read_bytes()
        assert png.startswith(b"\x89PNG") and len(png) > 20_000


def test_poise_log_plot_of_a_log_without_commands_is_one_line_and_exit_code_2(tmp_path):
    welcome = next(m for m in sample_messages() if m.type == "welcome")
    path = tmp_path / "handshake_only.mcap"
    with Recorder(path) as recorder:
        recorder.record(Hello(seq=1, model="thesis_humanoid"), "sent")
        recorder.record(welcome, "received")
    result = command("log", "plot", str(path), "--output", str(tmp_path))
    assert result.returncode == 2
    assert "nothing to plot" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_poise_log_info_reads_the_fixtures():
    assert len(FIXTURES) >= 2
    for fixture in FIXTURES:
        result = command("log", "info", str(fixture))
        assert result.returncode == 0, result.stderr
        assert "session 1: model thesis_humanoid" in result.stdout
        assert "state sent" in result.stdout
        # the recorded hello's parameters, one per line under a count (issue 40)
        lines = result.stdout.splitlines()
        start = next(i for i, line in enumerate(lines) if line.startswith("  parameters ("))
        count = int(lines[start].split("(")[1].split(")")[0])
        block = [line for line in lines[start + 1 :] if line.startswith("    ")]
        assert all(len(line) <= 96 for line in block)  # long lists wrap, indented further
        names = [line.split()[0] for line in block if not line.startswith("     ")]
        assert len(names) == count and names == sorted(names) and "cop_margin" in names


SIGKILL_AFTER_STATES = 300


@pytest.mark.slow
def test_a_recording_client_killed_mid_run_leaves_a_log_that_replays_up_to_the_kill(
    server, tmp_path
):
    """`poise sim --record` killed by SIGKILL: its log replays clean, with a warning."""
    child = subprocess.Popen(
        [
            sys.executable, "-m", "controller_server.cli", "--log-level", "WARNING",
            "sim", "stand", "--connect", server.endpoint,
            "--record", str(tmp_path), "--output", str(tmp_path / "out"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    log_path = tmp_path / "stand.mcap"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and child.poll() is None:
            time.sleep(0.2)  # the writer flushes every 0.1 s: count what reached the disk
            if log_path.exists() and _states_on_disk(log_path) >= SIGKILL_AFTER_STATES:
                break
    finally:
        child.kill()
        child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL, "the run ended before the kill"
    summary = summarize_log(log_path)
    states, commands = summary.counts["state sent"], summary.counts["command received"]
    assert states >= SIGKILL_AFTER_STATES and commands >= states - 1

    report = replay_log(log_path, server.endpoint)
    assert report.log_truncated
    assert report.requests_sent == states and report.compared == commands
    assert not report.regression, report

    result = command("replay", str(log_path), "--connect", server.endpoint)
    assert result.returncode == 0, result.stderr
    warning = f"the log ends early (its recorder was killed?): replayed the {report.messages_read}"
    assert warning in result.stdout


def _states_on_disk(path: Path) -> int:
    with contextlib.suppress(BadLog):
        return summarize_log(path).counts["state sent"]
    return 0


@pytest.mark.slow
def test_poise_serve_record_writes_one_log_per_session_that_replays_clean(tmp_path):
    record_dir = tmp_path / "server-logs"
    with ServerProcess(extra_args=["--record", str(record_dir)]) as recording_server:
        for duration_s in (0.05, 0.03):
            scenario = load_scenario("stand", duration_s=duration_s)
            run_scenario(scenario, recording_server.endpoint)
    logs = sorted(record_dir.glob("*.mcap"))
    assert len(logs) == 2, logs
    states = sorted(summarize_log(log).counts["state received"] for log in logs)
    assert states == [30, 50]
    for log in logs:
        summary = summarize_log(log)
        assert summary.counts["hello received"] == 1 and summary.counts["welcome sent"] == 1
        assert summary.counts["bye received"] == 1 and summary.counts["bye sent"] == 1
        assert summary.counts["command sent"] == summary.counts["state received"]
    # A server's log (requests received, replies sent) replays like a client's.
    with ServerProcess() as plain_server:
        for log in logs:
            report = replay_log(log, plain_server.endpoint)
            assert report.compared == summarize_log(log).counts["state received"]
            assert not report.regression and not report.log_truncated
