"""Behaviours hosted by the controllers: targets for one tick, never the client's parameters.

Every controller hosts behaviours the same way (controllers/base.py); a behaviour says which
controllers can host it, and no controller's code names one.
"""

import io
import math
import tokenize
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from controller_server.behaviors import BEHAVIORS
from controller_server.behaviors.observation import Observation
from controller_server.controllers import CONTROLLERS, ControlInput, create_controller
from controller_server.errors import InvalidParams
from controller_server.models import load_robot_model

ROOT = Path(__file__).resolve().parents[2]
PERIOD_S = 2.0


@pytest.fixture(scope="module")
def robot():
    return load_robot_model("thesis_humanoid")


def standing(robot, time_s: float) -> ControlInput:
    q = robot.standing_configuration.copy()
    return ControlInput(time_s, q, np.zeros(robot.model.nv), (True,) * len(robot.contacts))


def lateral_rate(controller, robot, time_s: float, axis: np.ndarray) -> float:
    """The desired rate of linear momentum along ``axis`` at ``time_s`` (N)."""
    output = controller.compute(standing(robot, time_s))
    rate = np.asarray(output.diagnostics["linear_momentum_rate_desired"])
    return float(rate[:2] @ axis)


@pytest.mark.parametrize("name", ["momentum", "prioritized"])
def test_both_controllers_host_a_sway_that_moves_the_cm_reference_and_not_the_params(robot, name):
    """At a quarter period the CM is asked toward one foot, at three quarters toward the other,
    by the same amount; a client reading the parameters back sees its own offset."""
    params = {"behavior": "sway", "sway_amplitude": 0.02, "sway_period_s": PERIOD_S}
    if name == "momentum":
        params["optimizer_period_ticks"] = 1  # a behaviour runs at the optimizer's rate
    controller = create_controller(name, robot, params)
    balance = create_controller(name, robot, {k: v for k, v in params.items() if k != "behavior"})
    feet = robot.standing_configuration  # the feet's axis, from the standing pose
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, feet)
    left, right = (data.oMf[c.frame_id].translation[:2] for c in robot.contacts[:2])
    axis = (left - right) / np.linalg.norm(left - right)

    controller.compute(standing(robot, 0.0))  # the sway starts here
    toward_first = lateral_rate(controller, robot, PERIOD_S / 4, axis)
    toward_second = lateral_rate(controller, robot, 3 * PERIOD_S / 4, axis)
    still = lateral_rate(balance, robot, PERIOD_S / 4, axis)
    assert abs(still) < 1e-6 * max(abs(toward_first), 1.0)
    assert toward_first * toward_second < 0.0
    assert abs(toward_first) > 1.0  # N: a real request, not rounding
    assert math.isclose(abs(toward_first), abs(toward_second), rel_tol=1e-3)
    assert controller.behavior_state == "sway"
    assert controller.parameters()["com_offset_xy"] == [0.0, 0.0]
    assert np.any(controller.in_force()["com_offset_xy"] != 0.0)


@pytest.mark.parametrize("behavior", ["walk", "jump"])
@pytest.mark.parametrize("controller", ["momentum", "tracking"])
def test_a_behaviour_its_controller_cannot_host_is_a_typed_error(robot, controller, behavior):
    host = create_controller(controller, robot)
    with pytest.raises(InvalidParams, match="runs on prioritized") as caught:
        host.set_params({"behavior": behavior})
    assert caught.value.field == "params.behavior"
    assert host.parameters()["behavior"] == "balance"  # nothing changed


def test_a_jump_sets_its_targets_for_the_tick_and_balance_gives_every_one_back(robot):
    controller = create_controller("prioritized", robot, {"behavior": "jump"})
    own = controller.parameters()
    for tick in range(2):  # stand, then compress (jump_delay_s 0.3 s)
        controller.compute(standing(robot, 0.4 * tick))
    assert controller.behavior_state == "compress"
    in_force = controller.in_force()
    assert in_force["com_height"] < own["com_height"] - 0.1  # crouching
    assert in_force["priority_com_height"] == own["jump_com_height_priority"]
    assert controller.parameters() == own  # what a client reads back is its own
    controller.set_params({"behavior": "balance"})
    assert controller.behavior_state == "balance"
    assert {k: _plain(v) for k, v in controller.in_force().items()} == {
        k: _plain(v) for k, v in controller.parameters().items()
    }


def _plain(value):
    return [float(x) for x in value] if isinstance(value, np.ndarray) else value


def test_every_behaviour_names_hosts_that_exist_and_parameters_of_its_own():
    for name, behavior in BEHAVIORS.items():
        assert behavior.name == name
        assert set(behavior.HOSTS) <= set(CONTROLLERS), name
        assert all(key.startswith(f"{name}_") for key in behavior.PARAMETERS), name
        for host in behavior.HOSTS:
            assert set(behavior.PARAMETERS) <= set(CONTROLLERS[host].PARAMETERS), (name, host)


def names_in_code(path: Path) -> set[str]:
    """The identifiers of a module's code (its strings and comments left out)."""
    tokens = tokenize.generate_tokens(io.StringIO(path.read_text()).readline)
    return {token.string for token in tokens if token.type == tokenize.NAME}


def test_no_controller_names_a_behaviour_in_its_code():
    for path in (ROOT / "controller_server" / "controllers").glob("*.py"):
        named = {
            name
            for name in names_in_code(path)
            if any(word in name.lower() for word in ("walk", "jump", "knee", "shoulder"))
        }
        assert not named, (path.name, named)


def test_the_walk_learns_its_speed_correction_from_steps_that_land_on_time_only(robot):
    """A stumble's early or late touch-down measures the disturbance, not the model's bias:
    the footholds correct it in the next step, and learning it too counted it twice."""
    walk = BEHAVIORS["walk"](robot)
    walk._speed = 0.5  # the planned speed, reached
    params = {"walk_speed": 0.5, "walk_speed_gain": 0.5}
    contacts = len(robot.contacts)

    def touch_down(time_s: float, com_x: float, on_time: bool) -> float:
        observation = Observation(
            time_s,
            np.array([com_x, 0.0, 0.9]),
            np.zeros(3),
            (True,) * contacts,
            np.zeros((contacts, 3)),
            np.tile(np.eye(3), (contacts, 1, 1)),
            robot.standing_joint_position,
            np.array([0.0, 0.0, 0.0, 1.0]),
            0.0,
        )
        walk._learn_speed(observation, params, on_time)
        return walk._speed_correction

    assert touch_down(1.0, 0.0, on_time=True) == 0.0  # the first: nothing to compare with
    assert touch_down(1.4, 0.3, on_time=False) == 0.0  # a stumble at 0.75 m/s: not learned
    # On time again, at 0.2 m / 0.5 s = 0.4 m/s: the correction grows by 0.5 × 0.1 / 0.5.
    assert touch_down(1.9, 0.5, on_time=True) == pytest.approx(0.1)
