"""``poise inspect``: what Poise reads from a robot file, and the starter scenario it writes."""

from pathlib import Path

import pytest

from clients.sim.scenario import load_scenario
from controller_server.cli import main
from controller_server.models import load_robot_model

SCENE = Path(__file__).resolve().parent / "models" / "vendor_humanoid" / "scene.xml"


def inspected(capsys, *arguments: str) -> list[str]:
    assert main(["inspect", *arguments]) == 0
    return capsys.readouterr().out.splitlines()


def test_a_vendor_scene_shows_joints_limits_servos_contacts_and_pose(capsys):
    lines = inspected(capsys, str(SCENE), "--keyframe", "home")
    builtin = load_robot_model("revolute_humanoid")
    start = (
        lines.index(
            "joints (wire order): name, kind, range (rad; prismatic: m), "
            "torque limit (N·m; prismatic: N), actuator"
        )
        + 1
    )
    rows = [line.split() for line in lines[start : start + len(builtin.joints)]]
    assert [row[0] for row in rows] == [joint.name for joint in builtin.joints]
    limits = {row[0]: float(row[4]) for row in rows}  # name kind [low, high] limit
    assert limits["torso_yaw"] == 90.0  # the joint's actuatorfrcrange under the class's 100
    assert limits["left_knee"] == 300.0  # from the default class
    assert all("position servo: a torque motor in MuJoCo" in line for line in lines[start:][:5])
    assert "scene: MJCF, 22 joint coordinates, 57.60 kg" == lines[0]
    assert lines[1].startswith("standing pose: keyframe 'home'; base at (0.000, 0.000, 0.994) m")
    assert "keyframes: home, stand" in lines
    header = "contacts (collision geometry): name, body, sole points, sole length × width (m)"
    assert header in lines
    assert any(line.split()[:2] == ["left_foot", "left_foot"] for line in lines)


def test_the_starter_scenario_names_the_model_keyframe_and_a_push(capsys, tmp_path):
    path = tmp_path / "starter.toml"
    lines = inspected(capsys, str(SCENE), "--keyframe", "home", "--write-scenario", str(path))
    assert lines[-1] == f"wrote {path}: poise sim {path}"
    scenario = load_scenario(path)
    assert (scenario.model, scenario.keyframe, scenario.backend) == (
        str(SCENE.resolve()),
        "home",
        "mujoco",
    )
    assert scenario.pushes[0].body == "pelvis"
    assert scenario.pushes[0].force_in_world_N[0] == pytest.approx(57.6)  # 0.1 m/s for 57.6 kg
    assert main(["inspect", str(SCENE), "--write-scenario", str(path)]) == 2  # not replaced
    assert "exists; pass --force" in capsys.readouterr().err


def test_named_feet_and_a_builtin(capsys):
    lines = inspected(capsys, "revolute_humanoid")
    assert "contacts (sole sites): name, body, sole points, sole length × width (m)" in lines
    lines = inspected(
        capsys, str(SCENE), "--contacts", "left_ankle_pitch_link", "right_ankle_pitch_link"
    )
    assert "contacts (given): name, body, sole points, sole length × width (m)" in lines
    assert any(line.split()[0] == "left_ankle_pitch_link" for line in lines)
