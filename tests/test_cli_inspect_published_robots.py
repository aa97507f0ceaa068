"""Robots as their makers publish them (issue 31), through the real command line.

Unnamed meshes named after their files, as MuJoCo names them.
"""

import subprocess
import sys
from pathlib import Path

import pytest

from controller_server.cli import main

MODELS = Path(__file__).resolve().parent / "models"
UNNAMED_MESH_SCENE = MODELS / "unnamed_mesh_humanoid" / "scene.xml"


def inspected(capsys, *arguments: str) -> list[str]:
    assert main(["inspect", *arguments]) == 0
    return capsys.readouterr().out.splitlines()


def contact_rows(lines: list[str]) -> dict[str, list[str]]:
    """The contact rows of `poise inspect`'s report: name → the row's words."""
    start = next(i for i, line in enumerate(lines) if line.startswith("contacts ("))
    rows = {}
    for line in lines[start + 1 :]:
        if not line.startswith("  "):
            break
        if not line.startswith("    "):
            rows[line.split()[0]] = line.split()
    return rows


def poise_sim(tmp_path: Path, endpoint: str, *arguments: str) -> subprocess.CompletedProcess:
    options = ["--connect", endpoint, "--output", str(tmp_path / "out")]
    return subprocess.run(
        [sys.executable, "-m", "controller_server.cli", "sim", *arguments, *options],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        stdin=subprocess.DEVNULL,
    )


def short_stand(tmp_path: Path) -> Path:
    path = tmp_path / "short_stand.toml"
    path.write_text('name = "short_stand"\nduration_s = 1.0\n')
    return path


def test_unnamed_meshes_keep_the_names_mujoco_gives_them(capsys):
    """``<mesh file="pelvis.STL"/>`` is ``pelvis``, ``<mesh file="feet/foot.stl"/>`` ``foot``."""
    text = (UNNAMED_MESH_SCENE.parent / "robot.xml").read_text()
    assert '<mesh file="feet/foot.stl"/>' in text and 'mesh="foot"' in text
    assert '<mesh file="pelvis.STL"/>' in text and 'mesh="pelvis"' in text
    lines = inspected(capsys, str(UNNAMED_MESH_SCENE))
    assert lines[0] == "scene: MJCF, 22 joint coordinates, 57.60 kg"
    rows = contact_rows(lines)
    assert list(rows) == ["left_foot", "right_foot"]
    assert rows["left_foot"][1:4] == ["left_foot", "4", "points"]
    assert rows["right_foot"][1:4] == ["right_foot", "4", "points"]
    # The sole of the foot mesh (0.24 m × 0.11 m), not a box put in its place.
    assert rows["left_foot"][4:] == ["0.240", "×", "0.110"]


@pytest.mark.e2e
def test_a_robot_with_unnamed_meshes_stands_in_mujoco(server, tmp_path):
    result = poise_sim(
        tmp_path,
        server.endpoint,
        str(short_stand(tmp_path)),
        "--model",
        str(UNNAMED_MESH_SCENE),
        "--backend",
        "mujoco",
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "short_stand" in result.stdout and "stayed up" in result.stdout, result.stdout
