"""The prioritized controller (issue 5) as a client sees it: over ZeroMQ, in both simulators."""

import pytest

from clients.demo import DEMO_SCENARIOS
from clients.sim.app import run_scenarios
from clients.sim.runner import run_scenario
from clients.sim.scenario import load_scenario

pytestmark = pytest.mark.e2e


@pytest.mark.parametrize("backend", ["reference", "mujoco"])
def test_prioritized_controller_stands_in_both_simulators(server, backend):
    scenario = load_scenario("stand", controller="prioritized", backend=backend, duration_s=1.0)
    record = run_scenario(scenario, server.endpoint)
    assert not record.fell, record.fall_reason
    last = record.commands[-1].diagnostics
    assert last.weighted is None and last.prioritized is not None
    levels = last.prioritized.priority_levels
    assert levels is not None and levels[0].objectives == ["dynamics"]
    assert all(level.status == "solved" for level in levels)
    assert last.objective_residuals["dynamics"] < 1e-6
    assert last.prioritized.inequality_violation < 1e-7
    # Quiet standing: the CM stays over the feet, the feet do not slide.
    start = record.commands[0].diagnostics.position_com_in_world
    assert abs(last.position_com_in_world[1] - start[1]) < 0.01
    assert 0.0 < last.position_com_in_world[0] < 0.1


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["reference", "mujoco"])
def test_prioritized_controller_survives_the_thesis_pushes(server, backend, tmp_path):
    """Issue 5 acceptance: `push_sequence` and `head_push` in both simulators."""
    reports = run_scenarios(
        DEMO_SCENARIOS,
        tmp_path,
        endpoint=server.endpoint,
        overrides={"backend": backend, "controller": "prioritized"},
        progress=False,
    )
    assert [r["scenario"] for r in reports] == list(DEMO_SCENARIOS)
    for report in reports:
        assert report["controller"] == "prioritized", report
        assert not report["fell"], report
        assert report["com_excursion_m"] < 0.3, report
