"""Robots as their vendors write them (issue 18), through a real server and both simulators."""

from pathlib import Path

import numpy as np
import pytest

from clients.sim.metrics import compute_metrics
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


MODELS = Path(__file__).resolve().parents[1] / "models"
VENDOR_SCENE = MODELS / "vendor_humanoid" / "scene.xml"


def vendor_scenario(directory: Path, controller: str) -> Path:
    """Only what a user writes for a vendor's scene: the model, its keyframe, the run."""
    path = directory / f"vendor_{controller}.toml"
    path.write_text(
        f'name = "vendor_{controller}"\n'
        f'model = "{VENDOR_SCENE}"\n'
        'keyframe = "home"\n'
        f'controller = "{controller}"\n'
        'backend = "mujoco"\n'
        "duration_s = 5.0\n"
        "[[pushes]]\n"
        'body = "pelvis"\n'
        "force_in_world_N = [100.0, 0.0, 0.0]\n"
        "start_s = 2.0\n"
        "duration_s = 0.1\n"
    )
    return path


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["momentum", "prioritized"])
def test_a_vendor_scene_balances_5_s_and_survives_a_push_in_mujoco(server, controller, tmp_path):
    """Issue 18's acceptance: include, default classes, ``type="free"``, mesh feet, position
    servos and a keyframe, with no hand edits, from a scenario with the model and keyframe."""
    scenario = load_scenario(vendor_scenario(tmp_path, controller))
    record = run_scenario(scenario, server.endpoint)
    assert not record.fell, record.fall_reason
    assert record.simulated_s == pytest.approx(5.0)
    # It started in the keyframe's crouch, soles on the floor, and the servos were made motors.
    knee = [joint.name for joint in record.welcome.joints].index("left_knee")
    assert record.states[0].joint_position[knee] == pytest.approx(0.6)
    assert record.welcome.standing_position_base_in_world[2] == pytest.approx(0.9943, abs=1e-3)
    assert any("22 position/velocity servos torque motors" in n for n in record.model_notes)
    # The push moved it (the CM travelled forward), and it came back to stand.
    metrics = compute_metrics(record)
    assert metrics["com_excursion_m"] > 0.005
    velocity = record.states[-1].linear_velocity_base_in_world
    assert np.linalg.norm(velocity) < 0.05


@pytest.mark.slow
@pytest.mark.parametrize(
    ("model", "backend"),
    [
        ("sphere_feet_humanoid.xml", "reference"),
        ("sphere_feet_humanoid.xml", "mujoco"),
        ("urdf_humanoid/robot.urdf", "reference"),
        ("urdf_humanoid/robot.urdf", "mujoco"),
        ("vendor_humanoid/robot.xml", "mujoco"),
        ("vendor_humanoid/scene.xml", "reference"),
    ],
)
def test_vendor_constructs_stand_in_both_simulators(server, model, backend):
    """Sphere feet, a URDF (feet a metre under the floor as written), a robot file without its
    scene (no floor), a scene in the reference simulator: each stands on what was found."""
    scenario = load_scenario("stand", model=str(MODELS / model), backend=backend, duration_s=1.5)
    record = run_scenario(scenario, server.endpoint)
    assert not record.fell, record.fall_reason
    heights = [state.position_base_in_world[2] for state in record.states]
    assert max(heights) - min(heights) < 0.02, (min(heights), max(heights))
    assert abs(heights[0] - record.welcome.standing_position_base_in_world[2]) < 0.005
    if model.endswith("robot.xml"):
        assert "added a floor (the model has no plane)" in record.model_notes
