"""The task stack: one type for both controllers, tasks added, removed, re-weighted, re-ranked.

A task added at run time must move the solution toward its rows (and be reported); removing
it must give back exactly the controller without it; ``set_params`` must address the
controllers' own tasks by name.
"""

import numpy as np
import pytest

from controller_server.controllers import ControlInput, create_controller
from controller_server.errors import InvalidParams
from controller_server.features import Objective
from controller_server.models import load_robot_model
from controller_server.tasks import Task, TaskStack, Tick

TURN_RAD_S2 = 2.0
"""The root's angular acceleration about its vertical axis that :class:`PelvisTurn` asks."""


class PelvisTurn(Task):
    """A test task written as a user would: the pelvis turning on the hips, feet planted."""

    def __init__(self, name: str = "pelvis_turn"):
        super().__init__(name)
        self.ticks = 0

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """One row selecting ``ω̇_z`` of the free flyer."""
        self.ticks += 1
        row = np.zeros((1, tick.robot.model.nv))
        row[0, 5] = 1.0
        return Objective(self.name, row, np.array([TURN_RAD_S2]), np.array([weight]))


class Nothing(Task):
    """A task with no rows."""

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """None: nothing to ask this tick."""
        return None


@pytest.fixture(scope="module")
def robot():
    return load_robot_model("thesis_humanoid")


def standing(robot) -> ControlInput:
    q = robot.standing_configuration.copy()
    return ControlInput(0.0, q, np.zeros(robot.model.nv), (True,) * len(robot.contacts))


def test_the_stack_keeps_order_and_addresses_tasks_by_name():
    stack = TaskStack()
    first, second, third = PelvisTurn("a"), PelvisTurn("b"), Nothing("c")
    stack.add(first, 1.0, 1)
    stack.add(second, 2.0, 2)
    stack.add(third)
    replacement = PelvisTurn("a")
    stack.add(replacement, 3.0, 4)  # replaces `a` in its place
    assert stack.names() == ["a", "b", "c"]
    assert stack["a"].task is replacement and (stack["a"].weight, stack["a"].level) == (3.0, 4)
    stack.follow({"weight_b": 0.5, "priority_b": 3, "weight_other": 9.0})
    assert (stack["b"].weight, stack["b"].level) == (0.5, 3)
    stack.reweight("a", 0.0)
    stack.rerank("a", 1)
    assert (stack["a"].weight, stack["a"].level) == (0.0, 1)
    stack.remove("b")
    stack.remove("absent")
    assert stack.names() == ["a", "c"] and "b" not in stack and len(stack) == 2


def test_rows_leave_out_a_task_without_rows_and_keep_one_at_weight_zero(robot):
    stack = TaskStack()
    stack.add(PelvisTurn("on"), 2.0)
    stack.add(PelvisTurn("off"), 0.0)
    stack.add(Nothing("none"))
    state = standing(robot)
    tick = Tick(
        robot=robot,
        data=robot.model.createData(),
        q=state.q,
        v=state.v,
        time_s=0.0,
        terms=None,  # type: ignore[arg-type]  (PelvisTurn reads none of them)
        params={},
        supports=state.contact_flags,
        gravity=9.81,
    )
    solved = stack.solve_rows(tick)
    assert [(s.name, s.active) for s in solved] == [("on", True), ("off", False)]
    assert solved[0].objective.weight.tolist() == [2.0]
    assert stack.solve_rows(tick, block="torque") == []


@pytest.mark.parametrize("name", ["momentum", "prioritized"])
def test_a_task_added_at_run_time_moves_the_solution_and_removed_gives_it_back(robot, name):
    """Both controllers build their problem from the stack: a user's task enters the solve.

    Standing on both feet the pelvis may turn on the hips, so the task's row can be met;
    with it the root's commanded yaw acceleration comes most of the way to TURN_RAD_S2,
    without it (added, then removed) the command is bit for bit the controller's own.
    """
    # A user's task is Python: the weighted controllers solve it with the Python tick.
    params = {"optimizer_period_ticks": 1, "kernel": "python"} if name == "momentum" else {}
    plain = create_controller(name, robot, params)
    with_task = create_controller(name, robot, params)
    removed = create_controller(name, robot, params)
    task = PelvisTurn()
    with_task.tasks.add(task, weight=100.0, level=2)
    removed.tasks.add(PelvisTurn(), weight=100.0, level=2)
    removed.tasks.remove("pelvis_turn")

    state = standing(robot)
    own = plain.compute(state)
    asked = with_task.compute(state)
    back = removed.compute(state)

    assert task.ticks == 1
    before, after = abs(own.acceleration[5] - TURN_RAD_S2), abs(asked.acceleration[5] - TURN_RAD_S2)
    assert before > 0.9 * TURN_RAD_S2  # the controller's own command holds the pelvis still
    assert after < 0.5 * before
    # reported as ‖√w (A q̈ − b)‖ of the command
    residual = asked.diagnostics["objective_residuals"]["pelvis_turn"]
    assert residual == pytest.approx(10.0 * after, rel=1e-3, abs=1e-9)
    assert "pelvis_turn" not in back.diagnostics["objective_residuals"]
    np.testing.assert_array_equal(back.acceleration, own.acceleration)
    np.testing.assert_array_equal(back.joint_torque, own.joint_torque)


def test_the_compiled_tick_refuses_a_task_it_does_not_compute(robot):
    """The weighted controllers' compiled tick knows its own tasks only: a user's task is a
    typed error naming the kernel that solves it, never silently left out."""
    controller = create_controller("momentum", robot)
    assert controller.parameters()["kernel"] == "compiled"
    controller.tasks.add(PelvisTurn(), weight=100.0)
    with pytest.raises(InvalidParams, match=r"pelvis_turn.*kernel 'python'"):
        controller.compute(standing(robot))
    controller.set_params({"kernel": "python"})
    assert (
        controller.compute(standing(robot)).diagnostics["objective_residuals"]["pelvis_turn"] >= 0
    )


def _levels(output) -> list[list[str]]:
    return [level["objectives"] for level in output.diagnostics["prioritized"]["priority_levels"]]


def test_set_params_reranks_and_reweights_the_prioritized_controllers_tasks_by_name(robot):
    controller = create_controller("prioritized", robot)
    default = _levels(controller.compute(standing(robot)))
    assert ["com_height", "torque"] not in default  # torque has no selection: inactive
    assert any("com_height" in level and "com" not in level for level in default)

    controller.set_params({"priority_com_height": 2, "weight_pose": 0.0})
    levels = _levels(controller.compute(standing(robot)))
    assert (controller.tasks["com_height"].level, controller.tasks["pose"].weight) == (2, 0.0)
    together = [level for level in levels if "com" in level]
    assert len(together) == 1 and "com_height" in together[0]
    assert all("pose" not in level for level in levels)  # weight 0: reported, not solved


def test_point_targets_are_tasks_on_the_weighted_controllers_stack(robot):
    controller = create_controller("momentum", robot)
    assert controller.tasks.names() == ["tracking", "linear_momentum", "angular_momentum"]
    target = {"frame": "left_forearm", "target_position_in_world": [0.3, 0.2, 1.0], "weight": 2.0}
    controller.set_params({"point:hand": target})
    assert controller.tasks.names()[-1] == "point:hand"
    assert controller.tasks["point:hand"].weight == 2.0
    assert controller.parameters()["point:hand"]["frame"] == "left_forearm"
    controller.set_params({"point:hand": None})
    assert "point:hand" not in controller.tasks
