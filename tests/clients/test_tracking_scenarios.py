"""Thesis ch. 7.2–7.4 scenarios in the reference simulator, over ZeroMQ (issue 4 acceptance).

Double support (squat), single support (kicks: lean onto the right foot, the
left leg kicks, lands), the low-friction leg circle (μ = 0.03, ch. 7.3) and
point targets dragged around (ch. 7.4), all with every momentum objective on.
"""

import numpy as np
import pinocchio as pin
import pytest

from clients.physics.model_file import builtin_model_path
from clients.sim.app import run_scenarios
from clients.sim.metrics import compute_metrics
from clients.sim.runner import run_scenario
from clients.sim.scenario import load_scenario

pytestmark = [pytest.mark.e2e, pytest.mark.slow]


@pytest.mark.parametrize("name", ["squat", "low_friction_leg_circle"])
def test_tracked_motion_keeps_the_robot_up(server, tmp_path, name):
    (report,) = run_scenarios([name], tmp_path, endpoint=server.endpoint)
    assert report["backend"] == "reference"
    assert not report["fell"], report
    assert report["simulated_s"] == pytest.approx(load_scenario(name).duration_s)
    assert report["cop_strictly_inside_fraction"] > 0.9, report


def test_kicks_take_the_left_foot_off_the_supports(server):
    record = run_scenario(load_scenario("kicks"), server.endpoint)
    assert not record.fell
    report = compute_metrics(record)
    assert report["cop_strictly_inside_fraction"] > 0.9, report
    assert report["foot_slip_m"] < 0.01, report
    flags = np.array(record.contact_flags)
    time_s = np.array(record.time_s)
    kicking = (time_s > 2.5) & (time_s < 6.0)
    assert not flags[kicking, 0].any()  # the left foot is up, not a support
    assert flags[kicking, 1].all()  # the right foot carries the robot
    assert flags[-1].all()  # both feet down at the end


def test_dragged_point_targets_are_followed(server):
    """At 2.5 s the hands' targets are 25 cm ahead of and 5 cm above where they started."""
    scenario = load_scenario("point_constraints")
    record = run_scenario(scenario, server.endpoint)
    assert not record.fell
    model = pin.buildModelFromMJCF(str(builtin_model_path(scenario.model)))
    data = model.createData()

    def point_in_world(tick: int, frame: str, offset: list[float]) -> np.ndarray:
        state = record.states[tick]
        q = np.concatenate(
            [
                state.position_base_in_world,
                state.orientation_base_in_world_xyzw,
                state.joint_position,
            ]
        )
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[model.getFrameId(frame)].act(np.array(offset))

    targets = {}
    for change in scenario.param_changes:
        if change.time_s <= 2.5:
            targets.update(change.params)
    tick = int(np.searchsorted(record.time_s, 2.5))
    for name in ("left_hand", "right_hand"):
        target = targets[f"point:{name}"]
        frame, offset = target["frame"], target["offset_in_frame"]
        reached = point_in_world(tick, frame, offset)
        moved = reached - point_in_world(0, frame, offset)
        assert np.linalg.norm(reached - target["target_position_in_world"]) < 0.05, (name, reached)
        assert moved[0] > 0.15 and moved[2] > 0.02, (name, moved)
