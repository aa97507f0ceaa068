"""The README's main job: the thesis humanoid under the thesis' pushes, reference simulator.

Acceptance of issue 4: with all momentum objectives on, the humanoid survives
each thesis push scenario (150 N × 100 ms pushes across the upper body; one
220 N × 100 ms push to the head) in the reference simulator, served over
ZeroMQ by a real server process. The MuJoCo runs of the same scenarios are in
``test_push_scenarios_mujoco.py``. And, issue 20: ``poise demo --video`` writes an MP4 per
scenario, with a frame every 1/30 s of the run, the robot moving and the pushes drawn.
"""

import json

import pytest

from clients.demo import DEMO_SCENARIOS
from clients.visual.video import VIDEO_FPS
from tests.helpers import moved, red_pixels, run_poise, video_frames

pytestmark = [pytest.mark.e2e, pytest.mark.slow]


def test_demo_survives_the_thesis_pushes_and_writes_readable_plots_and_videos(server, tmp_path):
    # The command line, in its own process: MuJoCo picks its OpenGL when first imported.
    result = run_poise(
        ["demo", "--video", "--connect", server.endpoint, "--output", str(tmp_path)],
        tmp_path,
        timeout_s=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    wrote = [line for line in result.stdout.splitlines() if line.startswith("report: ")]
    assert wrote == [
        f"report: {tmp_path / 'report.json'}; plots: "
        + ", ".join(str(tmp_path / f"{name}.png") for name in DEMO_SCENARIOS)
    ]

    reports = json.loads((tmp_path / "report.json").read_text())
    assert [r["scenario"] for r in reports] == list(DEMO_SCENARIOS)
    for report in reports:
        assert report["backend"] == "reference"
        assert report["controller"] == "momentum"
        assert not report["fell"], report
        png = (tmp_path / f"{report['scenario']}.png").read_bytes()
        assert png.startswith(b"\x89PNG") and len(png) > 20_000
        video = video_frames(tmp_path / f"{report['scenario']}.mp4")
        assert abs(len(video) - report["simulated_s"] * VIDEO_FPS) <= 1, len(video)
        assert moved(video[0], video[-1]) > 500
        assert max(red_pixels(frame) for frame in video) > 30  # its pushes, drawn
