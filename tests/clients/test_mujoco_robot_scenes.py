"""Published robots in the MuJoCo backend (issue 31): bodies beside the robot, links that overlap
at the standing pose, an SRDF's keyframes and disabled pairs, and URDF meshes in memory."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from clients.physics.mujoco_backend import MujocoBackend, UnsupportedModel  # noqa: E402
from clients.sim.runner import run_scenario  # noqa: E402
from clients.sim.scenario import load_scenario  # noqa: E402
from clients.state import RobotState  # noqa: E402
from tests.helpers import box_stl  # noqa: E402

MODELS = Path(__file__).resolve().parents[1] / "models"
DUMMY_SCENE = MODELS / "dummy_body_scene" / "scene.xml"
OVERLAP_URDF = MODELS / "overlap_humanoid" / "robot.urdf"
PLAIN_URDF = MODELS / "urdf_humanoid" / "robot.urdf"


def poise_sim(tmp_path: Path, endpoint: str, *options: str) -> subprocess.CompletedProcess:
    """``poise sim`` as a user runs it, against the test's server."""
    return subprocess.run(
        [
            *(sys.executable, "-m", "controller_server.cli", "sim", *options),
            *("--connect", endpoint, "--output", str(tmp_path / "out")),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )


def explain(result: subprocess.CompletedProcess, tmp_path: Path) -> str:
    """What ``poise sim`` printed, and why a robot fell (from its report)."""
    report = tmp_path / "out" / "report.json"
    reasons = [r["fall_reason"] for r in json.loads(report.read_text())] if report.exists() else []
    return f"{result.stdout}{result.stderr}fall reasons: {reasons}"


def standing_state(backend: MujocoBackend) -> RobotState:
    """The description's standing pose, at rest (hinge joints only: wire = Pinocchio order)."""
    q = backend.description.standing_configuration
    return RobotState(
        q[7:].copy(), np.zeros(len(q) - 7), q[:3].copy(), q[3:7].copy(), np.zeros(3), np.zeros(3)
    )


def robot_pairs(model, data, robot_bodies: set[int]) -> set[tuple[str, str]]:
    """Body-name pairs of the contacts between two of the robot's bodies."""
    pairs = set()
    for geom1, geom2 in data.contact.geom.tolist():
        bodies = sorted(int(model.geom_bodyid[g]) for g in (geom1, geom2))
        if set(bodies) <= robot_bodies:
            pairs.add(tuple(model.body(b).name for b in bodies))
    return pairs


# -- bodies outside the robot --------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.e2e
@pytest.mark.parametrize("backend", ["mujoco", "reference"])
def test_a_jointed_dummy_body_in_the_scene_is_left_to_the_simulator(server, tmp_path, backend):
    """A scene that includes a robot from another folder and adds a hinged box on the floor:
    both simulators run it, and MuJoCo says what it left alone."""
    result = poise_sim(
        tmp_path, server.endpoint, "stand", "--model", str(DUMMY_SCENE), "--backend", backend,
        "--duration", "1.5",
    )  # fmt: skip
    assert result.returncode == 0, explain(result, tmp_path)
    assert "stayed up" in result.stdout
    assert "Traceback" not in result.stderr
    note = "left 1 body outside the robot to the simulator: dummy (joint not_use_joint)"
    assert (note in result.stdout) == (backend == "mujoco"), result.stdout


def test_the_dummy_body_is_simulated_and_its_floor_contact_is_not_the_robot_falling():
    backend = MujocoBackend(str(DUMMY_SCENE), keyframe="home")
    model, data = backend.model, backend.data
    assert "not_use_joint" not in backend.joint_names
    hinge = model.joint("not_use_joint")
    assert hinge.qposadr[0] not in backend._qpos_index
    backend.reset(standing_state(backend))
    data.qvel[hinge.dofadr[0]] = 1.0  # the dummy spins, nobody drives it
    report = backend.step(np.zeros(len(backend.joint_names)), [])
    dummy = model.body("dummy").id
    on_floor = [
        sorted(model.geom_bodyid[g] for g in geoms) == [0, dummy]
        for geoms, address in zip(data.contact.geom, data.contact.efc_address, strict=True)
        if address >= 0
    ]
    assert any(on_floor)  # the box rests on the floor …
    assert not report.non_foot_contact  # … and that is not the robot touching the ground
    assert 0.0 < data.qvel[hinge.dofadr[0]] < 1.0  # MuJoCo turns it on, the floor slows it
    assert backend.total_mass_kg == pytest.approx(backend.description.total_mass)


def test_a_wire_that_disagrees_with_the_robot_names_only_the_differences():
    names = MujocoBackend(str(DUMMY_SCENE)).joint_names
    wire = [name for name in names if name != "neck_yaw"] + ["tail"]
    with pytest.raises(UnsupportedModel) as raised:
        MujocoBackend(str(DUMMY_SCENE), joint_names=wire)
    message = str(raised.value)
    assert "on the wire, not in the robot: tail" in message
    assert "in the robot, not on the wire: neck_yaw" in message
    assert "same robot file" in message  # what to do
    assert "not_use_joint" not in message and "left_knee" not in message
    assert "\n" not in message


# -- self-collision at the standing pose ---------------------------------------------------


def urdf_compiled_as_mujoco_imports_it(path: Path):
    """The URDF through MuJoCo's importer alone (static links kept), no Poise code."""
    text = path.read_text().replace(
        '<robot name="overlap_humanoid">',
        '<robot name="overlap_humanoid"><mujoco><compiler fusestatic="false"/></mujoco>',
    )
    spec = mujoco.MjSpec.from_string(text)
    spec.body("pelvis").add_freejoint()
    return spec.compile()


def test_overlapping_links_touch_at_the_standing_pose_unless_excluded():
    """MuJoCo's import collides the hands with the thighs and the thighs with each other; the
    backend excludes exactly those pairs, each noted with its depth."""
    backend = MujocoBackend(str(OVERLAP_URDF))
    plain = urdf_compiled_as_mujoco_imports_it(OVERLAP_URDF)
    plain_data = mujoco.MjData(plain)
    backend.reset(standing_state(backend))
    names = backend.joint_names
    plain_data.qpos[:7] = backend.data.qpos[:7]
    for name, value in zip(names, standing_state(backend).joint_position, strict=True):
        plain_data.qpos[plain.joint(name).qposadr[0]] = value
    mujoco.mj_forward(plain, plain_data)
    robot = set(range(1, plain.nbody))
    touching = robot_pairs(plain, plain_data, robot)
    assert {
        ("left_thigh", "right_thigh"),
        ("left_hand", "left_thigh"),
        ("right_hand", "right_thigh"),
    } <= {tuple(sorted(pair)) for pair in touching}, touching
    assert robot_pairs(backend.model, backend.data, robot) == set()
    notes = [n for n in backend.conversions if n.startswith("excluded the self-collision")]
    assert len(notes) == len(touching) == backend.model.nexclude
    assert (
        "excluded the self-collision left_thigh – right_thigh: 90.0 mm deep at the standing pose"
        in notes
    )


@pytest.mark.slow
@pytest.mark.e2e
def test_a_robot_whose_links_overlap_stands_in_mujoco(server, tmp_path):
    result = poise_sim(
        tmp_path, server.endpoint, "stand", "--model", str(OVERLAP_URDF), "--backend", "mujoco"
    )
    assert result.returncode == 0, explain(result, tmp_path)
    assert "stayed up" in result.stdout
    assert (
        "note (stand): excluded the self-collision left_hand – left_thigh: 50.0 mm deep at the "
        "standing pose" in result.stdout
    )


@pytest.mark.slow
@pytest.mark.e2e
def test_without_the_exclusions_the_overlapping_robot_fights_itself_and_falls(server, monkeypatch):
    """The test robot reproduces the issue: the exclusions are what keep it up."""
    monkeypatch.setattr(MujocoBackend, "_exclude_self_collisions", lambda self, spec: None)
    scenario = load_scenario("stand", model=str(OVERLAP_URDF), backend="mujoco", duration_s=3.0)
    record = run_scenario(scenario, server.endpoint)
    assert record.fell, "the overlapping robot stood without the exclusions"
    assert not record.fall_reason.startswith("controller error"), record.fall_reason


SRDF = """<?xml version="1.0"?>
<robot name="urdf_humanoid">
  <group name="legs"><joint name="left_hip_roll"/><joint name="right_hip_roll"/></group>
  <group_state name="legs_crossed" group="legs">
    <joint name="left_hip_roll" value="-0.3"/>
    <joint name="right_hip_roll" value="0.3"/>
  </group_state>
  <disable_collisions link1="left_thigh" link2="left_forearm" reason="Never"/>
</robot>
"""


def test_an_srdf_gives_keyframes_to_check_and_pairs_to_exclude(tmp_path):
    """Pairs touching only in a group_state are excluded too, and the SRDF's disabled pairs."""
    shutil.copy(PLAIN_URDF, tmp_path / "robot.urdf")
    (tmp_path / "urdf_humanoid.srdf").write_text(SRDF)
    backend = MujocoBackend(str(tmp_path / "robot.urdf"))
    model = backend.model
    notes = backend.conversions
    assert "excluded 1 pair the SRDF disables" in notes
    crossed = [n for n in notes if n.endswith("at keyframe 'legs_crossed'")]
    assert any(
        n.startswith("excluded the self-collision left_thigh – right_thigh: ") for n in crossed
    )
    assert not [n for n in notes if "standing pose" in n]  # the plain robot stands clear
    excluded = {
        tuple(sorted((model.body(s >> 16).name, model.body(s & 0xFFFF).name)))
        for s in model.exclude_signature
    }
    assert ("left_forearm", "left_thigh") in excluded
    assert ("left_thigh", "right_thigh") in excluded
    assert len(excluded) == 1 + len(crossed)
    # In the crossed pose the legs now pass through each other.
    backend.reset(standing_state(backend))
    backend.data.qpos[model.joint("left_hip_roll").qposadr[0]] = -0.3
    backend.data.qpos[model.joint("right_hip_roll").qposadr[0]] = 0.3
    mujoco.mj_forward(model, backend.data)
    assert robot_pairs(model, backend.data, set(range(1, model.nbody))) == set()


# -- URDF meshes ---------------------------------------------------------------------------


def write_box_stl(path: Path, size_m: tuple[float, float, float]) -> None:
    """A binary STL of a box centred on the origin, written to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(box_stl(size_m))


def urdf_with_meshes(directory: Path, meshes: dict[str, str]) -> Path:
    """The plain URDF humanoid with some links' collision boxes replaced by meshes."""
    robot = ET.parse(PLAIN_URDF).getroot()
    for link in robot.iter("link"):
        if link.get("name") in meshes:
            geometry = link.find("collision/geometry")
            geometry.remove(geometry[0])
            ET.SubElement(geometry, "mesh", filename=meshes[link.get("name")])
    path = directory / "robot.urdf"
    path.write_bytes(ET.tostring(robot))
    return path


def mesh_extent_of(model, body: str) -> np.ndarray:
    """The extent (m) of the one mesh geom of a body, smallest first (MuJoCo turns a mesh to
    its principal axes)."""
    (geom,) = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body(body).id]
    mesh = model.geom_dataid[geom]
    start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
    vertices = model.mesh_vert[start : start + count]
    return np.sort(vertices.max(axis=0) - vertices.min(axis=0))


def test_two_meshes_of_one_base_name_stay_two_meshes(tmp_path):
    write_box_stl(tmp_path / "meshes" / "pelvis" / "base_link_collision.STL", (0.16, 0.28, 0.14))
    write_box_stl(tmp_path / "meshes" / "torso" / "base_link_collision.STL", (0.2, 0.34, 0.42))
    path = urdf_with_meshes(
        tmp_path,
        {
            "pelvis": "meshes/pelvis/base_link_collision.STL",
            "torso": "meshes/torso/base_link_collision.STL",
        },
    )
    model = MujocoBackend(str(path)).model
    assert model.nmesh == 2
    np.testing.assert_allclose(mesh_extent_of(model, "pelvis"), (0.14, 0.16, 0.28), atol=1e-6)
    np.testing.assert_allclose(mesh_extent_of(model, "torso"), (0.2, 0.34, 0.42), atol=1e-6)


def test_mesh_names_never_make_mujoco_read_the_disk(tmp_path, monkeypatch):
    """A quote in a file name reaches MuJoCo only escaped, and a mesh the reader could not read
    is dropped (noted), not opened by MuJoCo from the working directory."""
    robot_dir, elsewhere = tmp_path / "robot", tmp_path / "cwd"
    write_box_stl(robot_dir / 'meshes/it"s.stl', (0.2, 0.34, 0.42))
    for decoy in ('it"s.stl', "s.stl", "head.stl", "meshes/head.stl"):
        write_box_stl(elsewhere / decoy, (1.0, 1.0, 1.0))
    path = urdf_with_meshes(robot_dir, {"torso": 'meshes/it"s.stl', "head": "meshes/head.stl"})
    monkeypatch.chdir(elsewhere)
    backend = MujocoBackend(str(path))
    model = backend.model
    assert model.nmesh == 1
    np.testing.assert_allclose(mesh_extent_of(model, "torso"), (0.2, 0.34, 0.42), atol=1e-6)
    head = model.body("head").id
    assert not any(model.geom_bodyid[g] == head for g in range(model.ngeom))
    assert "dropped 1 collision mesh(es) that could not be read: head (meshes/head.stl)" in (
        backend.conversions
    )


@pytest.mark.e2e
def test_a_ros_package_urdf_runs_in_mujoco(server, tmp_path):
    """``package://`` meshes (two different ``foot_collision.stl``), its SRDF's standing pose."""
    urdf = MODELS / "ros_ws/src/poise_test_description/urdf/poise_biped.urdf"
    result = poise_sim(
        tmp_path, server.endpoint, "stand", "--model", str(urdf), "--keyframe", "half_sitting",
        "--backend", "mujoco", "--duration", "1",
    )  # fmt: skip
    assert result.returncode == 0, explain(result, tmp_path)
    assert "Traceback" not in result.stderr
    assert "stayed up" in result.stdout
    assert "excluded 5 pairs the SRDF disables" in result.stdout
