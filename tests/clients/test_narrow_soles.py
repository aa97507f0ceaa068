"""Balance on narrow soles (issue 31): a 52 kg vendor-style robot on 3 cm-wide feet.

Each controller, through a real server in MuJoCo, survives a push from the side of 80 % of
the robot's no-step bound (capturability, Koolen & Pratt 2012): ``J = m ω d``, with
``ω = √(g / z_CM)`` and ``d`` the distance from the CM's ground projection at the standing
pose to the edge of the support polygon (both soles) along the push.
"""

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from clients.physics.backend import PushSpec
from clients.physics.model_file import describe_model
from clients.sim.runner import run_scenario
from clients.sim.scenario import load_scenario
from controller_server.balance_points import polygon_width, support_polygon
from controller_server.models.description import RobotDescription

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

SCENE = Path(__file__).resolve().parents[1] / "models" / "narrow_sole_humanoid" / "scene.xml"
KEYFRAME = "home"
PUSH_DURATION_S = 0.1
GRAVITY = 9.81


def sole_points_in_world(robot: RobotDescription) -> np.ndarray:
    """Every contact point at the standing pose, ``(points, 3)`` in the world frame (m)."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, robot.standing_configuration)
    return np.array(
        [
            data.oMf[model.getFrameId(contact.frame)].act(point)
            for contact in robot.contacts
            for point in contact.points_in_frame
        ]
    )


def no_step_bound_Ns(robot: RobotDescription, direction_in_world: np.ndarray) -> float:
    """``m ω d`` (N·s) along the horizontal ``direction_in_world`` at the standing pose."""
    position_com_in_world = pin.centerOfMass(
        robot.model, robot.model.createData(), robot.standing_configuration
    )
    points = sole_points_in_world(robot)
    height_m = position_com_in_world[2] - points[:, 2].min()
    unit = direction_in_world[:2] / np.linalg.norm(direction_in_world[:2])
    distance_m = max((points[:, :2] - position_com_in_world[:2]) @ unit)
    return robot.total_mass * math.sqrt(GRAVITY / height_m) * distance_m


def test_the_test_robot_is_heavy_and_stands_on_3_cm_soles():
    robot = describe_model(str(SCENE), keyframe=KEYFRAME)
    assert robot.total_mass == pytest.approx(52.0, abs=0.5)
    assert [c.name for c in robot.contacts] == ["left_foot", "right_foot"]
    points = sole_points_in_world(robot)
    for sole in (points[:4], points[4:]):
        assert polygon_width(support_polygon(sole)) == pytest.approx(0.03, abs=1e-6)
    # From the side the CM is 11.5 cm from the polygon's edge: a bound near 19 N·s.
    bound = no_step_bound_Ns(robot, np.array([0.0, 1.0, 0.0]))
    assert bound == pytest.approx(19.3, abs=0.3)


@pytest.mark.parametrize("controller", ["momentum", "prioritized"])
def test_a_push_from_the_side_of_80_percent_of_the_bound_is_survived(server, controller):
    robot = describe_model(str(SCENE), keyframe=KEYFRAME)
    direction = np.array([0.0, 1.0, 0.0])
    force_N = 0.8 * no_step_bound_Ns(robot, direction) / PUSH_DURATION_S
    scenario = load_scenario(
        "stand",
        model=str(SCENE),
        keyframe=KEYFRAME,
        backend="mujoco",
        controller=controller,
        duration_s=3.0,
        pushes=[
            PushSpec(
                body="torso",
                force_in_world_N=[float(f) for f in force_N * direction],
                start_s=0.5,
                duration_s=PUSH_DURATION_S,
            )
        ],
    )
    record = run_scenario(scenario, server.endpoint)
    assert not record.fell, record.fall_reason
    # The push moved it sideways (the base left the centre line), and it stayed on its feet
    # to the end, 2.4 s after the push (rocking from one sole to the other: see issue 31),
    # its base no lower than 5 cm under the standing height.
    base_y = [state.position_base_in_world[1] for state in record.states]
    assert max(base_y) > 0.01, max(base_y)
    heights = [state.position_base_in_world[2] for state in record.states]
    assert min(heights) > heights[0] - 0.05, (heights[0], min(heights))
