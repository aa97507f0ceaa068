"""`poise list`: one line per scenario, model, controller, joint or body."""

import subprocess
import sys

import mujoco
import pytest

from clients.sim.model_file import resolve_model_path
from clients.sim.scenario import SCENARIO_DIR
from controller_server.cli import main
from controller_server.controllers import CONTROLLERS
from controller_server.models import BUILTIN_MODELS, load_robot_model


def listed(capsys, *arguments: str) -> list[str]:
    assert main(["list", *arguments]) == 0
    return capsys.readouterr().out.splitlines()


def test_scenarios_one_line_each_with_its_description(capsys):
    lines = listed(capsys, "scenarios")
    assert [line.split()[0] for line in lines] == sorted(
        p.stem for p in SCENARIO_DIR.glob("*.toml")
    )
    assert any(line.startswith("stand ") and "Quiet standing" in line for line in lines)


def test_models_and_controllers(capsys):
    assert listed(capsys, "models") == sorted(BUILTIN_MODELS)
    controllers = listed(capsys, "controllers")
    assert [line.split()[0] for line in controllers] == sorted(CONTROLLERS)
    assert "momentum  (default)" in controllers


@pytest.mark.parametrize("model", sorted(BUILTIN_MODELS))
def test_joints_in_wire_order_with_their_size(capsys, model):
    lines = listed(capsys, "joints", model)
    joints = load_robot_model(model).joints
    assert [line.split()[:2] for line in lines] == [[j.name, j.kind] for j in joints]
    for line, joint in zip(lines, joints, strict=True):
        assert ("4 numbers" if joint.kind == "ball" else f"{joint.nq} number") in line


@pytest.mark.parametrize("model", sorted(BUILTIN_MODELS))
def test_bodies_are_mujocos(capsys, model):
    physics = mujoco.MjModel.from_xml_path(str(resolve_model_path(model)))
    bodies = [physics.body(i).name for i in range(1, physics.nbody)]  # 0 is the world
    assert listed(capsys, "bodies", model) == bodies


def test_joints_of_a_model_file(capsys, tmp_path):
    path = tmp_path / "robot.xml"
    path.write_text(resolve_model_path("revolute_humanoid").read_text())
    assert listed(capsys, "joints", str(path)) == listed(capsys, "joints", "revolute_humanoid")


def test_list_through_the_command_line():
    result = subprocess.run(
        [sys.executable, "-m", "controller_server.cli", "list", "bodies"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert (
        result.stderr == "poise list: name the model: poise list bodies MODEL (poise list models)\n"
    )
    output = subprocess.check_output(
        [sys.executable, "-m", "controller_server.cli", "list", "models"], text=True, timeout=60
    )
    assert output.splitlines() == sorted(BUILTIN_MODELS)


def test_no_category_lists_every_category(capsys):
    lines = listed(capsys)
    headings = [line for line in lines if not line.startswith("  ")]
    assert [heading.split()[0] for heading in headings] == [
        "scenarios",
        "models",
        "controllers",
        "joints",
        "bodies",
    ]
    for what in ("scenarios", "models", "controllers"):
        start = lines.index(f"{what} (poise list {what}):") + 1
        items = lines[start : start + len(listed(capsys, what))]
        assert items == [f"  {line}" for line in listed(capsys, what)], what
    assert "joints (poise list joints MODEL): " in "\n".join(lines)
    assert "bodies (poise list bodies MODEL): " in "\n".join(lines)
    result = subprocess.run(
        [sys.executable, "-m", "controller_server.cli", "list"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert (result.returncode, result.stderr) == (0, "")
    assert result.stdout.splitlines() == lines
