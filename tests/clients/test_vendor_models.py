"""Robots as their vendors write them (issue 18), through a real server and both simulators."""

import pytest

from clients.sim.runner import run_scenario
from clients.sim.scenario import load_scenario
from controller_server.models import BUILTIN_MODELS

pytestmark = pytest.mark.e2e


@pytest.mark.parametrize("backend", ["reference", "mujoco"])
def test_a_root_written_joint_type_free_stands_at_its_height(server, backend, tmp_path):
    """``<joint type="free"/>`` for ``<freejoint/>``: it once doubled the standing height."""
    text = BUILTIN_MODELS["thesis_humanoid"].read_text()
    assert '<freejoint name="root"/>' in text
    path = tmp_path / "thesis_humanoid_type_free.xml"
    path.write_text(text.replace('<freejoint name="root"/>', '<joint name="root" type="free"/>'))
    scenario = load_scenario("stand", model=str(path), backend=backend, duration_s=1.0)
    record = run_scenario(scenario, server.endpoint)
    builtin = load_scenario("stand", backend=backend, duration_s=0.01)
    reference = run_scenario(builtin, server.endpoint)
    assert not record.fell, record.fall_reason
    assert record.welcome.standing_position_base_in_world == (
        reference.welcome.standing_position_base_in_world
    )
    # Standing, not dropped from twice its height: the base stays within 2 cm of the start.
    heights = [state.position_base_in_world[2] for state in record.states]
    assert max(heights) - min(heights) < 0.02, (min(heights), max(heights))
