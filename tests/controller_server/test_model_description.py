"""Robot files as vendors write them (issue 18): one reading for server and simulators.

Every check compares with something the reader does not compute itself:
Pinocchio's own MJCF parser, MuJoCo's compiled model, the built-in robot the
test models were written from, and the sole sites of the built-ins.
"""

import re
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from controller_server.controllers import create_controller
from controller_server.errors import FrameNotFound, ModelError, wire_code
from controller_server.models import BUILTIN_MODELS, load_robot_model
from controller_server.models.description import (
    DescriptionError,
    compile_mjcf,
    describe,
    expand_mjcf,
)
from protocol.errors import ErrorCode
from protocol.messages import ContactSpec

MODELS = Path(__file__).resolve().parents[1] / "models"
VENDOR = MODELS / "vendor_humanoid"


def local(path: Path):
    return lambda relative: (path.parent / relative).read_bytes()


def vendor(**options):
    scene = VENDOR / "scene.xml"
    return describe(scene.read_bytes(), read=local(scene), name="vendor", **options)


def random_motion(model: pin.Model, seed: int):
    rng = np.random.default_rng(seed)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    return q, rng.normal(size=model.nv), rng.normal(size=model.nv)


@pytest.mark.parametrize("name", sorted(BUILTIN_MODELS))
def test_the_model_built_from_mujoco_has_pinocchios_own_dynamics(name):
    """Inverse dynamics, mass matrix and sole frames equal Pinocchio's MJCF parser's."""
    path = BUILTIN_MODELS[name]
    ours = describe(path.read_bytes(), read=local(path)).model
    theirs = pin.buildModelFromMJCF(str(path))
    assert list(ours.names) == list(theirs.names)
    ours_data, theirs_data = ours.createData(), theirs.createData()
    for seed in range(5):
        q, v, a = random_motion(ours, seed)
        np.testing.assert_allclose(
            pin.rnea(ours, ours_data, q, v, a), pin.rnea(theirs, theirs_data, q, v, a), atol=1e-9
        )
        np.testing.assert_allclose(
            pin.crba(ours, ours_data, q), pin.crba(theirs, theirs_data, q), atol=1e-9
        )
        pin.framesForwardKinematics(ours, ours_data, q)
        pin.framesForwardKinematics(theirs, theirs_data, q)
        for frame in ("left_sole", "right_sole", "left_foot", "chest", "head"):
            if theirs.existFrame(frame):
                np.testing.assert_allclose(
                    ours_data.oMf[ours.getFrameId(frame)].homogeneous,
                    theirs_data.oMf[theirs.getFrameId(frame)].homogeneous,
                    atol=1e-12,
                )


def test_a_vendor_scene_is_the_robot_it_was_written_from():
    """Include, default classes, ``type="free"``, fullinertia, a camera rig and a mocap body."""
    description = vendor()
    builtin = load_robot_model("revolute_humanoid")
    model, reference = description.model, builtin.model
    assert description.joint_names == list(reference.names[2:])
    assert description.bodies[0].name == "pelvis"  # not the camera rig nor the mocap target
    assert description.total_mass == pytest.approx(builtin.total_mass, abs=1e-9)
    np.testing.assert_allclose(model.armature[6:], 0.01)  # from the joint default class
    data, reference_data = model.createData(), reference.createData()
    for seed in range(3):
        q, v, a = random_motion(model, seed)
        # The vendor file adds armature; with it taken out, the dynamics are the built-in's.
        armature_torque = model.armature * a
        np.testing.assert_allclose(
            pin.rnea(model, data, q, v, a) - armature_torque,
            pin.rnea(reference, reference_data, q, v, a),
            atol=1e-9,
        )


def test_torque_limits_come_from_default_classes_and_joint_actuatorfrcrange():
    description = vendor()
    limits = dict(zip(description.joint_names, description.torque_limit, strict=True))
    builtin = load_robot_model("revolute_humanoid")
    expected = {joint.name: joint.torque_limit[0] for joint in builtin.joints}
    # torso_yaw: forcerange ±100 from its class, actuatorfrcrange ±90 on the joint.
    # neck_yaw: forcerange ±20 on the actuator, actuatorfrcrange ±100 on the joint.
    expected["torso_yaw"] = 90.0
    assert limits == pytest.approx(expected)
    assert set(description.actuator_kind.values()) == {"position"}
    _, compiled = compile_mjcf((VENDOR / "scene.xml").read_bytes(), local(VENDOR / "scene.xml"))
    knee = compiled.actuator("left_knee")
    assert abs(knee.forcerange).max() == limits["left_knee"]  # MuJoCo reads the same class


def test_feet_are_found_where_the_sole_sites_of_the_builtins_are():
    for name, path in BUILTIN_MODELS.items():
        with_sites = load_robot_model(name)
        text = re.sub(r'<site name="\w+_sole"[^>]*/>', "", path.read_text())
        found = describe(text, name=name)
        assert found.contacts_source == "collision geometry"
        assert [c.name for c in found.contacts] == [c.name for c in with_sites.contacts]
        model, data = with_sites.model, with_sites.model.createData()
        pin.framesForwardKinematics(model, data, with_sites.standing_configuration)
        for contact, site_contact in zip(found.contacts, with_sites.contacts, strict=True):
            placement = data.oMf[model.getFrameId(contact.frame)]
            world = contact.points_in_frame @ placement.rotation.T + placement.translation
            site = data.oMf[site_contact.frame_id]
            expected = site_contact.points_in_frame @ site.rotation.T + site.translation
            np.testing.assert_allclose(np.sort(world, axis=0), np.sort(expected, axis=0), atol=1e-9)
        np.testing.assert_allclose(
            found.standing_configuration, with_sites.standing_configuration, atol=1e-12
        )


def test_mesh_and_sphere_feet_give_the_sole_of_their_lowest_points():
    # Mesh feet: the foot mesh's flat bottom, the built-in's foot box.
    mesh = vendor().contacts
    np.testing.assert_allclose(
        mesh[0].points_in_frame,
        [
            [0.17, 0.055, -0.07],
            [0.17, -0.055, -0.07],
            [-0.07, 0.055, -0.07],
            [-0.07, -0.055, -0.07],
        ],
        atol=1e-9,
    )
    # Four small spheres per foot: the rectangle of their bottoms.
    spheres = describe((MODELS / "sphere_feet_humanoid.xml").read_bytes()).contacts
    assert [c.name for c in spheres] == ["left_foot", "right_foot"]
    np.testing.assert_allclose(np.ptp(spheres[0].points_in_frame, axis=0), [0.22, 0.09, 0.0])
    np.testing.assert_allclose(spheres[0].points_in_frame[:, 2], -0.07)


def test_a_named_foot_gets_its_sole_found_and_unknown_frames_are_refused(allow_model_dir):
    named = vendor(contacts=[ContactSpec(name="l", frame="left_ankle_pitch_link")]).contacts
    # The named body's subtree holds the foot: its sole, in the named body's frame (the
    # ankle-roll joint is at zero standing, so the frames differ only by nothing).
    np.testing.assert_allclose(named[0].points_in_frame, vendor().contacts[0].points_in_frame)
    with pytest.raises(DescriptionError, match="did you mean 'left_foot'") as info:
        vendor(contacts=[ContactSpec(name="l", frame="left_fot")])
    assert info.value.field == "contacts"
    allow_model_dir(MODELS)
    with pytest.raises(FrameNotFound):
        load_robot_model(
            "vendor_humanoid/scene.xml", contacts=[ContactSpec(name="l", frame="left_fot")]
        )


def test_a_keyframe_sets_the_standing_pose_reference_pose_and_cm_height(allow_model_dir):
    allow_model_dir(MODELS)
    robot = load_robot_model("vendor_humanoid/scene.xml", keyframe="home")
    compiled = mujoco.MjModel.from_xml_path(str(VENDOR / "scene.xml"))
    key = compiled.key("home").qpos
    joints = {compiled.joint(j).name: key[compiled.jnt_qposadr[j]] for j in range(1, compiled.njnt)}
    np.testing.assert_allclose(
        robot.standing_joint_position, [joints[joint.name] for joint in robot.joints]
    )
    assert robot.standing_joint_position[robot.model.getJointId("left_knee") - 2] == 0.6
    # The soles touch z = 0 in the crouch (the keyframe's base height has them 20 cm up).
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.standing_configuration)
    lowest = min(
        (data.oMf[c.frame_id].act(p))[2] for c in robot.contacts for p in c.points_in_frame
    )
    assert lowest == pytest.approx(0.0, abs=1e-12)
    assert key[2] - robot.standing_position_base_in_world[2] == pytest.approx(0.2057, abs=1e-3)
    controller = create_controller("prioritized", robot)
    params = controller.parameters()
    np.testing.assert_allclose(params["reference_joint_position"], robot.standing_joint_position)
    com = pin.centerOfMass(robot.model, data, robot.standing_configuration)
    assert params["com_height"] == pytest.approx(com[2])
    with pytest.raises(ModelError, match="keyframes: home, stand") as info:
        load_robot_model("vendor_humanoid/scene.xml", keyframe="crouch")
    assert info.value.field == "keyframe"
    assert robot.model_hash != load_robot_model("vendor_humanoid/scene.xml").model_hash


def test_a_urdf_stands_on_its_soles_with_its_effort_limits(allow_model_dir):
    urdf = MODELS / "urdf_humanoid" / "robot.urdf"
    allow_model_dir(MODELS)
    robot = load_robot_model("urdf_humanoid/robot.urdf")
    builtin = load_robot_model("revolute_humanoid")
    assert robot.standing_position_base_in_world[2] == pytest.approx(
        builtin.standing_position_base_in_world[2]
    )
    assert [c.name for c in robot.contacts] == ["left_foot", "right_foot"]
    limits = {joint.name: joint.torque_limit for joint in robot.joints}
    assert limits == {joint.name: joint.torque_limit for joint in builtin.joints}
    assert robot.description.actuator_kind["left_knee"] == "effort"
    assert urdf.is_file()


def test_includes_and_assets_are_read_only_through_the_reader(tmp_path, allow_model_dir):
    """A sent model reads only the files sent with it; a server model only its directories."""
    opened: list[str] = []

    def read(path: str) -> bytes:
        opened.append(path)
        return (VENDOR / path).read_bytes()

    xml, assets = expand_mjcf((VENDOR / "scene.xml").read_bytes(), read)
    assert sorted(opened) == ["assets/foot.stl", "robot.xml"]
    assert "<include" not in xml and set(assets) == {"poise_asset_0.stl"}
    # A sent model naming a server file: refused, and nothing is opened.
    for text in (
        '<mujoco><include file="/etc/passwd"/></mujoco>',
        '<mujoco><asset><mesh name="m" file="/etc/hostname.stl"/></asset></mujoco>',
        '<mujoco><asset><texture name="t" type="cube" fileright="../x.png"/></asset></mujoco>',
    ):
        with pytest.raises(ModelError) as info:
            load_robot_model(model_text=text)
        assert wire_code(info.value) == ErrorCode.MODEL_INVALID
        assert "not among the files sent with the model" in info.value.detail
        assert "\n" not in info.value.detail
    # A model in the model directories cannot reach out of them.
    inside, outside = tmp_path / "inside", tmp_path / "outside"
    inside.mkdir(), outside.mkdir()
    (outside / "robot.xml").write_text((VENDOR / "robot.xml").read_text())
    (inside / "scene.xml").write_text('<mujoco><include file="../outside/robot.xml"/></mujoco>')
    allow_model_dir(inside)
    with pytest.raises(ModelError, match="not a readable file in the server's model directories"):
        load_robot_model("scene.xml")


def test_a_sent_scene_with_its_files_loads_like_the_same_files_on_the_server(allow_model_dir):
    allow_model_dir(MODELS)
    on_server = load_robot_model("vendor_humanoid/scene.xml", keyframe="home")
    sent = load_robot_model(
        model_text=(VENDOR / "scene.xml").read_text(),
        model_assets={
            "robot.xml": (VENDOR / "robot.xml").read_bytes(),
            "assets/foot.stl": (VENDOR / "assets" / "foot.stl").read_bytes(),
        },
        keyframe="home",
    )
    assert sent.model_hash == on_server.model_hash
    np.testing.assert_array_equal(sent.standing_configuration, on_server.standing_configuration)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('<mujoco><include file="a.xml"/></mujoco>', "does not end"),
        ("<mujoco><extension><plugin plugin='x'/></extension></mujoco>", "plugins"),
        ("<robot name='r'><link name='a'/></robot>", "<mujoco>"),
        ("<mujoco><worldbody><body><geom size='1'/></body></worldbody></mujoco>", "no body with"),
    ],
)
def test_what_cannot_be_read_says_why_on_one_line(text, message):
    files = {"a.xml": b'<mujoco><include file="a.xml"/></mujoco>'}
    with pytest.raises(DescriptionError, match=message) as info:
        describe(text, read=lambda path: files[path])
    assert "\n" not in str(info.value)


CAPSULE_FEET = """
<mujoco model="capsule_feet">
  <compiler angle="degree"/>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1"/>
    <body name="root" pos="0 0 1">
      <freejoint name="root"/>
      <geom type="ellipsoid" size="0.1 0.15 0.2" mass="20"/>
      <site name="root" pos="0 0 0.2"/>
      <body name="left_leg" pos="0 0.1 -0.4">
        <joint name="left_hip" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.04" mass="3"/>
        <body name="left_shoe" pos="0 0 -0.5">
          <joint name="left_ankle" axis="0 1 0"/>
          <geom type="capsule" size="0.02 0.08" pos="0 0.03 -0.05" euler="0 90 0" mass="0.5"/>
          <geom type="capsule" size="0.02 0.08" pos="0 -0.03 -0.05" euler="0 90 0" mass="0.5"/>
        </body>
      </body>
      <body name="right_leg" pos="0 -0.1 -0.4">
        <joint name="right_hip" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.04" mass="3"/>
        <body name="right_shoe" pos="0 0 -0.5">
          <joint name="right_ankle" axis="0 1 0"/>
          <geom type="capsule" size="0.02 0.08" pos="0 0.03 -0.05" euler="0 90 0" mass="0.5"/>
          <geom type="capsule" size="0.02 0.08" pos="0 -0.03 -0.05" euler="0 90 0" mass="0.5"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_capsule_feet_stand_on_their_bottoms_and_shared_names_resolve_to_bodies():
    """Round shapes touch at their bottoms (a capsule along its segment), whatever their axes;
    a free joint and a site named like their body (``root``, as in the CMU humanoid) leave
    the name to the body."""
    description = describe(CAPSULE_FEET)
    left, right = description.contacts
    assert (left.name, left.frame, right.frame) == ("left_foot", "left_shoe", "right_shoe")
    np.testing.assert_allclose(
        np.sort(left.points_in_frame, axis=0),
        np.sort([[sx * 0.08, sy * 0.03, -0.07] for sx in (1, -1) for sy in (1, -1)], axis=0),
        atol=1e-12,
    )
    model = description.model
    assert model.frames[model.getFrameId("root")].type == pin.BODY
    assert description.standing_configuration[2] == pytest.approx(1.0 + 0.4 + 0.5 + 0.07 - 1.0)
    # The reader's points are MuJoCo's geoms: the ellipsoid's extremes along its axes.
    compiled = mujoco.MjModel.from_xml_string(CAPSULE_FEET)
    root = description.bodies[0]
    np.testing.assert_allclose(np.abs(root.collision_points).max(axis=0), compiled.geom_size[1])


def test_a_turned_keyframe_keeps_the_feet_sides_and_sets_the_reference_orientations():
    text = CAPSULE_FEET.replace(
        "</worldbody>",
        '</worldbody><keyframe><key name="turned" qpos="0 0 1 0.7071068 0 0 0.7071068 '
        '-0.2 0.2 -0.2 0.2"/></keyframe>',
    )
    robot = load_robot_model(model_text=text, keyframe="turned")
    np.testing.assert_allclose(
        robot.standing_orientation_base_in_world_xyzw, [0, 0, np.sqrt(0.5), np.sqrt(0.5)]
    )
    assert [c.frame_name for c in robot.contacts] == ["left_shoe", "right_shoe"]
    momentum = create_controller("momentum", robot).parameters()
    prioritized = create_controller("prioritized", robot).parameters()
    for orientation in (
        momentum["reference_base_orientation_xyzw"],
        prioritized["reference_trunk_orientation_xyzw"],
    ):
        np.testing.assert_allclose(orientation, robot.standing_orientation_base_in_world_xyzw)
    np.testing.assert_allclose(momentum["reference_joint_position"], [-0.2, 0.2, -0.2, 0.2])
