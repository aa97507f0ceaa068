"""`poise list`: one line per scenario, model, controller, joint or body."""

import importlib.machinery
import importlib.util
import subprocess
import sys

import mujoco
import pytest

from clients.physics import model_file
from clients.physics.model_file import resolve_model_path
from clients.sim.scenario import SCENARIO_DIR
from controller_server.cli import main
from controller_server.controllers import CONTROLLERS
from controller_server.models import BUILTIN_MODELS, load_robot_model


def listed(capsys, *arguments: str) -> list[str]:
    assert main(["list", *arguments]) == 0
    return capsys.readouterr().out.splitlines()


def test_the_models_are_found_in_a_package_over_two_directories(tmp_path, monkeypatch):
    """An editable install: the compiled core in site-packages (listed first), the data here."""
    spec = importlib.util.find_spec("controller_server")
    split = importlib.machinery.ModuleSpec("controller_server", None, is_package=True)
    split.submodule_search_locations = [str(tmp_path), *spec.submodule_search_locations]
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: split)
    assert model_file.builtin_model_names() == sorted(BUILTIN_MODELS)
    assert model_file.builtin_model_path("dino_biped") == BUILTIN_MODELS["dino_biped"]


def test_scenarios_one_line_each_with_its_description(capsys):
    lines = listed(capsys, "scenarios")
    assert [line.split()[0] for line in lines] == sorted(
        p.stem for p in SCENARIO_DIR.glob("*.toml")
    )
    assert any(line.startswith("stand ") and "Quiet standing" in line for line in lines)


def test_a_cut_description_says_so_and_full_shows_it_whole(capsys):
    from clients.sim.scenario import builtin_scenario_names, load_scenario

    assert main(["list", "scenarios"]) == 0
    printed = capsys.readouterr()
    assert any(line.endswith("…") for line in printed.out.splitlines())
    assert printed.err == (
        "(… descriptions cut to one line: `poise list scenarios --full` shows them whole)\n"
    )
    full = listed(capsys, "scenarios", "--full")
    names = [line for line in full if not line.startswith(" ")]
    assert names == builtin_scenario_names()
    for name in names:  # every word of the description, under its name, in order
        start = full.index(name) + 1
        end = next((i for i in range(start, len(full)) if not full[i].startswith(" ")), None)
        text = " ".join(" ".join(full[start:end]).split())
        assert text == " ".join(load_scenario(name).description.split())
        assert all(len(line) <= 88 for line in full[start:end])


def test_a_reader_that_left_is_no_traceback():
    """``poise list | head`` closes the pipe early: no BrokenPipeError on the screen."""
    import os

    from tests.helpers import POISE

    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line
    try:
        result = subprocess.run(
            [*POISE, "list", "scenarios", "--full"],
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            timeout=60,
        )
    finally:
        os.close(write_end)
    assert result.stderr == ""
    assert result.returncode == 141  # 128 + SIGPIPE, as a program the signal stopped


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
    assert result.returncode == 0 and "Traceback" not in result.stderr
    assert result.stdout.splitlines() == lines
