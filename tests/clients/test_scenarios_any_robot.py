"""Built-in scenarios on any robot (issue 31, item 6): what they ask, in the robot's terms.

The crouch is found on the legs from the root to each contact, pushes on `chest` act on the
robot's trunk, the twist is a yaw rate times the robot's vertical inertia; the thesis humanoid
gets exactly what its scenarios gave it before (the quaternions and the 7 and 11 kg·m²/s they
wrote out). Then through the real command line on the vendor-style robot: the built-ins run,
and a user's mistake names the user's file.
"""

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from clients.physics.model_file import describe_model
from clients.physics.robot_terms import (
    crouched_joint_positions,
    knee_bend_rad,
    leg_pitch_joints,
    resolve_body,
    trunk_body,
    vertical_inertia,
)
from clients.sim.scenario import (
    controller_params,
    initial_configuration,
    initial_joint_positions,
    load_scenario,
)
from tests import helpers
from tests.helpers import REVOLUTE_CROUCH

VENDOR = str(Path(__file__).parents[1] / "models" / "vendor_humanoid" / "scene.xml")
THESIS_CROUCH = {
    # What the thesis humanoid's walk and jump scenarios wrote out before (about y, xyzw).
    f"{side}_{joint}": value
    for side in ("left", "right")
    for joint, value in (
        ("hip", [0.0, -0.149438, 0.0, 0.988771]),
        ("knee", [0.0, 0.29552, 0.0, 0.955336]),
        ("ankle", [0.0, -0.149438, 0.0, 0.988771]),
    )
}


@pytest.mark.parametrize("name", ["walk", "walk_fast", "walk_push", "walk_sad", "jump"])
def test_the_thesis_humanoid_crouches_as_its_scenarios_wrote_it(name):
    positions = initial_joint_positions(load_scenario(name))
    assert positions.keys() == THESIS_CROUCH.keys()
    for joint, value in THESIS_CROUCH.items():
        np.testing.assert_allclose(positions[joint], value, atol=1e-6)


def test_hinge_legs_crouch_by_their_own_joints():
    """The revolute humanoid's legs (yaw, roll, pitch hips; pitch, roll ankles): only the
    pitch joints move, as the tests' hand-written crouch."""
    positions = initial_joint_positions(load_scenario("walk", model="revolute_humanoid"))
    assert positions.keys() == REVOLUTE_CROUCH.keys()
    for joint, value in REVOLUTE_CROUCH.items():
        assert positions[joint] == pytest.approx(value, abs=1e-12)


def test_a_pose_already_bent_is_left_as_it_is():
    """The vendor's `home` keyframe has the knees at 0.6 rad: a 0.6 rad crouch adds nothing;
    a deeper one adds only the difference, the feet staying flat."""
    description = describe_model(VENDOR, keyframe="home")
    legs = leg_pitch_joints(description)
    assert [leg.knee.name for leg in legs] == ["left_knee", "right_knee"]
    q = description.standing_configuration
    assert [knee_bend_rad(description, leg, q) for leg in legs] == pytest.approx([0.6, 0.6])
    assert crouched_joint_positions(description, 0.6) == {}
    deeper = crouched_joint_positions(description, 0.8)
    assert deeper["left_knee"] == pytest.approx([0.8])
    assert deeper["left_hip_pitch"] == pytest.approx([-0.4])
    assert deeper["left_ankle_pitch"] == pytest.approx([-0.4])
    # The sole keeps its orientation.
    model = description.model
    crouched = q.copy()
    for joint, value in deeper.items():
        crouched[model.joints[model.getJointId(joint)].idx_q] = value[0]
    before, after = model.createData(), model.createData()
    pin.framesForwardKinematics(model, before, q)
    pin.framesForwardKinematics(model, after, crouched)
    foot = model.getFrameId("left_foot")
    np.testing.assert_allclose(after.oMf[foot].rotation, before.oMf[foot].rotation, atol=1e-9)


def test_a_user_pose_overrides_the_crouch_joint_by_joint():
    scenario = load_scenario("walk", initial_joint_position={"left_knee": [0.0, 0.0, 0.0, 1.0]})
    positions = initial_joint_positions(scenario)
    assert positions["left_knee"] == [0.0, 0.0, 0.0, 1.0]
    assert positions["right_knee"] == pytest.approx(THESIS_CROUCH["right_knee"], abs=1e-6)


def test_pushes_on_the_chest_act_on_each_robots_trunk():
    thesis, vendor = describe_model("thesis_humanoid"), describe_model(VENDOR)
    assert resolve_body(thesis, "chest") == "chest"  # a body the robot has is itself
    assert trunk_body(vendor) == "torso"  # 17 kg, the heaviest segment outside the legs
    assert resolve_body(vendor, "chest") == resolve_body(vendor, "abdomen") == "torso"
    assert resolve_body(vendor, "root") == "pelvis"
    assert resolve_body(vendor, "chst") is None
    scenario = load_scenario("push_sequence", model=VENDOR)
    assert {push.body for push in scenario.pushes} == {"torso"}


def test_the_twist_is_a_yaw_rate_times_the_robots_vertical_inertia():
    """7 and 11 kg·m²/s on the thesis humanoid as before; on another robot its own inertia."""
    for name, momentum in (("twist_jump_90", 7.0), ("twist_jump_180", 11.0)):
        thesis = load_scenario(name)
        assert controller_params(thesis)["jump_twist_angular_momentum"] == pytest.approx(
            momentum, abs=1e-4
        )
        vendor = load_scenario(name, model=VENDOR)
        inertia = vertical_inertia(describe_model(VENDOR), initial_configuration(vendor))
        assert controller_params(vendor)["jump_twist_angular_momentum"] == pytest.approx(
            thesis.twist_yaw_rate_rad_per_s * inertia
        )


def test_vertical_inertia_matches_a_hand_sum_over_the_bodies():
    """Σ (I_zz of each body about its CM + m (x² + y²) from the whole CM), from Pinocchio's
    per-joint inertias at the standing pose."""
    description = describe_model(VENDOR)
    model, q = description.model, description.standing_configuration
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    com = pin.centerOfMass(model, data, q)
    total = 0.0
    for joint in range(1, model.njoints):
        inertia = data.oMi[joint].act(model.inertias[joint])
        offset = inertia.lever - com
        rotation = inertia.inertia
        total += rotation[2, 2] + inertia.mass * (offset[0] ** 2 + offset[1] ** 2)
    assert vertical_inertia(description) == pytest.approx(total)


def test_a_twist_given_twice_is_refused():
    with pytest.raises(Exception, match="not both"):
        load_scenario(
            "twist_jump_90", params={"behavior": "jump", "jump_twist_angular_momentum": 3.0}
        )


# Through the real command line ---------------------------------------------------------


def poise_sim(tmp_path: Path, *arguments: str, timeout_s: float = 600.0):
    return helpers.run_poise(
        ["sim", *arguments, "--output", str(tmp_path / "out")], tmp_path, timeout_s
    )


@pytest.mark.slow
@pytest.mark.e2e
def test_the_built_ins_run_on_a_vendor_robot(tmp_path):
    """Once failed with `client_model has no joint 'left_hip'` (exit 2)."""
    result = poise_sim(
        tmp_path,
        *("walk", "jump", "twist_jump_90", "push_sequence"),
        *("--model", VENDOR, "--backend", "mujoco", "--duration", "0.3", "--workers", "1"),
    )
    assert result.returncode == 0, result.stderr
    reports = json.loads((tmp_path / "out" / "report.json").read_text())
    assert [r["scenario"] for r in reports] == ["walk", "jump", "twist_jump_90", "push_sequence"]
    assert not any(r["fell"] for r in reports)


@pytest.mark.e2e
def test_a_joint_the_robot_lacks_names_the_users_file(tmp_path):
    path = tmp_path / "crouch.toml"
    path.write_text(
        f'name = "crouch"\nmodel = "{VENDOR}"\nduration_s = 0.1\n'
        "[initial_joint_position]\nleft_hip = [0.3]\n"
    )
    result = poise_sim(tmp_path, str(path), timeout_s=90.0)
    assert result.returncode == 2
    (line,) = result.stderr.strip().splitlines()
    assert f"initial_joint_position: {VENDOR} has no joint 'left_hip'" in line
    assert "did you mean 'left_hip_yaw'?" in line
    assert "client_model" not in line


@pytest.mark.e2e
def test_a_crouch_on_a_robot_without_knees_says_what_to_give(tmp_path):
    robot = tmp_path / "stilts.xml"
    robot.write_text(
        """<mujoco><worldbody><body name="base" pos="0 0 0.6"><freejoint/>
        <geom type="box" size="0.1 0.2 0.05" mass="10"/>
        <body name="left_leg" pos="0 0.1 -0.3"><joint name="left_hip" axis="0 1 0"/>
          <geom type="box" size="0.03 0.03 0.25" mass="1"/>
          <body name="left_foot" pos="0 0 -0.27"><geom type="box" size="0.1 0.05 0.02"/></body>
        </body>
        <body name="right_leg" pos="0 -0.1 -0.3"><joint name="right_hip" axis="0 1 0"/>
          <geom type="box" size="0.03 0.03 0.25" mass="1"/>
          <body name="right_foot" pos="0 0 -0.27"><geom type="box" size="0.1 0.05 0.02"/></body>
        </body></body></worldbody></mujoco>"""
    )
    result = poise_sim(tmp_path, "jump", "--model", str(robot), timeout_s=90.0)
    assert result.returncode == 2
    (line,) = result.stderr.strip().splitlines()
    assert "initial_knee_bend_rad" in line and "1 pitch joint(s)" in line
    assert "initial_joint_position" in line
