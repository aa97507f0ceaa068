"""Videos of runs and logs through the real command line (issue 20, part 1).

``poise sim … --video`` starts a real server process, runs a short pushed
scenario in the reference simulator and renders it with MuJoCo offscreen;
``poise log video`` renders a committed log. The MP4s are opened with PyAV
(the encoder's own library) and checked frame by frame: the count, motion,
and the push arrow's red present exactly while the push acts.
"""

import subprocess
from pathlib import Path

import numpy as np
import pytest

from clients.visual.video import VIDEO_FPS
from tests.helpers import moved, red_pixels, run_poise, video_frames, yellow_pixels

pytestmark = pytest.mark.e2e

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
PUSH_START_S, PUSH_DURATION_S, DURATION_S = 0.4, 0.2, 1.0
SCENARIO = f"""
name = "video_push"
description = "A chest push from behind, drawn."
duration_s = {DURATION_S}
diagnostics_period_ticks = 10

[[pushes]]
body = "chest"
force_in_world_N = [150.0, 0.0, 0.0]
start_s = {PUSH_START_S}
duration_s = {PUSH_DURATION_S}
"""


def poise(arguments: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return run_poise(arguments, cwd, timeout_s=300)


@pytest.mark.slow
def test_sim_video_shows_the_robot_moving_and_the_push_while_it_acts(tmp_path):
    scenario = tmp_path / "video_push.toml"
    scenario.write_text(SCENARIO)
    result = poise(["sim", str(scenario), "--video", "--output", "out"], tmp_path)
    assert result.returncode == 0, result.stderr

    video = video_frames(tmp_path / "out" / "video_push.mp4")
    assert abs(len(video) - DURATION_S * VIDEO_FPS) <= 1
    times = np.arange(len(video)) / VIDEO_FPS
    pushed = (times >= PUSH_START_S) & (times < PUSH_START_S + PUSH_DURATION_S)
    red = np.array([red_pixels(frame) for frame in video])
    assert red[pushed].min() > 30, red
    assert red[times < PUSH_START_S].max() == 0, red
    # The push sways the robot; the camera follows the base, so the floor grid moves too.
    assert moved(video[0], video[-1]) > 500
    assert "video_push.mp4" in (tmp_path / "out" / "report.json").read_text()


def test_log_video_draws_the_recorded_run(tmp_path):
    output = tmp_path / "push.mp4"
    log = FIXTURES / "replay_momentum_push.mcap"
    result = poise(["log", "video", str(log), "-o", str(output)], tmp_path)
    assert result.returncode == 0, result.stderr
    assert str(output) in result.stdout

    video = video_frames(output)
    assert abs(len(video) - 0.2 * VIDEO_FPS) <= 1  # the log holds 0.2 s of states
    assert moved(video[0], video[-1]) > 100  # its chest push sways the robot
    assert min(yellow_pixels(frame) for frame in video) > 20  # the support polygon
    assert max(red_pixels(frame) for frame in video) == 0  # pushes are not logged


def test_a_video_of_a_sweep_is_refused_in_one_line(tmp_path):
    result = poise(["sim", "stand", "--sweep-push", "--video"], tmp_path)
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "poise sim: --video shows scenario runs; a --sweep-push has none to show"
    ]


def test_a_video_of_a_file_that_is_no_log_is_one_line(tmp_path):
    (tmp_path / "notes.mcap").write_text("not a log")
    result = poise(["log", "video", "notes.mcap"], tmp_path)
    assert result.returncode == 2
    (line,) = result.stderr.splitlines()
    assert "'notes.mcap' is not a readable Poise log" in line
