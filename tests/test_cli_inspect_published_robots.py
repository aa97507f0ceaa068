"""Robots as their makers publish them (issue 31), through the real command line.

Unnamed meshes named after their files, as MuJoCo names them; a URDF in a ROS
package naming its meshes by ``package://`` URIs, found as ROS tools find them;
its SRDF's keyframes and disabled collision pairs.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from controller_server.cli import main

MODELS = Path(__file__).resolve().parent / "models"
UNNAMED_MESH_SCENE = MODELS / "unnamed_mesh_humanoid" / "scene.xml"
PACKAGE = MODELS / "ros_ws" / "src" / "poise_test_description"
URDF = PACKAGE / "urdf" / "poise_biped.urdf"
FOUND_REASON = (
    "why: its collision points are among the lowest at the standing pose (within 0.02 m of "
    "the lowest point); {side} of the root's heading (0.100 m)"
)


def inspected(capsys, *arguments: str) -> list[str]:
    assert main(["inspect", *arguments]) == 0, capsys.readouterr().err
    return capsys.readouterr().out.splitlines()


def refused(capsys, *arguments: str) -> str:
    """The one line `poise inspect` prints when it exits 2."""
    assert main(["inspect", *arguments]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    return lines[0]


@pytest.fixture(autouse=True)
def no_ros_package_path(monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)


def package_copy(directory: Path) -> Path:
    """A copy of the test package in a workspace under ``directory``; its URDF's path."""
    copy = directory / "ws" / "src" / PACKAGE.name
    shutil.copytree(PACKAGE, copy)
    return copy / "urdf" / URDF.name


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


def test_package_uris_resolve_through_the_urdfs_ancestor_named_like_the_package(capsys):
    """example-robot-data's rule; the two feet's meshes share a file name, not a shape."""
    text = URDF.read_text()
    assert "package://poise_test_description/meshes/left/foot_collision.stl" in text
    assert "package://poise_test_description/meshes/right/foot_collision.stl" in text
    lines = inspected(capsys, str(URDF))
    rows = contact_rows(lines)
    assert rows["left_foot"][1:] == ["left_foot", "4", "points", "0.240", "×", "0.110"]
    assert rows["right_foot"][1:] == ["right_foot", "4", "points", "0.220", "×", "0.100"]
    assert FOUND_REASON.format(side="left") in [line.strip() for line in lines]
    assert FOUND_REASON.format(side="right") in [line.strip() for line in lines]
    assert not [line for line in lines if line.startswith("warning")]


def test_ros_package_path_comes_before_the_ancestors(capsys, tmp_path, monkeypatch):
    """A copy of the package elsewhere, its feet swapped: ROS_PACKAGE_PATH's copy is read."""
    copy = package_copy(tmp_path).parents[1]
    left, right = copy / "meshes" / "left", copy / "meshes" / "right"
    (left / "foot_collision.stl").write_bytes((right / "foot_collision.stl").read_bytes())
    # The URDF alone in another directory: only ROS_PACKAGE_PATH can find its package.
    alone = tmp_path / "elsewhere" / "robot.urdf"
    alone.parent.mkdir()
    shutil.copy(URDF, alone)
    # The real command, in its own process: exit code 2, one line, no traceback.
    result = subprocess.run(
        [sys.executable, "-m", "controller_server.cli", "inspect", str(alone)],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
        env={k: v for k, v in os.environ.items() if k != "ROS_PACKAGE_PATH"},
    )
    assert result.returncode == 2, result.stderr
    (message,) = result.stderr.splitlines()
    assert message.startswith(
        "poise inspect: the collision mesh "
        "'package://poise_test_description/meshes/left/foot_collision.stl' of link 'left_foot' "
        "(a foot candidate: one of the lowest links standing) cannot be read: package "
        "'poise_test_description' is not in ROS_PACKAGE_PATH (unset) nor an ancestor of "
    )
    assert "set ROS_PACKAGE_PATH to a directory that holds package 'poise_test_description'" in (
        message
    )
    monkeypatch.setenv("ROS_PACKAGE_PATH", f"{tmp_path / 'nothing_here'}:{tmp_path / 'ws'}")
    for urdf in (alone, URDF):  # found below an entry; before the URDF's own ancestor
        rows = contact_rows(inspected(capsys, str(urdf)))
        assert rows["left_foot"][4:] == ["0.220", "×", "0.100"]
        assert rows["right_foot"][4:] == ["0.220", "×", "0.100"]


def test_an_unreadable_foot_mesh_is_an_error_and_other_meshes_one_warning(capsys, tmp_path):
    urdf = package_copy(tmp_path)
    meshes = urdf.parents[1] / "meshes"
    (meshes / "wrist_ft_collision.stl").unlink()  # two links' mesh (the wrist force sensors)
    lines = inspected(capsys, str(urdf))
    warnings = [line for line in lines if line.startswith("warning")]
    assert warnings == [
        "warning: 1 collision mesh file(s) cannot be read and are left out, e.g. "
        "'package://poise_test_description/meshes/wrist_ft_collision.stl' of link "
        "'left_wrist_ft_link': No such file or directory "
        f"(tried '{meshes / 'wrist_ft_collision.stl'}')"
    ]
    assert list(contact_rows(lines)) == ["left_foot", "right_foot"]
    (meshes / "right" / "foot_collision.stl").unlink()
    message = refused(capsys, str(urdf))
    assert message.startswith(
        "poise inspect: the collision mesh "
        "'package://poise_test_description/meshes/right/foot_collision.stl' of link "
        "'right_foot' (a foot candidate: one of the lowest links standing) cannot be read: No "
        f"such file or directory (tried '{meshes / 'right' / 'foot_collision.stl'}'); "
    )
    assert message.endswith(
        "or name feet whose meshes can be read (--contacts) or give their points "
        "(`contacts` with `points_in_frame`)"
    )
    # Named feet whose meshes can be read: the missing one does not matter.
    lines = inspected(capsys, str(urdf), "--contacts", "left_foot", "left_ankle_pitch_link")
    assert list(contact_rows(lines)) == ["left_foot", "left_ankle_pitch_link"]


def test_the_srdf_beside_the_urdf_gives_keyframes_and_disabled_pairs(capsys):
    lines = inspected(capsys, str(URDF), "--keyframe", "half_sitting")
    assert "keyframes: half_sitting, straight" in lines
    # The knees bent 0.6 rad, the hips and ankles −0.3: the vendor scene's crouch and height.
    assert lines[1].startswith(
        "standing pose: keyframe 'half_sitting'; base at (0.000, 0.000, 0.994) m"
    )
    assert lines[3] == (
        "disabled collision pairs (SRDF): 5: left_forearm–left_wrist_ft_link, "
        "left_hip_yaw_link–pelvis, left_thigh–right_thigh, …"
    )
    message = refused(capsys, str(URDF), "--keyframe", "home")
    assert message == (
        "poise inspect: no keyframe 'home' in the model; keyframes: half_sitting, straight (a "
        "URDF's keyframes are its SRDF's group_states: poise_biped.srdf or "
        "../srdf/poise_biped.srdf beside it, or --srdf FILE)"
    )


def test_srdf_given_on_the_command_line(capsys, tmp_path):
    srdf = tmp_path / "other.srdf"
    srdf.write_text(
        '<robot name="poise_biped"><group_state name="crouch" group="legs">'
        '<joint name="left_knee" value="1.0"/><joint name="right_knee" value="1.0"/>'
        "</group_state></robot>"
    )
    lines = inspected(capsys, str(URDF), "--srdf", str(srdf), "--keyframe", "crouch")
    assert "keyframes: crouch" in lines
    assert not [line for line in lines if line.startswith("disabled collision pairs")]
    srdf.write_text('<robot name="poise_biped"><group_state name="crouch">')
    assert refused(capsys, str(URDF), "--srdf", str(srdf)).startswith(
        "poise inspect: the SRDF 'poise_biped.srdf' is not valid XML: "
    )
    srdf.write_text(
        '<robot name="poise_biped"><group_state name="crouch" group="legs">'
        '<joint name="left_kne" value="1.0"/></group_state></robot>'
    )
    assert refused(capsys, str(URDF), "--srdf", str(srdf)) == (
        "poise inspect: the SRDF 'poise_biped.srdf': group_state 'crouch' sets joint "
        "'left_kne', which the URDF does not have; did you mean 'left_knee'?"
    )
    assert refused(capsys, str(UNNAMED_MESH_SCENE), "--srdf", str(srdf)) == (
        "poise inspect: --srdf " + str(srdf) + ": an SRDF goes with a URDF, not scene.xml"
    )
    assert refused(capsys, str(URDF), "--srdf", str(tmp_path / "missing.srdf")).startswith(
        f"poise inspect: SRDF file '{tmp_path / 'missing.srdf'}' does not exist"
    )


@pytest.mark.e2e
def test_a_ros_package_urdf_stands_in_its_srdf_pose_through_a_server(server, tmp_path):
    """The URDF is sent with its meshes and SRDF by the names it gives them
    (``package://…``, ``../srdf/poise_biped.srdf``); the server reads its keyframe."""
    result = poise_sim(
        tmp_path,
        server.endpoint,
        str(short_stand(tmp_path)),
        "--model",
        str(URDF),
        "--keyframe",
        "half_sitting",
        "--backend",
        "reference",
    )
    assert result.returncode == 0, result.stderr
    assert "stayed up" in result.stdout, result.stdout
