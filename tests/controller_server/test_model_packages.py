"""Files a published robot names (issue 31): unnamed MJCF assets, ``package://`` URIs, SRDFs.

The names of unnamed assets are checked against MuJoCo's own parser; the package
rules against ROS's (``ROS_PACKAGE_PATH`` first, searched below each entry,
packages not searched into, ignore markers; then the URDF's ancestors); the
server's reader against its model directories; SRDF keyframes against the
joints they set.
"""

import shutil
import struct
import zlib
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from clients.physics.model_file import hello_model, local_reader
from controller_server.errors import ModelError
from controller_server.models import load_robot_model
from controller_server.models.description import (
    DescriptionError,
    describe,
    expand_mjcf,
    find_package,
    foot_candidates,
    gather_files,
    resolve_file,
)
from protocol.messages import ContactSpec

MODELS = Path(__file__).resolve().parents[1] / "models"
PACKAGE = MODELS / "ros_ws" / "src" / "poise_test_description"
URDF = PACKAGE / "urdf" / "poise_biped.urdf"
FOOT_STL = (MODELS / "vendor_humanoid" / "assets" / "foot.stl").read_bytes()
LEFT_FOOT = "package://poise_test_description/meshes/left/foot_collision.stl"
RIGHT_FOOT = "package://poise_test_description/meshes/right/foot_collision.stl"


@pytest.fixture(autouse=True)
def no_ros_package_path(monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)


def package(directory: Path, name: str, manifest_name: str | None = None) -> Path:
    directory.mkdir(parents=True)
    (directory / "package.xml").write_text(
        f"<package format='3'><name>{manifest_name or name}</name></package>"
    )
    return directory


# -- unnamed MJCF assets -----------------------------------------------------------------


@pytest.mark.parametrize(
    "file",
    ["pelvis.STL", "meshes/foot.stl", "meshes/foot.Part.stl", "meshes\\left.stl", "d.x/file.stl"],
)
def test_an_unnamed_mesh_is_named_as_mujoco_names_it(tmp_path, file):
    """MuJoCo's parser, on the same file from disk, is the reference (``meshdir`` set)."""
    on_disk = tmp_path / "assets" / file.replace("\\", "/")
    on_disk.parent.mkdir(parents=True, exist_ok=True)
    on_disk.write_bytes(FOOT_STL)
    xml = (
        f'<mujoco><compiler meshdir="assets"/><asset><mesh file="{file}"/>'
        '<mesh name="kept" file="pelvis_named.stl"/></asset><worldbody/></mujoco>'
    )
    (tmp_path / "assets" / "pelvis_named.stl").write_bytes(FOOT_STL)
    (tmp_path / "model.xml").write_text(xml)
    theirs = [mesh.name for mesh in mujoco.MjSpec.from_file(str(tmp_path / "model.xml")).meshes]
    if "\\" in file:  # MuJoCo reads the backslash path; read here by the path as written
        expanded, assets = expand_mjcf(xml, lambda _: FOOT_STL)
    else:
        expanded, assets = expand_mjcf(xml, lambda path: (tmp_path / path).read_bytes())
    ours = [mesh.name for mesh in mujoco.MjSpec.from_string(expanded, assets=assets).meshes]
    assert ours == theirs
    assert theirs[1] == "kept"


def test_unnamed_textures_and_height_fields_are_named_after_their_files():
    rows = (b"\x00" + b"\x80" * 6) * 2  # a 2 × 2 grey image: per row a filter byte, 2 pixels

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    png = (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(rows))
        + chunk(b"IEND", b"")
    )
    xml = (
        '<mujoco><compiler texturedir="textures"/><asset>'
        '<texture type="2d" file="ground/grid.png"/><hfield file="terrain.png" size="1 1 1 1"/>'
        '<material name="m" texture="grid"/></asset>'
        '<worldbody><geom type="hfield" hfield="terrain"/></worldbody></mujoco>'
    )
    opened = []
    expanded, assets = expand_mjcf(xml, lambda path: opened.append(path) or png)
    compiled = mujoco.MjSpec.from_string(expanded, assets=assets).compile()
    assert (compiled.texture(0).name, compiled.hfield(0).name) == ("grid", "terrain")
    assert sorted(opened) == ["terrain.png", "textures/ground/grid.png"]


# -- package:// URIs ---------------------------------------------------------------------


def test_packages_are_found_as_ros_tools_find_them(tmp_path):
    ws = tmp_path / "ws"
    nested = package(ws / "src" / "repo" / "robot_description", "robot_description")
    renamed = package(ws / "src" / "checkout-1.2", "checkout-1.2", manifest_name="renamed")
    package(ws / "src" / "ignored" / "hidden_pkg", "hidden_pkg")
    (ws / "src" / "ignored" / "CATKIN_IGNORE").touch()
    package(ws / "src" / ".git" / "dot_pkg", "dot_pkg")
    package(nested / "inner", "inner")  # inside a package: ROS does not look there
    first = package(tmp_path / "first" / "robot_description", "robot_description")
    assert find_package("robot_description", [ws]) == nested
    assert find_package("robot_description", [tmp_path / "first", ws]) == first
    assert find_package("robot_description", [first]) == first  # an entry that is the package
    assert find_package("renamed", [ws]) == renamed  # by its manifest's <name>
    for hidden in ("hidden_pkg", "dot_pkg", "inner", "missing"):
        assert find_package(hidden, [ws]) is None
    # Then the ancestors of the URDF's directory, named like the package (no manifest needed).
    urdf_directory = tmp_path / "example-robot-data" / "robots" / "talos_data" / "robots"
    urdf_directory.mkdir(parents=True)
    assert find_package("example-robot-data", [], urdf_directory) == urdf_directory.parents[2]
    assert find_package("robot_description", [ws], urdf_directory) == nested
    # Confined: a package outside `within` is not found, wherever it is.
    assert find_package("robot_description", [ws], within=[tmp_path / "first"]) is None
    assert find_package("example-robot-data", [], urdf_directory, within=[urdf_directory]) is None


def test_uris_and_paths_resolve_to_files(tmp_path):
    found = package(tmp_path / "pkg", "pkg")
    directory = tmp_path / "pkg" / "urdf"
    assert resolve_file("package://pkg/meshes/a.stl", directory) == found / "meshes" / "a.stl"
    assert resolve_file("../meshes/a.stl", directory) == directory / "../meshes/a.stl"
    assert resolve_file("file:///abs/a.stl", directory) == Path("/abs/a.stl")
    with pytest.raises(DescriptionError, match="file:// URIs are not read here"):
        resolve_file("file:///abs/a.stl", directory, file_uris=False)
    with pytest.raises(DescriptionError, match="http:// URIs are not read here"):
        resolve_file("http://example.com/a.stl", directory)
    with pytest.raises(DescriptionError) as info:
        resolve_file("package://other/a.stl", directory, search_path=[tmp_path / "ws"])
    assert str(info.value) == (
        f"package 'other' is not in ROS_PACKAGE_PATH ({tmp_path / 'ws'}) nor an ancestor of "
        f"'{directory}'"
    )


def test_gather_files_keys_meshes_and_the_srdf_by_the_names_the_urdf_gives_them():
    asked: list[str] = []

    def read(name: str) -> bytes:
        asked.append(name)
        return local_reader(URDF)(name)

    files = gather_files(URDF.read_bytes(), "urdf", read)
    meshes = "package://poise_test_description/meshes/"
    assert sorted(files) == [
        "../srdf/poise_biped.srdf",
        f"{meshes}left/foot_collision.stl",
        f"{meshes}pelvis_collision.stl",
        f"{meshes}right/foot_collision.stl",
        f"{meshes}wrist_ft_collision.stl",
    ]
    # In file order, each once (both wrists name one file); the SRDF beside, then in ../srdf.
    assert asked == [
        f"{meshes}pelvis_collision.stl",
        f"{meshes}wrist_ft_collision.stl",
        f"{meshes}left/foot_collision.stl",
        f"{meshes}right/foot_collision.stl",
        "poise_biped.srdf",
        "../srdf/poise_biped.srdf",
    ]
    assert files[LEFT_FOOT] != files[RIGHT_FOOT]  # one file name, two meshes
    assert files[LEFT_FOOT] == (PACKAGE / "meshes" / "left" / "foot_collision.stl").read_bytes()


def test_a_sent_package_urdf_is_the_one_on_the_server(allow_model_dir):
    """The same description from the server's model directories (the package found as the
    URDF's ancestor) and from the files a client sends, keyed by URI (no protocol change)."""
    allow_model_dir(MODELS)
    on_server = load_robot_model(
        "ros_ws/src/poise_test_description/urdf/poise_biped.urdf", keyframe="half_sitting"
    )
    sent = load_robot_model(**hello_model(str(URDF)), keyframe="half_sitting")
    assert sent.model_hash == on_server.model_hash
    np.testing.assert_array_equal(sent.standing_configuration, on_server.standing_configuration)
    assert sent.description.disabled_collision_pairs == (
        on_server.description.disabled_collision_pairs
    )


def test_the_server_finds_packages_only_inside_its_model_directories(
    tmp_path, allow_model_dir, monkeypatch
):
    """Outside the model directories a package is not found, through ROS_PACKAGE_PATH, an
    ancestor or a symlink, and says nothing the client did not send; file:// is not read."""
    models = tmp_path / "models"
    copy = models / "ws" / "src" / PACKAGE.name
    shutil.copytree(PACKAGE, copy)
    allow_model_dir(models)
    robot = load_robot_model(f"ws/src/{PACKAGE.name}/urdf/poise_biped.urdf")
    assert [contact.name for contact in robot.contacts] == ["left_foot", "right_foot"]
    # Only the URDF inside the model directories: its package lies outside them.
    allow_model_dir(copy / "urdf")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(models / "ws"))
    with pytest.raises(ModelError) as info:
        load_robot_model("poise_biped.urdf")
    assert (
        f"cannot be read: it is not a readable file in the server's model directories "
        f"('{LEFT_FOOT}' names no file in them)" in info.value.detail
    )
    assert str(tmp_path) not in info.value.detail
    # A package directory inside that links out of the model directories.
    inside = tmp_path / "inside"
    (inside / "urdf").mkdir(parents=True)
    (inside / "poise_test_description").symlink_to(copy, target_is_directory=True)
    shutil.copy(URDF, inside / "urdf" / "poise_biped.urdf")
    allow_model_dir(inside)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(inside))
    with pytest.raises(ModelError, match="not a readable file in the server's model directories"):
        load_robot_model("urdf/poise_biped.urdf")
    text = URDF.read_text().replace(
        "package://poise_test_description/", f"file://{copy.as_posix()}/"
    )
    (inside / "urdf" / "file_uris.urdf").write_text(text)
    allow_model_dir(inside, copy)
    with pytest.raises(ModelError, match="names no file in them"):
        load_robot_model("urdf/file_uris.urdf")
    # The client reads file:// URIs.
    assert describe(text, "urdf", read=local_reader(inside / "urdf" / "file_uris.urdf")).contacts


# -- feet from meshes --------------------------------------------------------------------


def test_foot_candidates_are_the_lowest_links_not_the_wrist_leaves():
    """The wrist force-sensor links are leaves of the tree, like the feet, but high up."""
    description = describe(URDF.read_bytes(), "urdf", read=local_reader(URDF))
    model, data = description.model, description.model.createData()
    children = {body.parent for body in description.bodies}
    leaves = [body.name for i, body in enumerate(description.bodies) if i not in children]
    assert {"left_wrist_ft_link", "right_wrist_ft_link", "left_foot", "head"} <= set(leaves)
    for q in (
        description.standing_configuration,
        describe(
            URDF.read_bytes(), "urdf", read=local_reader(URDF), keyframe="half_sitting"
        ).standing_configuration,
    ):
        pin.framesForwardKinematics(model, data, q)
        assert sorted(foot_candidates(model, data, description.bodies)) == [
            "left_ankle_pitch_link",
            "left_foot",
            "right_ankle_pitch_link",
            "right_foot",
        ]


def test_a_missing_wrist_mesh_warns_once_a_missing_foot_mesh_is_refused():
    def without(*names: str):
        def read(name: str) -> bytes:
            if name in names:
                raise FileNotFoundError(2, "No such file or directory", f"/somewhere/{name}")
            return local_reader(URDF)(name)

        return read

    wrist = "package://poise_test_description/meshes/wrist_ft_collision.stl"
    pelvis = "package://poise_test_description/meshes/pelvis_collision.stl"
    description = describe(URDF.read_bytes(), "urdf", read=without(wrist, pelvis))
    assert [c.name for c in description.contacts] == ["left_foot", "right_foot"]
    (warning,) = [w for w in description.warnings if "collision mesh" in w]
    assert warning.startswith("2 collision mesh file(s) cannot be read and are left out, e.g. ")
    with pytest.raises(DescriptionError) as info:
        describe(URDF.read_bytes(), "urdf", read=without(wrist, RIGHT_FOOT))
    assert f"(tried '/somewhere/{RIGHT_FOOT}')" in str(info.value)
    assert "of link 'right_foot' (a foot candidate" in str(info.value)
    # Given points need no mesh; a named foot without points needs its own.
    given = describe(
        URDF.read_bytes(),
        "urdf",
        read=without(RIGHT_FOOT),
        contacts=[
            ContactSpec(name="left_foot", frame="left_foot"),
            ContactSpec(name="right_foot", frame="right_foot", points_in_frame=[(0, 0, -0.07)]),
        ],
    )
    assert [c.reason for c in given.contacts] == [
        "named; its sole from the collision geometry of 'left_foot' and below",
        "named, with its points",
    ]
    with pytest.raises(DescriptionError, match="'right_foot' \\(part of a named foot\\)"):
        describe(
            URDF.read_bytes(),
            "urdf",
            read=without(RIGHT_FOOT),
            contacts=[ContactSpec(name="right_foot", frame="right_ankle_pitch_link")],
        )


# -- SRDF --------------------------------------------------------------------------------


def srdf_reader(srdf: str):
    """The test URDF's files, its SRDF beside it replaced by ``srdf``."""

    def read(name: str) -> bytes:
        return srdf.encode() if name == "poise_biped.srdf" else local_reader(URDF)(name)

    return read


def test_group_states_of_one_name_merge_over_the_neutral_pose():
    description = describe(
        URDF.read_bytes(), "urdf", read=local_reader(URDF), keyframe="half_sitting"
    )
    joints = dict(zip(description.joint_names, description.standing_configuration[7:], strict=True))
    for side in ("left", "right"):  # one group_state per leg, both called half_sitting
        assert joints[f"{side}_hip_pitch"] == -0.3
        assert joints[f"{side}_knee"] == 0.6
        assert joints[f"{side}_ankle_pitch"] == -0.3
    assert joints["left_elbow"] == 0.0 and joints["torso_yaw"] == 0.0  # neutral, not named
    assert description.keyframes == ("half_sitting", "straight")
    assert description.disabled_collision_pairs == (
        ("left_forearm", "left_wrist_ft_link"),
        ("left_hip_yaw_link", "pelvis"),
        ("left_thigh", "right_thigh"),
        ("pelvis", "right_hip_yaw_link"),
        ("pelvis", "torso"),
    )
    assert not description.warnings


@pytest.mark.parametrize(
    ("srdf", "message"),
    [
        ("<robot><group_state name='a'>", "the SRDF 'poise_biped.srdf' is not valid XML: "),
        ("<mujoco/>", "an SRDF file's root element is <robot>, not <mujoco>"),
        (
            "<robot><group_state name='a'><joint name='left_knee' value='x'/></group_state>"
            "</robot>",
            "group_state 'a' gives joint 'left_knee' the value 'x'; write 1 number(s)",
        ),
        (
            "<robot><group_state name='a'><joint name='knee' value='1'/></group_state></robot>",
            "group_state 'a' sets joint 'knee', which the URDF does not have; did you mean",
        ),
    ],
)
def test_an_srdf_that_cannot_be_used_says_why_on_one_line(srdf, message):
    with pytest.raises(DescriptionError, match=message.replace("(", "\\(").replace(")", "\\)")):
        describe(URDF.read_bytes(), "urdf", read=srdf_reader(srdf))


def test_unknown_srdf_links_are_one_warning_and_fixed_joints_pass():
    srdf = (
        "<robot><group_state name='a' group='g'><joint name='left_wrist_ft_joint' value='0'/>"
        "<joint name='left_elbow' value='-0.5'/></group_state>"
        "<disable_collisions link1='left_thigh' link2='gripper'/>"
        "<disable_collisions link1='hand' link2='gripper'/>"
        "<disable_collisions link1='right_thigh' link2='left_thigh'/></robot>"
    )
    description = describe(URDF.read_bytes(), "urdf", read=srdf_reader(srdf), keyframe="a")
    assert description.disabled_collision_pairs == (("left_thigh", "right_thigh"),)
    assert description.warnings == (
        "the SRDF 'poise_biped.srdf' disables collisions of 2 link(s) the URDF does not have "
        "('gripper', 'hand'): those pairs are ignored",
    )
    elbow = description.joint_names.index("left_elbow")
    assert description.standing_configuration[7 + elbow] == -0.5


def test_an_srdf_given_by_path_is_sent_as_the_one_beside_the_urdf(tmp_path):
    """``hello_model(srdf=…)``: what `poise sim --srdf` sends; the server needs no new field."""
    srdf = tmp_path / "lab.srdf"
    srdf.write_text(
        "<robot name='poise_biped'><group_state name='lab' group='all'>"
        "<joint name='torso_yaw' value='0.25'/></group_state></robot>"
    )
    fields = hello_model(str(URDF), srdf=srdf)
    assert fields["model_assets"]["poise_biped.srdf"] == srdf.read_bytes()
    assert "../srdf/poise_biped.srdf" not in fields["model_assets"]  # the first one found wins
    robot = load_robot_model(**fields, keyframe="lab")
    torso = [joint.name for joint in robot.joints].index("torso_yaw")
    assert robot.standing_joint_position[torso] == 0.25
    assert robot.description.keyframes == ("lab",)
    with pytest.raises(DescriptionError, match=r"an SRDF goes with a URDF, not scene\.xml"):
        hello_model(str(MODELS / "vendor_humanoid" / "scene.xml"), srdf=srdf)
