"""The thesis' push scenarios in MuJoCo, the independent physics engine (issue 4 acceptance).

Same scenario files, same server, same controller as the demo
(``test_demo.py`` runs them in the reference simulator).
"""

import pytest

from clients.demo import DEMO_SCENARIOS
from clients.sim.app import run_scenarios

pytestmark = [pytest.mark.e2e, pytest.mark.slow]


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


@pytest.mark.parametrize("backend", ["mujoco", "reference"])
def test_real_time_configuration_survives_the_thesis_pushes(server, tmp_path, backend):
    """What `bench/sim_realtime.py` times: pipelined (each command acts one tick late, on
    the predicted state), optimizer and diagnostics at 200 Hz, inverse dynamics every tick."""
    reports = run_scenarios(
        DEMO_SCENARIOS,
        tmp_path,
        endpoint=server.endpoint,
        overrides={
            "backend": backend,
            "command_delay_ticks": 1,
            "diagnostics_period_ticks": 5,
            "params": {"optimizer_period_ticks": 5},
        },
        progress=False,
    )
    for report in reports:
        assert not report["fell"], report
        assert report["com_excursion_m"] < 0.3, report
        assert report["cop_strictly_inside_fraction"] > 0.8, report
