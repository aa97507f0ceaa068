"""The README's main job: the thesis humanoid under the thesis' pushes, reference simulator.

Acceptance of issue 4: with all momentum objectives on, the humanoid survives
each thesis push scenario (150 N × 100 ms pushes across the upper body; one
220 N × 100 ms push to the head) in the reference simulator, served over
ZeroMQ by a real server process. The MuJoCo runs of the same scenarios are in
``test_push_scenarios_mujoco.py``.
"""

import json

import pytest

from clients.demo import DEMO_SCENARIOS, run_demo

pytestmark = pytest.mark.e2e


def test_demo_survives_the_thesis_pushes_and_writes_readable_plots(server, tmp_path):
    exit_code = run_demo(tmp_path, endpoint=server.endpoint)

    reports = json.loads((tmp_path / "report.json").read_text())
    assert [r["scenario"] for r in reports] == list(DEMO_SCENARIOS)
    for report in reports:
        assert report["backend"] == "reference"
        assert report["controller"] == "momentum"
        assert not report["fell"], report
        png = (tmp_path / f"{report['scenario']}.png").read_bytes()
        assert png.startswith(b"\x89PNG") and len(png) > 20_000
    assert exit_code == 0
