"""The thesis' push scenarios in MuJoCo, the independent physics engine (issue 4 acceptance).

Same scenario files, same server, same controller as the demo
(``test_demo.py`` runs them in the reference simulator).
"""

import pytest

from clients.demo import DEMO_SCENARIOS
from clients.sim.app import run_scenarios

pytestmark = pytest.mark.e2e


def test_full_controller_survives_the_thesis_pushes_in_mujoco(server, tmp_path):
    reports = run_scenarios(
        DEMO_SCENARIOS, tmp_path, endpoint=server.endpoint, overrides={"backend": "mujoco"}
    )
    assert [r["scenario"] for r in reports] == list(DEMO_SCENARIOS)
    for report in reports:
        assert report["backend"] == "mujoco"
        assert not report["fell"], report
        # Pushed, the CM moves a few centimetres and comes back; it does not wander off.
        assert report["com_excursion_m"] < 0.3, report
