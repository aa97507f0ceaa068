"""The MuJoCo backend against Pinocchio and against closed-form physics.

Pinocchio is the server's dynamics library and never touches MuJoCo here:
agreeing site poses and velocities on random wire states proves the
quaternion order, the free-joint velocity split (linear in world, angular in
base) and the ball-joint velocity frame (child). The physics checks use
cases with known answers: free fall, momentum from a push, static standing.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

mujoco = pytest.importorskip("mujoco")
pin = pytest.importorskip("pinocchio")

from clients.physics.backend import Push  # noqa: E402
from clients.physics.model_file import resolve_model_path  # noqa: E402
from clients.physics.mujoco_backend import (  # noqa: E402
    GRAVITY_M_S2,
    MujocoBackend,
    SimulationDiverged,
    UnsupportedModel,
)
from clients.state import RobotState  # noqa: E402

MODELS = ["thesis_humanoid", "revolute_humanoid", "dino_biped"]
FLOATING_HEIGHT_M = 5.0  # far above the floor: no contact


# -- independent helpers (Pinocchio and the wire conventions, no backend code) ---------


def pinocchio_model(name: str):
    model = pin.buildModelFromMJCF(str(resolve_model_path(name)))
    assert model.joints[1].shortname() == "JointModelFreeFlyer"
    return model, model.createData()


def joint_layout(model) -> list[tuple[str, int, int]]:
    """``(name, nq, nv)`` of the actuated joints in Pinocchio (= wire) order."""
    return [
        (model.names[j], model.joints[j].nq, model.joints[j].nv) for j in range(2, model.njoints)
    ]


def neutral_state(model, height_m: float = FLOATING_HEIGHT_M) -> RobotState:
    position = np.concatenate(
        [[0.0, 0.0, 0.0, 1.0] if nq == 4 else np.zeros(nq) for _, nq, _ in joint_layout(model)]
    )
    return RobotState(
        joint_position=position,
        joint_velocity=np.zeros(model.nv - 6),
        position_base_in_world=np.array([0.0, 0.0, height_m]),
        orientation_base_in_world_xyzw=np.array([0.0, 0.0, 0.0, 1.0]),
        linear_velocity_base_in_world=np.zeros(3),
        angular_velocity_base_in_base=np.zeros(3),
    )


def random_unit_quaternion(rng: np.random.Generator) -> np.ndarray:
    quaternion = rng.normal(size=4)  # either sign of w: the sign must survive
    return quaternion / np.linalg.norm(quaternion)


def random_state(model, rng: np.random.Generator) -> RobotState:
    parts = [
        random_unit_quaternion(rng) if nq == 4 else rng.uniform(-1.0, 1.0, nq)
        for _, nq, _ in joint_layout(model)
    ]
    return RobotState(
        joint_position=np.concatenate(parts),
        joint_velocity=rng.normal(0.0, 1.0, model.nv - 6),
        position_base_in_world=rng.normal(0.0, 0.3, 3) + np.array([0.0, 0.0, 1.0]),
        orientation_base_in_world_xyzw=random_unit_quaternion(rng),
        linear_velocity_base_in_world=rng.normal(0.0, 1.0, 3),
        angular_velocity_base_in_base=rng.normal(0.0, 1.0, 3),
    )


def pinocchio_q_v(state: RobotState) -> tuple[np.ndarray, np.ndarray]:
    """Wire → Pinocchio: ``q = [p, quat_xyzw, joints]``, ``v = [Rᵀ v_world, ω_base, joints]``."""
    rotation = Rotation.from_quat(state.orientation_base_in_world_xyzw).as_matrix()
    q = np.concatenate(
        [state.position_base_in_world, state.orientation_base_in_world_xyzw, state.joint_position]
    )
    v = np.concatenate(
        [
            rotation.T @ state.linear_velocity_base_in_world,
            state.angular_velocity_base_in_base,
            state.joint_velocity,
        ]
    )
    return q, v


def rotation_error(state: RobotState, model) -> np.ndarray:
    """Per wire DoF: hinge angle, or the ball joint's rotation vector (child in parent)."""
    errors, iq = [], 0
    for _, nq, _ in joint_layout(model):
        value = state.joint_position[iq : iq + nq]
        errors.append(Rotation.from_quat(value).as_rotvec() if nq == 4 else value)
        iq += nq
    return np.concatenate(errors)


def standing_state(backend: MujocoBackend, model) -> RobotState:
    """Neutral pose with the lowest sole site exactly on the ground."""
    state = neutral_state(model)
    backend.reset(state)
    sole_z = min(backend.data.site(frame).xpos[2] for frame in backend.contact_frames)
    state.position_base_in_world[2] += backend.ground_height_m - sole_z
    return state


def centroidal_momentum(model, data, state: RobotState) -> np.ndarray:
    """``[linear momentum (world), angular momentum about the CoM (world axes)]``."""
    q, v = pinocchio_q_v(state)
    return pin.computeCentroidalMomentum(model, data, q, v).vector.copy()


def pose_holder(model, data, reference: RobotState, dt: float, feedforward=None):
    """Stiff PD about the neutral pose: ``τ = τ_ff − Kp (q − q₀) − Kd v`` per DoF.

    Ball-joint errors are rotation vectors. Gains are as stiff as explicit
    torques allow at step ``dt``: ``Kp ≤ 0.25 / (Δt² (M⁻¹)ᵢᵢ)`` and
    ``Kd ≤ 0.25 / (Δt (M⁻¹)ᵢᵢ)``, with ``M`` the floating-base inertia.
    """
    q, _ = pinocchio_q_v(reference)
    inverse_inertia = np.diag(np.linalg.inv(pin.crba(model, data, q)))[6:]
    stiffness = np.minimum(2000.0, 0.25 / (dt**2 * inverse_inertia))
    damping = np.minimum(100.0, 0.25 / (dt * inverse_inertia))
    offset = np.zeros(model.nv - 6) if feedforward is None else feedforward

    def torque(state: RobotState) -> np.ndarray:
        error = rotation_error(state, model)
        return offset - stiffness * error - damping * state.joint_velocity

    return torque


# -- conversions ------------------------------------------------------------------------


@pytest.mark.parametrize("name", MODELS)
def test_state_round_trip(name):
    model, _ = pinocchio_model(name)
    backend = MujocoBackend(name)
    assert backend.joint_names == tuple(n for n, _, _ in joint_layout(model))
    rng = np.random.default_rng(1)
    for _ in range(5):
        state = random_state(model, rng)
        backend.reset(state)
        out = backend.state()
        for field in state.__dataclass_fields__:
            np.testing.assert_allclose(
                getattr(out, field), getattr(state, field), rtol=0, atol=1e-9, err_msg=field
            )
        # MuJoCo holds the base quaternion scalar-first.
        x, y, z, w = state.orientation_base_in_world_xyzw
        np.testing.assert_allclose(backend.data.qpos[3:7], [w, x, y, z], atol=1e-12)


def test_base_orientation_quaternion_order():
    backend = MujocoBackend("thesis_humanoid")
    state = neutral_state(pinocchio_model("thesis_humanoid")[0])
    yaw = Rotation.from_euler("z", 90, degrees=True)
    state.orientation_base_in_world_xyzw = yaw.as_quat()  # scalar last
    backend.reset(state)
    np.testing.assert_allclose(
        backend.data.body("pelvis").xmat.reshape(3, 3), yaw.as_matrix(), atol=1e-12
    )


@pytest.mark.parametrize("name", MODELS)
def test_poses_and_velocities_agree_with_pinocchio(name):
    """Every body frame and sole site: pose and 6D velocity, MuJoCo vs Pinocchio.

    MuJoCo's ``mj_objectVelocity(..., flg_local=0)`` gives [ω, v] of the
    object's origin in world axes, Pinocchio's ``LOCAL_WORLD_ALIGNED`` the same.
    """
    model, data = pinocchio_model(name)
    backend = MujocoBackend(name)
    rng = np.random.default_rng(2)
    velocity = np.zeros(6)
    objects = [(site, mujoco.mjtObj.mjOBJ_SITE) for site in backend.contact_frames] + [
        (backend.model.body(b).name, mujoco.mjtObj.mjOBJ_XBODY)
        for b in range(1, backend.model.nbody)
    ]
    for _ in range(5):
        state = random_state(model, rng)
        backend.reset(state)
        q, v = pinocchio_q_v(state)
        pin.forwardKinematics(model, data, q, v)
        pin.updateFramePlacements(model, data)
        for object_name, object_type in objects:
            frame = model.getFrameId(object_name)
            if object_type == mujoco.mjtObj.mjOBJ_SITE:
                element = backend.data.site(object_name)
            else:
                element = backend.data.body(object_name)
            np.testing.assert_allclose(
                element.xpos, data.oMf[frame].translation, atol=1e-9, err_msg=object_name
            )
            np.testing.assert_allclose(
                element.xmat.reshape(3, 3), data.oMf[frame].rotation, atol=1e-9
            )
            object_id = mujoco.mj_name2id(backend.model, object_type, object_name)
            mujoco.mj_objectVelocity(
                backend.model, backend.data, object_type, object_id, velocity, 0
            )
            expected = pin.getFrameVelocity(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
            np.testing.assert_allclose(
                velocity[3:], expected.linear, atol=1e-9, err_msg=object_name
            )
            np.testing.assert_allclose(velocity[:3], expected.angular, atol=1e-9)


# -- actuation --------------------------------------------------------------------------


@pytest.mark.parametrize("name", MODELS)
def test_unit_torque_reaches_exactly_its_dof(name):
    model, _ = pinocchio_model(name)
    backend = MujocoBackend(name)
    backend.model.opt.gravity[:] = 0.0
    # Wire DoF → MuJoCo DoF address, by joint name.
    dofs = np.concatenate(
        [
            backend.model.joint(joint).dofadr[0] + np.arange(nv)
            for joint, _, nv in joint_layout(model)
        ]
    )
    nv = len(dofs)
    for dof in range(nv):
        backend.reset(neutral_state(model))
        backend.step(np.eye(nv)[dof], [])
        actuator_force = backend.data.qfrc_actuator
        np.testing.assert_allclose(actuator_force[dofs], np.eye(nv)[dof], atol=1e-12)
        np.testing.assert_allclose(actuator_force[:6], 0.0, atol=1e-12)


def test_torque_beyond_the_control_range_saturates():
    backend = MujocoBackend("revolute_humanoid")
    model, _ = pinocchio_model("revolute_humanoid")
    backend.reset(neutral_state(model))
    torque = np.zeros(model.nv - 6)
    torque[0] = 1e6  # torso_yaw, ctrlrange ±100, gear 1
    backend.step(torque, [])
    assert backend.data.qfrc_actuator[backend.model.joint("torso_yaw").dofadr[0]] == 100.0


# -- free fall, pushes ------------------------------------------------------------------


@pytest.mark.parametrize("name", MODELS)
def test_free_fall_then_landing(name):
    """Semi-implicit Euler falls exactly as ``z_n = z₀ − g t_n (t_n + Δt) / 2``."""
    model, _ = pinocchio_model(name)
    backend = MujocoBackend(name)
    state = standing_state(backend, model)
    state.position_base_in_world[2] += 0.5
    z0 = state.position_base_in_world[2]
    backend.reset(state)
    assert backend.contact_flags() == [False, False]
    dt = backend.timestep_s
    # First step whose start state has the soles at or below the floor.
    steps = np.arange(1000)
    landing_step = int(np.argmax(GRAVITY_M_S2 * steps * dt * (steps + 1) * dt / 2 >= 0.5))
    while True:
        time_s = backend.time_s
        z = backend.state().position_base_in_world[2]
        report = backend.step(np.zeros(model.nv - 6), [])
        if any(report.contact_flags):
            break  # contacts of the state at time_s
        assert z == pytest.approx(z0 - GRAVITY_M_S2 * time_s * (time_s + dt) / 2, abs=1e-9)
        # First-order integrator: the continuous curve within g t Δt / 2.
        continuous_m = z0 - GRAVITY_M_S2 * time_s**2 / 2
        assert abs(z - continuous_m) <= GRAVITY_M_S2 * time_s * dt / 2 + 1e-9
    assert time_s == pytest.approx(landing_step * dt, abs=1e-12)
    assert report.contact_flags == [True, True]  # symmetric robot, level soles
    assert not report.non_foot_contact
    for _ in range(10):
        report = backend.step(np.zeros(model.nv - 6), [])
    assert report.contact_flags == [True, True]
    assert backend.contact_wrenches_in_world()[:, 2].min() > 0.0


def test_free_fall_converges_to_the_parabola():
    """At Δt = 10 µs the discrete fall is on ``z₀ − g t² / 2`` within 1e-4 m until contact."""
    model, _ = pinocchio_model("revolute_humanoid")
    backend = MujocoBackend("revolute_humanoid", timestep_s=1e-5)
    state = standing_state(backend, model)
    state.position_base_in_world[2] += 0.5
    z0 = state.position_base_in_world[2]
    backend.reset(state)
    zero = np.zeros(model.nv - 6)
    worst_m = 0.0
    while True:
        time_s, z = backend.time_s, backend.data.qpos[2]
        if any(backend.step(zero, []).contact_flags):
            break
        worst_m = max(worst_m, abs(z - (z0 - GRAVITY_M_S2 * time_s**2 / 2)))
    assert worst_m < 1e-4
    assert time_s == pytest.approx(np.sqrt(2 * 0.5 / GRAVITY_M_S2), abs=2e-5)


@pytest.mark.parametrize("name", MODELS)
def test_one_step_push_gives_the_wrench_about_the_com(name):
    """From rest, one step: Δh_G = Δt [F; (p − c) × F] (Newton–Euler about the CoM).

    Up to O(Δt): the momentum is read at the integrated configuration.
    """
    model, data = pinocchio_model(name)
    backend = MujocoBackend(name)
    backend.model.opt.gravity[:] = 0.0
    backend.reset(neutral_state(model))
    force_N = np.array([30.0, -20.0, 50.0])
    point_in_body_m = np.array([0.05, 0.1, -0.02])
    before = backend.state()
    com = pin.centerOfMass(model, data, pinocchio_q_v(before)[0])
    point_in_world = before.position_base_in_world + Rotation.from_quat(
        before.orientation_base_in_world_xyzw
    ).apply(point_in_body_m)
    push = Push(tuple(force_N), "pelvis", tuple(point_in_body_m), start_s=0.0, duration_s=1.0)
    backend.step(np.zeros(model.nv - 6), [push])
    impulse = backend.timestep_s * np.concatenate(
        [force_N, np.cross(point_in_world - com, force_N)]
    )
    np.testing.assert_allclose(
        centroidal_momentum(model, data, backend.state()), impulse, rtol=1e-3, atol=1e-9
    )
    assert not backend.data.xfrc_applied.any()


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize(("start_s", "duration_s"), [(0.01, 0.05), (0.0104, 0.0333)])
def test_push_changes_momentum_by_the_impulse(name, start_s, duration_s):
    """ΔP = F · duration, also when the push starts and ends inside a step.

    The robot holds its pose: limp limbs would swing, and semi-implicit
    Euler's O(Δt) momentum mismatch grows with their centripetal forces.
    """
    model, data = pinocchio_model(name)
    backend = MujocoBackend(name)
    backend.model.opt.gravity[:] = 0.0
    backend.reset(neutral_state(model))
    force_N = np.array([30.0, -20.0, 50.0])
    push = Push(tuple(force_N), "pelvis", (0.05, 0.1, -0.02), start_s, duration_s)
    hold = pose_holder(model, data, backend.state(), backend.timestep_s)
    for _ in range(100):
        backend.step(hold(backend.state()), [push])
    linear = centroidal_momentum(model, data, backend.state())[:3]
    np.testing.assert_allclose(linear, force_N * duration_s, rtol=1e-3)


def test_push_on_an_unknown_body_names_the_bodies():
    backend = MujocoBackend("revolute_humanoid")
    with pytest.raises(KeyError, match="pelvis"):
        backend.step(np.zeros(22), [Push((1.0, 0.0, 0.0), "tail")])


# -- standing on the ground ---------------------------------------------------------------


def static_feedforward(model, data, state: RobotState, frames: tuple[str, ...]) -> np.ndarray:
    """Joint torques of a static equilibrium with min-norm foot wrenches (Pinocchio)."""
    q, _ = pinocchio_q_v(state)
    gravity = pin.computeGeneralizedGravity(model, data, q)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    jacobian = np.vstack(
        [
            pin.getFrameJacobian(model, data, model.getFrameId(f), pin.LOCAL_WORLD_ALIGNED)
            for f in frames
        ]
    )
    wrenches = np.linalg.lstsq(jacobian[:, :6].T, gravity[:6], rcond=None)[0]
    return gravity[6:] - jacobian[:, 6:].T @ wrenches


@pytest.mark.parametrize("name", MODELS)
def test_standing_under_stiff_pd(name):
    """Stiff PD about the neutral pose plus a static feed-forward: the robot stands still."""
    model, data = pinocchio_model(name)
    backend = MujocoBackend(name, friction_coefficient=0.6)
    start = standing_state(backend, model)
    backend.reset(start)
    dt = backend.timestep_s
    feedforward = static_feedforward(model, data, start, backend.contact_frames)
    hold = pose_holder(model, data, start, dt, feedforward)

    for _ in range(2000):
        backend.step(hold(backend.state()), [])
    end = backend.state()
    assert np.linalg.norm(end.position_base_in_world - start.position_base_in_world) < 0.01
    assert backend.contact_flags() == [True, True]
    assert backend.contact_names == ("left_foot", "right_foot")

    wrenches = backend.contact_wrenches_in_world()
    weight_N = GRAVITY_M_S2 * pin.computeTotalMass(model)
    assert wrenches[:, 2].sum() == pytest.approx(weight_N, rel=0.02)

    # Newton–Euler over steps under a push: the measured wrenches (force, and
    # torque about the sole origin, world), gravity and the push change the
    # centroidal momentum. This pins down the force sign, the rotation to
    # world and the torque's reference point.
    force_N = np.array([60.0, -40.0, 0.0])
    point_in_body_m = np.array([0.0, 0.0, 0.05])
    push = Push(tuple(force_N), "pelvis", tuple(point_in_body_m), backend.time_s, 0.02)
    tangential_N = 0.0
    for _ in range(20):
        before = backend.state()
        backend.step(hold(before), [push])
        wrenches = backend.contact_wrenches_in_world()
        tangential_N = max(tangential_N, np.abs(wrenches[:, :2]).max())
        q, _ = pinocchio_q_v(before)
        pin.framesForwardKinematics(model, data, q)
        com = pin.centerOfMass(model, data, q)
        momentum_rate = (
            centroidal_momentum(model, data, backend.state())
            - centroidal_momentum(model, data, before)
        ) / dt
        push_point = before.position_base_in_world + Rotation.from_quat(
            before.orientation_base_in_world_xyzw
        ).apply(point_in_body_m)
        total_force = wrenches[:, :3].sum(axis=0) + force_N - [0.0, 0.0, weight_N]
        moment_about_com = np.cross(push_point - com, force_N) + sum(
            np.cross(data.oMf[model.getFrameId(frame)].translation - com, wrench[:3]) + wrench[3:]
            for frame, wrench in zip(backend.contact_frames, wrenches, strict=True)
        )
        np.testing.assert_allclose(total_force, momentum_rate[:3], atol=1e-3 * weight_N)
        np.testing.assert_allclose(moment_about_com, momentum_rate[3:], atol=1e-4 * weight_N)
    assert tangential_N > 1.0  # friction acts: the contact frame's tangents are exercised
    # Every ground contact uses exactly the requested friction coefficient.
    active = backend.data.contact.efc_address >= 0
    np.testing.assert_allclose(backend.data.contact.friction[active, 0], 0.6)


def test_ground_height_moves_the_floor():
    model, _ = pinocchio_model("thesis_humanoid")
    backend = MujocoBackend("thesis_humanoid", ground_height_m=0.25)
    state = standing_state(backend, model)
    state.position_base_in_world[2] -= 1e-3
    backend.reset(state)
    assert backend.contact_flags() == [True, True]
    np.testing.assert_allclose(backend.data.contact.pos[:, 2], 0.25 - 5e-4, atol=1e-9)


def test_the_contact_time_constant_sets_how_far_a_standing_robot_sinks():
    """MuJoCo's soft contact is a spring of time constant ``solref[0]``: its static
    penetration shrinks with the square of the constant (measured 1.04 mm at MuJoCo's 0.02 s
    for the thesis humanoid, 0.13 mm at 0.005 s; solimp's impedance keeps the ratio under 16)."""
    model, data = pinocchio_model("thesis_humanoid")
    depth_m = {}
    for constant in (None, 0.005):
        backend = MujocoBackend("thesis_humanoid", contact_time_constant_s=constant)
        start = standing_state(backend, model)
        backend.reset(start)
        feedforward = static_feedforward(model, data, start, backend.contact_frames)
        hold = pose_holder(model, data, start, backend.timestep_s, feedforward)
        for _ in range(1000):
            backend.step(hold(backend.state()), [])
        contacts = backend.data.contact[: backend.data.ncon]
        assert backend.contact_flags() == [True, True]
        if constant is not None:
            np.testing.assert_allclose(contacts.solref, [[constant, 1.0]] * backend.data.ncon)
        depth_m[constant] = -float(np.mean(contacts.dist))
    assert 0.0 < depth_m[0.005] < depth_m[None] / 4.0, depth_m


@pytest.mark.parametrize(
    "keyword",
    [
        {"friction_coefficient": 0.0},
        {"timestep_s": -1.0},
        {"ground_height_m": np.nan},
        {"contact_time_constant_s": 0.0015},  # under two steps of 1 ms
    ],
)
def test_rejects_bad_settings(keyword):
    with pytest.raises(ValueError, match=next(iter(keyword))):
        MujocoBackend("thesis_humanoid", **keyword)


def test_joint_names_set_the_wire_order():
    model, _ = pinocchio_model("revolute_humanoid")
    names = [name for name, _, _ in joint_layout(model)]
    default = MujocoBackend("revolute_humanoid")
    reversed_order = MujocoBackend("revolute_humanoid", joint_names=names[::-1])
    state = random_state(model, np.random.default_rng(3))  # hinges only: 1 value per joint
    default.reset(state)
    state.joint_position = state.joint_position[::-1].copy()
    state.joint_velocity = state.joint_velocity[::-1].copy()
    reversed_order.reset(state)
    np.testing.assert_array_equal(default.data.qpos, reversed_order.data.qpos)
    np.testing.assert_array_equal(default.data.qvel, reversed_order.data.qvel)
    torque = np.arange(len(names), dtype=float)
    default.step(torque, [])
    reversed_order.step(torque[::-1].copy(), [])
    np.testing.assert_array_equal(default.data.qfrc_actuator, reversed_order.data.qfrc_actuator)


def test_a_dof_without_a_motor_is_refused(tmp_path):
    text = resolve_model_path("revolute_humanoid").read_text()
    line = next(line for line in text.splitlines() if '<motor name="neck_yaw"' in line)
    path = tmp_path / "no_neck_motor.xml"
    path.write_text(text.replace(line, ""))
    with pytest.raises(UnsupportedModel, match="neck_yaw"):
        MujocoBackend(str(path))


def test_divergence_raises_instead_of_teleporting(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # where MuJoCo would write MUJOCO_LOG.TXT
    model, _ = pinocchio_model("revolute_humanoid")
    backend = MujocoBackend("revolute_humanoid")
    state = neutral_state(model)
    state.joint_velocity[:] = 1e12  # beyond MuJoCo's sanity bound
    backend.reset(state)
    with pytest.raises(SimulationDiverged):
        backend.step(np.zeros(model.nv - 6), [])
    with pytest.raises(ValueError, match="finite"):
        backend.step(np.full(model.nv - 6, np.nan), [])
    assert list(tmp_path.iterdir()) == [], "MuJoCo's warning went to a log file in the cwd"


def test_position_servos_become_torque_motors_that_keep_their_force_limits():
    """A vendor's ``<position>`` servos (issue 18): the torque sent is the torque applied."""
    from pathlib import Path

    scene = Path(__file__).resolve().parents[1] / "models" / "vendor_humanoid" / "scene.xml"
    backend = MujocoBackend(str(scene), keyframe="home")
    model, data = backend.model, backend.data
    assert (model.actuator_gaintype == int(mujoco.mjtGain.mjGAIN_FIXED)).all()
    assert (model.actuator_biastype == int(mujoco.mjtBias.mjBIAS_NONE)).all()
    np.testing.assert_array_equal(model.actuator_gainprm[:, 0], 1.0)
    assert not model.actuator_ctrllimited.any()
    q = backend.description.standing_configuration
    backend.reset(
        RobotState(q[7:].copy(), np.zeros(model.nv - 6), q[:3], q[3:7], np.zeros(3), np.zeros(3))
    )
    names = list(backend.joint_names)
    torque = np.zeros(len(names))
    torque[names.index("left_knee")] = 5.0
    torque[names.index("neck_yaw")] = 50.0  # beyond its 20 N·m forcerange
    torque[names.index("torso_yaw")] = -95.0  # beyond the joint's 90 N·m actuatorfrcrange
    backend.step(torque, [])
    applied = {name: data.qfrc_actuator[model.joint(name).dofadr[0]] for name in names}
    assert applied["left_knee"] == pytest.approx(5.0)
    assert applied["neck_yaw"] == pytest.approx(20.0)
    assert applied["torso_yaw"] == pytest.approx(-90.0)
    assert applied["right_knee"] == pytest.approx(0.0)
