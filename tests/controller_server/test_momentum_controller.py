"""The momentum-based controller through a session: every objective on, bad params, modes, rates."""

import numpy as np
import pinocchio as pin
import pytest

from controller_server.controllers import ControlInput, MomentumController
from controller_server.errors import InvalidParams, ServerFault, wire_code
from controller_server.features import load_motion_clip
from controller_server.models import BUILTIN_MODELS, load_robot_model
from controller_server.session import Session
from protocol import ErrorCode
from protocol.messages import Hello, SetParams
from tests.helpers import IndependentDynamics, random_state

ALL_ON = {
    "weight_linear_momentum": 2.0,
    "angular_momentum_gain": 50.0,
    "joint_limit_stiffness": 500.0,
    "joint_limit_damping": 50.0,
}


def hand_frame(robot):
    names = [f.name for f in robot.model.frames]
    return next(n for n in names if "forearm" in n or "elbow" in n or "head" in n or "neck" in n)


def point_params(robot, name="reach", x=0.3):
    return {
        f"point:{name}": {
            "frame": hand_frame(robot),
            "target_position_in_world": [x, 0.2, 1.2],
            "stiffness": 50.0,
            "damping": 10.0,
            "weight": 0.5,
        }
    }


@pytest.mark.parametrize("name", BUILTIN_MODELS)
def test_every_objective_on_stays_consistent_and_within_limits(name):
    robot = load_robot_model(name)
    session = Session(
        Hello(model=name, controller="momentum", params={**ALL_ON, **point_params(robot)})
    )
    welcome = session.welcome(0)
    checker = IndependentDynamics(str(BUILTIN_MODELS[name]), welcome)
    limits = np.concatenate([j.torque_limit for j in welcome.joints])
    rng = np.random.default_rng(5)
    angular_used = 0
    for tick in range(60):
        # Large spreads push ball joints past their limits: soft limits engage.
        state = random_state(welcome, rng, spread=0.6 if tick % 3 == 0 else 0.1)
        command = session.step(state.model_copy(update={"seq": tick}))
        assert checker.residual(state, command) < 1e-6
        assert checker.point_force_mismatch < 1e-6
        assert np.all(np.abs(command.joint_torque) <= limits + 1e-9)
        diagnostics = command.diagnostics
        assert set(diagnostics.objective_residuals) >= {"tracking", "point:reach"}
        angular_used += "angular_momentum" in diagnostics.objective_residuals
        assert np.all(np.isfinite(command.joint_acceleration))
    assert angular_used > 0


def test_contact_flags_changing_every_tick_degrade_gracefully():
    session = Session(Hello(model="revolute_humanoid", controller="momentum", params=ALL_ON))
    welcome = session.welcome(0)
    rng = np.random.default_rng(2)
    state = random_state(welcome, rng)
    for tick, flags in enumerate([[True, True], [True, False], [False, False], [False, True]] * 10):
        command = session.step(state.model_copy(update={"seq": tick, "contact_flags": flags}))
        for array in (
            command.joint_acceleration,
            command.joint_torque,
            command.contact_force_in_world,
        ):
            assert np.all(np.isfinite(array))
        forces = command.contact_force_in_world.reshape(2, 4, 3)
        for contact, on in enumerate(flags):
            if not on:
                assert not forces[contact].any()


def test_standing_still_needs_no_correction():
    """Neutral pose at rest: zero accelerations, weight on the feet, COP = CMP under the CM."""
    robot = load_robot_model("thesis_humanoid")
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    support_center = np.mean([data.oMf[c.frame_id].translation for c in robot.contacts], axis=0)
    com = pin.centerOfMass(robot.model, data, q)
    # c_des = s + offset (eq. 5.9) placed at the current CM: nothing to correct.
    controller = MomentumController(robot, {"com_offset_xy": list((com - support_center)[:2])})
    output = controller.compute(ControlInput(0.0, q, np.zeros(robot.model.nv), (True, True)))
    for _ in range(2):  # second tick: COP/CMP from the first tick's forces weigh C_ba
        output = controller.compute(ControlInput(0.0, q, np.zeros(robot.model.nv), (True, True)))
    d = output.diagnostics
    assert np.abs(output.acceleration).max() < 1e-3
    assert output.contact_wrench_in_world[:, 2].sum() == pytest.approx(
        robot.total_mass * 9.81, rel=1e-6
    )
    np.testing.assert_allclose(
        d["center_of_pressure"][:2], d["position_com_in_world"][:2], atol=1e-6
    )
    np.testing.assert_allclose(
        d["centroidal_moment_pivot"][:2], d["position_com_in_world"][:2], atol=1e-6
    )
    # β_ba = β_0 + γ ‖p − g‖ with p = g: only the floor β_0 remains.
    assert d["weighted"]["angular_momentum_weight"] == pytest.approx(
        controller.parameters()["weight_angular_momentum"], abs=1e-4
    )
    np.testing.assert_allclose(d["angular_momentum_rate_desired"], 0.0, atol=1e-12)


def test_angular_momentum_is_damped_toward_zero():
    """Ḣ_des = −k_H H: a body spinning about the CM is driven back to rest (extension of
    eq. 5.15), and the optimizer's achieved Ḣ opposes H."""
    robot = load_robot_model("thesis_humanoid")
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    v = np.zeros(robot.model.nv)
    v[4] = 0.5  # the whole body pitching at 0.5 rad/s about the base's y axis
    controller = MomentumController(
        robot, {"angular_momentum_damping": 8.0, "weight_angular_momentum": 100.0}
    )
    d = controller.compute(ControlInput(0.0, q, v, (False, False))).diagnostics
    momentum = d["angular_momentum"]
    assert abs(momentum[1]) > 1.0
    np.testing.assert_allclose(
        d["angular_momentum_rate_desired"], -8.0 * momentum, rtol=1e-12, atol=1e-12
    )
    # In flight only gravity acts, so Ḣ about the CM is zero whatever the joints do
    # (the optimizer cannot change it); on the ground the feet can.
    d = controller.compute(ControlInput(0.0, q, v, (True, True))).diagnostics
    achieved = d["angular_momentum_rate_achieved"]
    assert achieved[1] * momentum[1] < 0.0, (achieved, momentum)


def test_linear_momentum_objective_pulls_the_cm_toward_c_des():
    robot = load_robot_model("thesis_humanoid")
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    controller = MomentumController(robot, {"com_offset_xy": [0.05, 0.0], "weight_tracking": 0.1})
    output = controller.compute(ControlInput(0.0, q, np.zeros(robot.model.nv), (True, True)))
    d = output.diagnostics
    assert d["linear_momentum_rate_desired"][0] > 0  # toward +x
    assert d["linear_momentum_rate_achieved"][0] > 0
    assert np.isnan(d["linear_momentum_rate_desired"][2])


def test_optimizer_rate_and_rerun_on_support_change():
    robot = load_robot_model("thesis_humanoid")
    controller = MomentumController(robot, {"optimizer_period_ticks": 4})
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    v = np.zeros(robot.model.nv)
    ran = [
        controller.compute(ControlInput(0.001 * k, q, v, (True, True))).diagnostics["weighted"][
            "optimizer_ran"
        ]
        for k in range(9)
    ]
    assert ran == [True, False, False, False, True, False, False, False, True]
    changed = controller.compute(ControlInput(0.01, q, v, (True, False)))
    assert changed.diagnostics["weighted"]["optimizer_ran"]


def test_point_targets_are_added_moved_and_removed_at_run_time():
    robot = load_robot_model("thesis_humanoid")
    session = Session(Hello(model="thesis_humanoid", controller="momentum"))
    welcome = session.welcome(0)
    state = random_state(welcome, np.random.default_rng(0))
    session.set_params(SetParams(params=point_params(robot)))
    assert "point:reach" in session.step(state).diagnostics.objective_residuals
    moved = session.set_params(SetParams(params=point_params(robot, x=0.5)))
    assert moved.params["point:reach"]["target_position_in_world"][0] == 0.5
    session.set_params(SetParams(params={"point:reach": None}))
    assert "point:reach" not in session.step(state).diagnostics.objective_residuals


@pytest.mark.parametrize(
    ("params", "field"),
    [
        (
            {"point:x": {"frame": "no_such_frame", "target_position_in_world": [0, 0, 1]}},
            "params.point:x.frame",
        ),
        ({"point:x": {"frame": "left_sole"}}, "params.point:x.target_position_in_world"),
        (
            {"point:x": {"frame": "left_sole", "target_position_in_world": [0, 1]}},
            "params.point:x.target_position_in_world",
        ),
        (
            {
                "point:x": {
                    "frame": "left_sole",
                    "target_position_in_world": [0, 0, 1],
                    "weight": -1.0,
                }
            },
            "params.point:x.weight",
        ),
        (
            {
                "point:x": {
                    "frame": "left_sole",
                    "target_position_in_world": [0, 0, 1],
                    "colour": 1.0,
                }
            },
            "params.point:x",
        ),
        ({"point:x": 3.0}, "params.point:x"),
        ({"clip": "no_such_clip"}, "params.clip"),
        ({"clip_speed": -1.0}, "params.clip_speed"),
        ({"clip_loop": 1.0}, "params.clip_loop"),
        ({"optimizer_period_ticks": 2.5}, "params.optimizer_period_ticks"),
        ({"ground_force_mode": "guess"}, "params.ground_force_mode"),
        ({"com_offset_xy": [0.0, float("nan")]}, "params.com_offset_xy"),
        ({"joint_weights": [1.0, 2.0]}, "params.joint_weights"),
        ({"angular_momentum_gain": "high"}, "params.angular_momentum_gain"),
    ],
)
def test_invalid_parameters_are_refused_and_nothing_changes(params, field):
    session = Session(Hello(model="thesis_humanoid", controller="momentum"))
    before = session.controller.parameters()
    with pytest.raises(ServerFault) as info:
        session.set_params(SetParams(params={"stiffness": 42.0, **params}))
    assert wire_code(info.value) == ErrorCode.INVALID_PARAMS
    assert info.value.field == field
    assert session.controller.parameters() == before


def test_clip_drives_the_tracking_reference():
    robot = load_robot_model("thesis_humanoid")
    clip = load_motion_clip("stand_sway", robot)
    controller = MomentumController(
        robot,
        {
            "clip": "stand_sway",
            "clip_start_s": 1.0,
            "clip_speed": 2.0,
            "weight_linear_momentum": 0.0,
            "angular_momentum_gain": 0.0,
            "kernel": "python",  # reads the Python tick's rows (the compiled tick's agree)
        },
    )
    time_s = 1.3
    reference = clip.sample(time_s, start_s=1.0, speed=2.0)
    q = reference.q.copy()
    q[:3] = robot.standing_position_base_in_world
    controller.compute(ControlInput(time_s, q, reference.v.copy(), (False, False)))
    tracking = next(o for o in controller._last_optimizer["objectives"] if o.name == "tracking")
    # On the reference itself, eq. 5.3 leaves only the feed-forward acceleration.
    np.testing.assert_allclose(tracking.b[6:], reference.a[6:], atol=1e-9)
    assert np.abs(reference.a[6:]).max() > 0.1


def test_measured_mode_compensates_the_clients_wrenches():
    session = Session(
        Hello(
            model="thesis_humanoid", controller="momentum", params={"ground_force_mode": "measured"}
        )
    )
    welcome = session.welcome(0)
    checker = IndependentDynamics(str(BUILTIN_MODELS["thesis_humanoid"]), welcome)
    rng = np.random.default_rng(9)
    for tick in range(20):
        state = random_state(welcome, rng, wrenches=True)
        command = session.step(state.model_copy(update={"seq": tick}))
        np.testing.assert_array_equal(
            command.contact_wrench_in_world, state.contact_wrench_in_world
        )
        assert not command.contact_force_in_world.any()
        assert checker.residual(state, command) < 1e-6
        force = state.contact_wrench_in_world.reshape(2, 6)[:, :3].sum(axis=0)
        cmp_ = command.diagnostics.centroidal_moment_pivot
        com = command.diagnostics.position_com_in_world
        np.testing.assert_allclose(cmp_[:2], com[:2] - force[:2] / force[2] * com[2], atol=1e-9)
    without = random_state(welcome, rng)
    with pytest.raises(ServerFault) as info:
        session.step(without)
    assert info.value.field == "contact_wrench_in_world"


def test_support_mask_and_friction_coefficients_shape_the_contact_forces():
    """A masked foot gets no force even when touching; forces stay in the set μ's cones."""
    robot = load_robot_model("thesis_humanoid")
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    v = np.zeros(robot.model.nv)
    controller = MomentumController(
        robot, {"support_mask": [0.0, 1.0], "friction_coefficients": [0.05, 0.05]}
    )
    for _ in range(3):
        output = controller.compute(ControlInput(0.0, q, v, (True, True)))
    left, right = np.split(output.contact_force_in_world, 2)
    assert not left.any()
    assert right[:, 2].sum() > 0.5 * robot.total_mass * 9.81
    # Inscribed pyramid of μ = 0.05: |f_t| ≤ μ f_z at every point.
    assert np.all(np.hypot(right[:, 0], right[:, 1]) <= 0.05 * right[:, 2] + 1e-9)
    with pytest.raises(InvalidParams):
        controller.set_params({"support_mask": [1.0, 1.0, 1.0]})


def test_angular_weight_follows_the_measured_cop_cmp_distance():
    """β_ba = β_0 + γ ‖p − g‖ (eq. 5.17) with p and g of the measured wrenches, also when
    inverse dynamics distributes its own forces; without a measured wrench, of the previous
    command's (none on the first tick: β_0 alone).

    The measured wrench is the body's weight, vertical, split over both feet with a pitch
    torque that puts the COP ``d`` ahead of the CM: the CMP of a vertical force is the CM's
    ground projection, so ``‖p − g‖ = d`` exactly, whatever the feet's geometry.
    """
    robot = load_robot_model("thesis_humanoid")
    q = pin.neutral(robot.model)
    q[:3] = robot.standing_position_base_in_world
    v = np.zeros(robot.model.nv)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    com = pin.centerOfMass(robot.model, data, q)
    support_center = np.mean([data.oMf[c.frame_id].translation for c in robot.contacts], axis=0)
    weight_N, d = robot.total_mass * 9.81, 0.04
    # p_x = c_sp,x − τ_y / f_z (eq. 3.3 with f_x = 0) = c_x + d; the feet's forces are
    # equal, so their moments about c_sp cancel and τ is the sum of the feet's torques.
    torque_y = -(com[0] + d - support_center[0]) * weight_N
    wrenches = np.zeros((len(robot.contacts), 6))
    wrenches[:, 2] = weight_N / len(robot.contacts)
    wrenches[:, 4] = torque_y / len(robot.contacts)
    flags = (True,) * len(robot.contacts)
    controller = MomentumController(robot, {"weight_angular_momentum": 2.0})
    assert controller.parameters()["angular_momentum_gain"] == 3000.0  # the default γ

    first = controller.compute(ControlInput(0.0, q, v, flags)).diagnostics["weighted"]
    assert first["angular_momentum_weight"] == 2.0  # nothing measured, nothing commanded yet

    measured = controller.compute(ControlInput(0.0, q, v, flags, wrenches)).diagnostics
    beta = measured["weighted"]["angular_momentum_weight"]
    assert beta == pytest.approx(2.0 + 3000.0 * d, rel=1e-9)

    controller.set_params({"angular_momentum_gain": 500.0, "weight_angular_momentum": 0.0})
    measured = controller.compute(ControlInput(0.0, q, v, flags, wrenches)).diagnostics
    assert measured["weighted"]["angular_momentum_weight"] == pytest.approx(500.0 * d, rel=1e-9)

    # Without a measurement, the previous command's wrench: its COP and CMP (as reported)
    # are millimetres apart at rest, not d.
    unmeasured = controller.compute(ControlInput(0.0, q, v, flags)).diagnostics
    assert unmeasured["weighted"]["angular_momentum_weight"] == pytest.approx(
        500.0
        * np.linalg.norm(
            (measured["center_of_pressure"] - measured["centroidal_moment_pivot"])[:2]
        ),
        rel=1e-6,
        abs=1e-9,
    )
    assert unmeasured["weighted"]["angular_momentum_weight"] < 500.0 * d / 4
