"""Extreme states and bad parameters: every tick ends, with a command or a typed error.

The server refuses physically meaningless states at its edge (|velocity| > 10³, …); these
tests call the controllers directly, so that they hold for any finite input. A tick that
hangs is killed by the CI time limit, which fails the test: a plain call is the check, and
no wall-clock time is asserted. What is asserted instead is bounded work: no QP at all on
data out of range, iteration caps, a fixed number of attempts under a spent time budget.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
import qpsolvers

from controller_server.controllers import CONTROLLERS, ControlInput, create_controller
from controller_server.controllers.base import Controller, ControllerFailed
from controller_server.controllers.compiled_tick import CompiledWeightedTick
from controller_server.errors import InvalidParams, ServerFault, wire_code
from controller_server.features import Objective
from controller_server.models import load_robot_model
from controller_server.session import Session
from controller_server.solvers import qp
from controller_server.solvers.prioritized import (
    qp_data_limit,
    solve_prioritized,
)
from controller_server.solvers.qp import QP_ITERATION_LIMITS, solve_qp_bounded
from protocol.errors import ErrorCode
from protocol.messages import Hello, SetParams

CONTROLLER_NAMES = ("momentum", "tracking", "prioritized")
EDGE = 1e3
"""The largest |velocity| the server accepts (rad/s, m/s)."""
EXTREMES = {
    "joint velocity 1e150": ("joint", 1e150),
    "joint velocity 1e100": ("joint", 1e100),
    "joint velocity 1e20": ("joint", 1e20),
    "joint velocity 1e8": ("joint", 1e8),
    "joint velocity 1e3": ("joint", EDGE),
    "base angular velocity 1e150": ("angular", 1e150),
    "base angular velocity 1e3": ("angular", EDGE),
    "base linear velocity 1e3": ("linear", EDGE),
    "joint velocity -1e3, base angular 1e3": ("mixed", EDGE),
}
"""Case → (which velocities, value), at the standing pose with every contact flagged."""


@pytest.fixture(scope="module")
def robot():
    return load_robot_model("thesis_humanoid")


def standing_input(robot, which: str, value: float) -> ControlInput:
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    v = np.zeros(robot.model.nv)
    if which == "joint":
        v[6:] = value
    elif which == "angular":
        v[3:6] = value
    elif which == "linear":
        v[:3] = value
    else:
        v[6:], v[3:6] = -value, value
    return ControlInput(0.0, q, v, (True,) * len(robot.contacts))


def check_outcome(robot, controller, control_input) -> str:
    """A finite command within the torque limits, or a typed SOLVE_FAILED error: which one."""
    try:
        output = controller.compute(control_input)
    except ServerFault as error:  # anything else (LinAlgError, ValueError) fails the test
        assert isinstance(error, ControllerFailed)
        assert wire_code(error) == ErrorCode.SOLVE_FAILED
        assert error.field == "controller"
        assert "\n" not in error.detail
        return "error"
    arrays = [
        output.acceleration,
        output.joint_torque,
        output.contact_force_in_world.reshape(-1),
        output.contact_wrench_in_world.reshape(-1),
    ]
    assert all(np.all(np.isfinite(array)) for array in arrays)
    assert np.all(np.abs(output.joint_torque) <= robot.torque_limit)
    return "command"


# 1. Extreme states ---------------------------------------------------------------------------


@pytest.mark.parametrize("qp_solver", ["daqp", "quadprog", "proxqp"])
@pytest.mark.parametrize("case", EXTREMES)
@pytest.mark.parametrize("name", CONTROLLER_NAMES)
def test_every_extreme_tick_ends_with_a_command_or_a_typed_error(robot, name, case, qp_solver):
    # The compiled kernel solves by quadprog's method only (eiquadprog): the others need python.
    kernel = {} if qp_solver == "quadprog" else {"kernel": "python"}
    controller = create_controller(name, robot, {"qp_solver": qp_solver, **kernel})
    control_input = standing_input(robot, *EXTREMES[case])
    outcomes = {check_outcome(robot, controller, control_input) for _ in range(2)}
    in_range = EXTREMES[case][1] <= EDGE
    if name != "prioritized" and in_range:
        assert outcomes == {"command"}


@pytest.mark.parametrize("case", [c for c, (_, value) in EXTREMES.items() if value > EDGE])
def test_prioritized_refuses_out_of_range_states_without_any_qp(robot, case, monkeypatch):
    """The inequality terms are too large to check: no solver is started (they used to spin)."""
    solutions = []

    def recording(*args, **kwargs):
        solutions.append(solve_prioritized(*args, **kwargs))
        return solutions[-1]

    monkeypatch.setattr("controller_server.controllers.prioritized.solve_prioritized", recording)
    controller = create_controller("prioritized", robot, {"qp_solver": "proxqp"})
    with pytest.raises(ControllerFailed, match="no QP"):
        controller.compute(standing_input(robot, *EXTREMES[case]))
    assert solutions[0].qp_attempts == 0
    assert solutions[0].levels[0].status == "infeasible"


@pytest.mark.parametrize("name", CONTROLLER_NAMES)
def test_overflowing_dynamics_are_a_typed_error_or_a_finite_command(robot, name):
    """Velocities whose squares overflow to inf: never a raw ValueError or LinAlgError."""
    controller = create_controller(name, robot)
    for value in (1e160, 1e200, 1e300):
        check_outcome(robot, controller, standing_input(robot, "joint", value))


@pytest.mark.parametrize("name", CONTROLLER_NAMES)
def test_a_failed_linear_solve_is_a_typed_error(robot, name, monkeypatch):
    def singular(*args, **kwargs):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(Controller, "_dynamics_terms", singular)
    monkeypatch.setattr(CompiledWeightedTick, "compute", singular)  # the compiled tick's
    controller = create_controller(name, robot)
    with pytest.raises(ControllerFailed, match=r"linear solve failed.*Singular matrix"):
        controller.compute(standing_input(robot, "joint", 0.0))


# 2. Bounded QP solves ------------------------------------------------------------------------


def overflowing_qp() -> qpsolvers.Problem:
    """Data of 1e300, as joint velocities of 1e150 made: ProxQP's residuals become NaN."""
    n = 6
    rng = np.random.default_rng(0)
    G = rng.normal(size=(8, n))
    return qpsolvers.Problem(np.eye(n), np.full(n, 1e300), G, np.full(8, -1e300))


def test_proxqp_stops_at_its_caps_on_nan_residuals():
    """The cause of the hang: 1500 inner iterations per outer one, on NaN residuals."""
    caps = QP_ITERATION_LIMITS["proxqp"]
    solution = solve_qp_bounded(overflowing_qp(), "proxqp", max_iter=10**6, max_iter_in=10**6)
    info = solution.extras["info"]
    assert not solution.found
    assert info.iter_ext <= caps["max_iter"]
    assert info.iter <= caps["max_iter"] * (caps["max_iter_in"] + 1)


def test_settings_may_lower_the_caps():
    solution = solve_qp_bounded(overflowing_qp(), "proxqp", max_iter=3)
    assert solution.extras["info"].iter_ext <= 3


def level_needing_a_qp(scale: float = 1.0):
    """x ≤ 0.2 scale, asked for x = scale: the closed form violates the inequality."""
    levels = [
        [Objective("first", np.array([[1.0, 0.0]]), np.array([scale]), np.ones(1))],
        [Objective("second", np.array([[0.0, 1.0]]), np.array([scale]), np.ones(1))],
    ]
    D = np.array([[-1.0, 0.0], [0.0, -1.0]])
    return levels, D, np.array([0.2, 0.2]) * scale


def never_found(calls):
    def solve(problem, solver, **settings):
        calls.append((solver, settings))
        return qpsolvers.Solution(problem, found=False)

    return solve


@pytest.mark.parametrize(("budget_s", "top_level_calls"), [(0.0, 3), (math.inf, 10)])
def test_a_spent_budget_leaves_one_attempt_per_solver(monkeypatch, budget_s, top_level_calls):
    """Past the budget no solver is tried twice; before it, retries and both curvatures."""
    calls: list = []
    monkeypatch.setattr(qp, "solve_qp_bounded", never_found(calls))
    solution = solve_prioritized(*level_needing_a_qp(), qp_time_budget_s=budget_s)
    # daqp, quadprog, proxqp once each; with time: + daqp's and proxqp's retries, × 2 curvatures.
    assert solution.qp_attempts == len(calls) == top_level_calls
    assert [level.status for level in solution.levels] == ["infeasible", "not reached"]
    expected = "QP time budget" if budget_s == 0.0 else "no QP solver found a solution"
    assert expected in solution.levels[0].detail


def test_a_spent_budget_skips_retries_below_the_top_level(monkeypatch):
    calls: list = []
    real = qp.solve_qp_bounded

    def top_level_real(problem, solver, **settings):
        if not calls:  # the top level's first attempt succeeds
            calls.append(solver)
            return real(problem, solver, **settings)
        return never_found(calls)(problem, solver, **settings)

    monkeypatch.setattr(qp, "solve_qp_bounded", top_level_real)
    solution = solve_prioritized(*level_needing_a_qp(), qp_time_budget_s=0.0)
    assert [level.status for level in solution.levels] == ["solved", "solver failed"]
    assert solution.qp_attempts == 2  # the second level: daqp once, no retry
    assert "QP time budget" in solution.levels[1].detail


def test_inequality_terms_beyond_the_rounding_limit_get_no_qp():
    scale = 10 * qp_data_limit(1e-7)
    solution = solve_prioritized(*level_needing_a_qp(scale))
    assert solution.qp_attempts == 0
    assert solution.levels[0].status == "infeasible"
    assert "no QP" in solution.levels[0].detail
    # Just below the limit the QP is solved as usual.
    solution = solve_prioritized(*level_needing_a_qp(1e3))
    assert solution.found
    np.testing.assert_allclose(solution.x, [200.0, 200.0], atol=1e-6)


# 3. Parameters -------------------------------------------------------------------------------


def numeric_parameters():
    for name, cls in CONTROLLERS.items():
        for key, spec in cls.PARAMETERS.items():
            if spec.kind in ("float", "int", "vector"):
                yield pytest.param(name, key, id=f"{name}.{key}")


def bad_values(controller, key):
    spec = controller.PARAMETERS[key]
    if spec.kind == "vector":
        size = np.size(controller.default_value(key))
        return [[bad] * size for bad in (math.nan, math.inf, -math.inf, True, 10**400)]
    values = [math.nan, math.inf, -math.inf, True, False, 10**400]
    if spec.kind == "int":
        values += [0.5 + max(spec.minimum, 0), spec.minimum - 1]
    return values


@pytest.mark.parametrize(("name", "key"), numeric_parameters())
def test_non_finite_and_boolean_numbers_are_invalid_params(robot, name, key):
    controller = create_controller(name, robot)
    before = controller.parameters()
    for value in bad_values(controller, key):
        with pytest.raises(InvalidParams) as hello:
            create_controller(name, robot, {key: value})
        with pytest.raises(InvalidParams) as set_params:
            controller.set_params({key: value})
        for error in (hello.value, set_params.value):
            assert wire_code(error) == ErrorCode.INVALID_PARAMS
            assert error.field == f"params.{key}"
    assert controller.parameters() == before


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan, 0, -1, 2.5, 0.0, 1e9])
def test_optimizer_period_ticks_is_checked_in_hello_and_set_params(value):
    """inf and NaN used to reach int() and end as INTERNAL errors."""
    params = {"optimizer_period_ticks": value}
    with pytest.raises(ServerFault) as hello:
        Session(Hello(model="thesis_humanoid", controller="momentum", params=params))
    session = Session(Hello(model="thesis_humanoid", controller="momentum"))
    with pytest.raises(ServerFault) as set_params:
        session.set_params(SetParams(params=params))
    for error in (hello.value, set_params.value):
        assert wire_code(error) == ErrorCode.INVALID_PARAMS
        assert error.field == "params.optimizer_period_ticks"


def test_integral_floats_are_integers(robot):
    controller = create_controller("momentum", robot, {"optimizer_period_ticks": 4.0})
    assert controller.parameters()["optimizer_period_ticks"] == 4


def test_point_target_numbers_beyond_the_float_range_are_invalid_params(robot):
    controller = create_controller("momentum", robot)
    target = {"frame": robot.model.frames[2].name, "target_position_in_world": [0, 0, 1]}
    for value in (10**400, math.inf, math.nan, True):
        with pytest.raises(InvalidParams) as error:
            controller.set_params({"point:hand": {**target, "stiffness": value}})
        assert error.value.field == "params.point:hand.stiffness"
