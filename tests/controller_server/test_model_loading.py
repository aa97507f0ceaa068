"""Loading robot models: sources, formats, contacts, limits, hashes and typed errors."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from controller_server.errors import FrameNotFound, ModelError, wire_code
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model
from protocol.errors import ErrorCode
from protocol.messages import ContactSpec

MODEL_NAMES = tuple(BUILTIN_MODELS)

# Two legs on a base with no joint of its own: the loader must add the free flyer.
TINY_MJCF = """<mujoco model="tiny_biped">
  <compiler angle="radian"/>
  <worldbody>
    <body name="base" pos="0 0 0.5">
      <inertial pos="0 0 0" mass="4" diaginertia="0.1 0.1 0.1"/>
      <body name="left_leg" pos="0 0.1 -0.1">
        <joint name="left_hip" type="hinge" axis="0 1 0" range="-1 1"/>
        <inertial pos="0 0 -0.15" mass="1" diaginertia="0.01 0.01 0.002"/>
        <site name="left_sole" type="box" pos="0 0 -0.4" size="0.08 0.04 0.001"/>
      </body>
      <body name="right_leg" pos="0 -0.1 -0.1">
        <joint name="right_hip" type="hinge" axis="0 1 0" range="-1 1"/>
        <inertial pos="0 0 -0.15" mass="1" diaginertia="0.01 0.01 0.002"/>
        <site name="right_sole" type="box" pos="0 0 -0.4" size="0.08 0.04 0.001"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="left_hip" joint="left_hip" gear="2" ctrllimited="true" ctrlrange="-15 15"/>
    <motor name="right_hip" joint="right_hip" gear="1" ctrllimited="true" ctrlrange="-30 25"/>
  </actuator>
</mujoco>
"""

_INERTIA = '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>'
TINY_URDF = f"""<?xml version="1.0"?>
<robot name="tiny_urdf">
  <link name="base"><inertial><origin xyz="0 0 0"/><mass value="2"/>{_INERTIA}</inertial></link>
  <link name="leg"><inertial><origin xyz="0 0 -0.1"/><mass value="1"/>{_INERTIA}</inertial></link>
  <link name="foot"><inertial><origin xyz="0 0 0"/><mass value="0.5"/>{_INERTIA}</inertial></link>
  <joint name="hip" type="revolute">
    <parent link="base"/><child link="leg"/><origin xyz="0 0 -0.2"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="42" velocity="10"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="leg"/><child link="foot"/><origin xyz="0 0 -0.3"/><axis xyz="0 0 1"/>
    <limit lower="-0.1" upper="0.1" effort="7.5" velocity="1"/>
  </joint>
</robot>
"""
URDF_FOOT = ContactSpec(
    name="foot", frame="foot", points_in_frame=[(0.1, 0.05, 0.0), (-0.1, -0.05, 0.0)]
)


def mujoco_torque_limits_in_wire_order(robot: RobotModel, mj: mujoco.MjModel) -> np.ndarray:
    """|gear| × max|ctrlrange| per MuJoCo DoF, reordered by joint name into the wire order."""
    limit_by_dof = np.full(mj.nv, np.inf)
    for actuator in range(mj.nu):
        joint = mj.actuator_trnid[actuator, 0]
        bound = np.max(np.abs(mj.actuator_ctrlrange[actuator]))
        gear = mj.actuator_gear[
            actuator, : 3 if mj.jnt_type[joint] == mujoco.mjtJoint.mjJNT_BALL else 1
        ]
        for axis in np.flatnonzero(gear):
            limit_by_dof[mj.jnt_dofadr[joint] + axis] = abs(gear[axis]) * bound
    wire = []
    for info in robot.joints:
        joint = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, info.name)
        start = mj.jnt_dofadr[joint]
        wire.extend(limit_by_dof[start : start + info.nv])
    return np.array(wire)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_text_path_and_name_give_the_same_model(name: str, allow_model_dir) -> None:
    path = BUILTIN_MODELS[name]
    allow_model_dir(path.parent)
    by_name = load_robot_model(name)
    by_path = load_robot_model(str(path))
    by_text = load_robot_model(model_text=path.read_text(encoding="utf-8"))
    assert by_name is load_robot_model(name)  # cached
    for other in (by_path, by_text):
        assert other.model_hash == by_name.model_hash
        assert (other.model.nq, other.model.nv) == (by_name.model.nq, by_name.model.nv)
        assert other.joints == by_name.joints
        np.testing.assert_array_equal(other.torque_limit, by_name.torque_limit)
        assert [c.to_spec() for c in other.contacts] == [c.to_spec() for c in by_name.contacts]
        np.testing.assert_array_equal(
            other.standing_position_base_in_world, by_name.standing_position_base_in_world
        )


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_builtin_torque_limits_match_mujoco(name: str) -> None:
    robot = load_robot_model(name)
    mj = mujoco.MjModel.from_xml_path(str(BUILTIN_MODELS[name]))
    expected = mujoco_torque_limits_in_wire_order(robot, mj)
    assert robot.torque_limit.shape == (robot.nv_joints,) == (mj.nv - 6,)
    np.testing.assert_array_equal(robot.torque_limit, expected)
    wire = np.concatenate([info.torque_limit for info in robot.joints])
    np.testing.assert_array_equal(wire, expected)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_builtin_standing_position_is_mujoco_qpos0(name: str) -> None:
    robot = load_robot_model(name)
    mj = mujoco.MjModel.from_xml_path(str(BUILTIN_MODELS[name]))
    np.testing.assert_allclose(robot.standing_position_base_in_world, mj.qpos0[:3], atol=1e-12)
    assert robot.model.joints[1].shortname() == "JointModelFreeFlyer"
    assert robot.model.jointPlacements[1].isIdentity()


def test_mjcf_without_freejoint_gets_a_free_flyer_root() -> None:
    robot = load_robot_model(model_text=TINY_MJCF)
    model = robot.model
    assert model.joints[1].shortname() == "JointModelFreeFlyer"
    assert (model.nq, model.nv) == (9, 8)
    assert [info.name for info in robot.joints] == ["left_hip", "right_hip"]
    assert [info.kind for info in robot.joints] == ["revolute", "revolute"]
    np.testing.assert_array_equal(robot.torque_limit, [30.0, 30.0])
    assert [c.name for c in robot.contacts] == ["left_foot", "right_foot"]
    assert [c.frame_name for c in robot.contacts] == ["left_sole", "right_sole"]
    for contact in robot.contacts:
        np.testing.assert_array_equal(
            np.sort(contact.points_in_frame, axis=0),
            np.sort([[sx * 0.08, sy * 0.04, 0.0] for sx in (1, -1) for sy in (1, -1)], axis=0),
        )
    assert robot.total_mass == pytest.approx(6.0)


def mujoco_saturated_joint_force(mj: mujoco.MjModel) -> np.ndarray:
    """max |qfrc_actuator| per DoF over controls far beyond both ends of their range."""
    data = mujoco.MjData(mj)
    largest = np.zeros(mj.nv)
    for sign in (1.0, -1.0):
        data.ctrl[:] = sign * 1e9
        mujoco.mj_forward(mj, data)
        largest = np.maximum(largest, np.abs(data.qfrc_actuator))
    return largest


@pytest.mark.parametrize(
    "motor_limits",
    [
        "",  # ctrlrange only
        'forcelimited="true" forcerange="-10 10"',  # binds after the gear of 2 on the left hip
        'forcelimited="true" forcerange="-100 100"',  # never binds
    ],
)
def test_client_mjcf_torque_limits_match_mujoco_saturation(motor_limits: str) -> None:
    text = TINY_MJCF.replace('ctrllimited="true"', f'ctrllimited="true" {motor_limits}')
    robot = load_robot_model(model_text=text)
    expected = mujoco_saturated_joint_force(mujoco.MjModel.from_xml_string(text))
    # MuJoCo's free joint of the welded base does not exist: its DoFs are the joints only.
    np.testing.assert_allclose(robot.torque_limit, expected, rtol=1e-12)


def test_mjcf_without_freejoint_stands_where_mujoco_puts_it() -> None:
    """The root body's ``pos`` is the standing base position, soles where MuJoCo has them."""
    robot = load_robot_model(model_text=TINY_MJCF)
    mj = mujoco.MjModel.from_xml_string(TINY_MJCF)
    mj_data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, mj_data)
    np.testing.assert_allclose(robot.standing_position_base_in_world, [0.0, 0.0, 0.5], atol=1e-12)
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    for contact in robot.contacts:
        site = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_SITE, contact.frame_name)
        np.testing.assert_allclose(
            data.oMf[contact.frame_id].translation, mj_data.site_xpos[site], atol=1e-12
        )


@pytest.mark.parametrize(
    "free_joint", ['<freejoint name="root"/>', '<joint name="root" type="free"/>']
)
def test_both_free_joint_spellings_stand_where_mujoco_puts_them(free_joint: str) -> None:
    """Issue 18: ``<joint type="free"/>`` is a free joint too (its root ``pos`` counted once)."""
    text = TINY_MJCF.replace(
        '<inertial pos="0 0 0" mass="4"', f'{free_joint}\n      <inertial pos="0 0 0" mass="4"'
    )
    robot = load_robot_model(model_text=text)
    mj = mujoco.MjModel.from_xml_string(text)
    np.testing.assert_allclose(robot.standing_position_base_in_world, mj.qpos0[:3], atol=1e-12)
    np.testing.assert_allclose(robot.standing_position_base_in_world, [0.0, 0.0, 0.5])
    assert [info.name for info in robot.joints] == ["left_hip", "right_hip"]


def test_urdf_text_with_contacts_uses_effort_limits() -> None:
    robot = load_robot_model(model_text=TINY_URDF, model_format="urdf", contacts=[URDF_FOOT])
    assert robot.model.joints[1].shortname() == "JointModelFreeFlyer"
    assert [(info.name, info.kind) for info in robot.joints] == [
        ("hip", "revolute"),
        ("slide", "prismatic"),
    ]
    np.testing.assert_array_equal(robot.torque_limit, [42.0, 7.5])
    assert robot.contacts[0].to_spec() == URDF_FOOT
    assert robot.contacts[0].frame_id == robot.model.getFrameId("foot")


def test_urdf_without_contacts_is_refused() -> None:
    with pytest.raises(ModelError) as error:
        load_robot_model(model_text=TINY_URDF, model_format="urdf")
    assert wire_code(error.value) == ErrorCode.MODEL_INVALID
    assert error.value.field == "contacts"


def test_unknown_path_is_model_not_found(tmp_path, allow_model_dir) -> None:
    allow_model_dir(tmp_path)
    with pytest.raises(ModelError) as error:
        load_robot_model("no_such_robot.xml")
    assert wire_code(error.value) == ErrorCode.MODEL_NOT_FOUND
    assert error.value.field == "model"
    assert "'no_such_robot.xml'" in error.value.detail


@pytest.mark.parametrize("model_format", ["mjcf", "urdf"])
@pytest.mark.parametrize("text", ["<mujoco><worldbody><body", "not xml <", "<robot name='x'><link"])
def test_malformed_xml_is_model_invalid(text: str, model_format: str) -> None:
    with pytest.raises(ModelError) as error:
        load_robot_model(model_text=text, model_format=model_format)
    assert wire_code(error.value) == ErrorCode.MODEL_INVALID


def test_mjcf_without_sole_sites_needs_contacts() -> None:
    text = TINY_MJCF.replace("_sole", "_ankle")
    with pytest.raises(ModelError) as error:
        load_robot_model(model_text=text)
    assert wire_code(error.value) == ErrorCode.MODEL_INVALID
    assert error.value.field == "contacts"


def test_contact_on_missing_frame_is_frame_not_found() -> None:
    spec = ContactSpec(name="hand", frame="no_such_frame", points_in_frame=[(0.0, 0.0, 0.0)])
    with pytest.raises(FrameNotFound) as error:
        load_robot_model("revolute_humanoid", contacts=[spec])
    assert wire_code(error.value) == ErrorCode.MODEL_INVALID
    assert error.value.name == "no_such_frame"
    assert "left_sole" in error.value.available and "right_sole" in error.value.available


def test_hash_follows_the_contacts() -> None:
    default = load_robot_model("revolute_humanoid")
    specs = [c.to_spec() for c in default.contacts]
    same = load_robot_model("revolute_humanoid", contacts=specs)
    assert same.model_hash == default.model_hash
    slippery = [spec.model_copy(update={"friction_coefficient": 0.3}) for spec in specs]
    one_foot = specs[:1]
    hashes = {
        default.model_hash,
        load_robot_model("revolute_humanoid", contacts=slippery).model_hash,
        load_robot_model("revolute_humanoid", contacts=one_foot).model_hash,
    }
    assert len(hashes) == 3
    assert load_robot_model("revolute_humanoid", contacts=one_foot).contacts[0].name == "left_foot"
