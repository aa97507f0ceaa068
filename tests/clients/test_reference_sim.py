"""The reference simulator (Pinocchio ABA, penalty contact, semi-implicit Euler) against physics.

Every check compares the simulator with something it does not compute
itself: closed-form free fall, the robot's weight, Coulomb's law, momentum
and energy conservation, impulse = force × time, a separately built
Pinocchio model, and MuJoCo's own reading of the MJCF geometry.
"""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from clients.physics.backend import Push
from clients.physics.model_file import builtin_model_path, describe_model
from clients.physics.reference import BodyNotFound, ReferenceBackend, SimulationDiverged
from clients.state import RobotState

GRAVITY_M_PER_S2 = 9.81
BUILTIN_MODELS = ["thesis_humanoid", "revolute_humanoid", "dino_biped"]

BOX_STANCE_MJCF = """
<mujoco model="box_stance">
  <compiler angle="radian"/>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="pelvis" pos="0 0 0.1">
      <freejoint name="root"/>
      <inertial pos="0 0 0" mass="20" diaginertia="0.3 0.3 0.3"/>
      <geom name="pelvis_box" type="box" size="0.15 0.2 0.05"/>
      <body name="left_foot" pos="0 0.1 -0.1">
        <inertial pos="0 0 0.02" mass="0.5" diaginertia="0.001 0.001 0.001"/>
        <geom name="left_foot_box" type="box" size="0.1 0.05 0.02" pos="0 0 0.02"/>
        <site name="left_sole" type="box" size="0.1 0.05 0.001"/>
      </body>
      <body name="right_foot" pos="0 -0.1 -0.1">
        <inertial pos="0 0 0.02" mass="0.5" diaginertia="0.001 0.001 0.001"/>
        <geom name="right_foot_box" type="box" size="0.1 0.05 0.02" pos="0 0 0.02"/>
        <site name="right_sole" type="box" size="0.1 0.05 0.001"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

# Free-floating 3-link chain (a hinge and a ball joint), no gravity, no feet.
CHAIN_MJCF = """
<mujoco model="chain">
  <compiler angle="radian"/>
  <option gravity="0 0 0"/>
  <worldbody>
    <body name="pelvis" pos="0 0 1">
      <freejoint name="root"/>
      <inertial pos="0.1 0 0" mass="2" diaginertia="0.01 0.02 0.02"/>
      <geom name="link0_box" type="box" size="0.1 0.03 0.03" pos="0.1 0 0"/>
      <body name="link1" pos="0.2 0 0">
        <joint name="hinge" type="hinge" axis="0 0 1"/>
        <inertial pos="0.15 0 0" mass="1.5" diaginertia="0.005 0.015 0.015"/>
        <geom name="link1_box" type="box" size="0.15 0.03 0.03" pos="0.15 0 0"/>
        <body name="link2" pos="0.3 0 0">
          <joint name="ball" type="ball"/>
          <inertial pos="0.1 0 0" mass="1" diaginertia="0.002 0.006 0.006"/>
          <geom name="link2_box" type="box" size="0.1 0.03 0.03" pos="0.1 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

# Box geoms turned every way MJCF allows, for the corner parser.
ORIENTED_BOXES_MJCF = """
<mujoco model="oriented">
  <compiler angle="degree" eulerseq="zyx"/>
  <worldbody>
    <body name="pelvis" pos="0.1 -0.2 0.7" euler="10 20 30">
      <freejoint name="root"/>
      <geom name="a" type="box" size="0.1 0.2 0.3" pos="0.01 0.02 0.03" quat="0.9 0.1 -0.3 0.2"/>
      <geom name="b" type="box" size="0.05 0.1 0.15" euler="30 -45 60"/>
      <body name="arm" pos="0.2 0 0.1" quat="0.8 0 0.6 0">
        <joint name="elbow" type="hinge" axis="0 1 0"/>
        <geom name="c" type="box" size="0.1 0.02 0.03" pos="0.1 0 0" axisangle="1 1 0 40"/>
        <geom name="d" type="box" size="0.1 0.02 0.03" xyaxes="0 1 0 -1 0.2 0.5"/>
        <geom name="e" type="box" size="0.1 0.02 0.03" pos="0 0 -0.1" zaxis="0.3 -0.4 1"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def write_model(tmp_path: Path, text: str, name: str) -> str:
    path = tmp_path / f"{name}.xml"
    path.write_text(text)
    return str(path)


def zero_torque(backend: ReferenceBackend) -> np.ndarray:
    return np.zeros(backend.pinocchio_model.nv - 6)


def locking_gains(backend: ReferenceBackend) -> tuple[np.ndarray, np.ndarray]:
    """Per-DoF PD gains that hold the joints and stay stable at 1 kHz.

    A per-DoF PD integrated explicitly is stable only while ``Kp Δt²`` and
    ``Kd Δt`` are small against the DoF's effective inertia ``1/(M⁻¹)ᵢᵢ``
    (all other joints free), which is 8·10⁻⁴ kg·m² for the thesis
    humanoid's ankle roll; so the gains are capped per DoF.
    """
    model = backend.pinocchio_model
    data = model.createData()
    mass_matrix = pin.crba(model, data, backend.configuration)
    mass_matrix = np.triu(mass_matrix) + np.triu(mass_matrix, 1).T
    effective_inertia = 1.0 / np.diag(np.linalg.inv(mass_matrix))[6:]
    step_s = backend.timestep_s
    stiffness = np.minimum(1e4, 0.5 * effective_inertia / step_s**2)
    damping = np.minimum(
        2.0 * np.sqrt(stiffness * effective_inertia), 0.3 * effective_inertia / step_s
    )
    return stiffness, damping


def locking_torque(
    backend: ReferenceBackend, q_lock: np.ndarray, stiffness: np.ndarray, damping: np.ndarray
) -> np.ndarray:
    """τ = −Kp (q ⊖ q_lock) − Kd v per DoF; ball joints by their rotation-vector difference."""
    model = backend.pinocchio_model
    error = pin.difference(model, q_lock, backend.configuration)[6:]
    return -stiffness * error - damping * backend.velocity[6:]


def momentum_rate(backend: ReferenceBackend, torque: np.ndarray, pushes: list[Push]) -> pin.Force:
    """Steps once; returns Pinocchio's centroidal momentum rate for the step's acceleration."""
    model = backend.pinocchio_model
    q, v = backend.configuration, backend.velocity
    backend.step(torque, pushes)
    acceleration = (backend.velocity - v) / backend.timestep_s
    return pin.computeCentroidalMomentumTimeVariation(model, model.createData(), q, v, acceleration)


def linear_momentum(backend: ReferenceBackend) -> np.ndarray:
    model = backend.pinocchio_model
    return pin.computeCentroidalMomentum(
        model, model.createData(), backend.configuration, backend.velocity
    ).linear.copy()


# ------------------------------------------------------------------ free fall


def test_free_fall_follows_the_parabola_until_the_first_contact():
    backend = ReferenceBackend("thesis_humanoid")
    drop_m = 0.5
    start = backend.standing_state()
    start.position_base_in_world = start.position_base_in_world + np.array([0.0, 0.0, drop_m])
    backend.reset(start)
    assert backend.contact_point_positions_in_world()[:, 2].min() == pytest.approx(drop_m)
    z0_m, step_s = start.position_base_in_world[2], backend.timestep_s
    steps = 0
    while backend.contact_point_positions_in_world()[:, 2].min() >= 0.0:
        assert backend.contact_flags() == [False, False]
        backend.step(zero_torque(backend), [])
        steps += 1
        time_s = steps * step_s
        assert backend.time_s == pytest.approx(time_s)
        z_m = backend.state().position_base_in_world[2]
        # Semi-implicit Euler: v_n = −g n Δt, z_n = z0 − g Δt² n (n + 1) / 2 exactly,
        # which is the parabola z0 − g t²/2 lagging by its O(Δt) term g t Δt / 2.
        assert z_m == pytest.approx(
            z0_m - GRAVITY_M_PER_S2 * step_s**2 * steps * (steps + 1) / 2, abs=1e-9
        )
        parabola_m = z0_m - GRAVITY_M_PER_S2 * time_s**2 / 2
        assert abs(z_m - parabola_m) <= GRAVITY_M_PER_S2 * time_s * step_s / 2 + 1e-9
        assert np.abs(backend.contact_wrenches_in_world()).max() == 0.0
        assert steps < 1000
    # The soles first dip below the ground within one step of the analytic time...
    assert abs(steps * step_s - np.sqrt(2 * drop_m / GRAVITY_M_PER_S2)) <= step_s
    # ...having fallen with the passive joints still: uniform gravity has no internal forces.
    state = backend.state()
    np.testing.assert_allclose(state.joint_position, start.joint_position, atol=1e-9)
    np.testing.assert_allclose(state.joint_velocity, 0.0, atol=1e-9)
    np.testing.assert_allclose(state.orientation_base_in_world_xyzw, [0, 0, 0, 1], atol=1e-12)
    # The next step is the first with ground forces, and the flags report it.
    report = backend.step(zero_torque(backend), [])
    assert report.contact_flags == [True, True] == backend.contact_flags()
    assert backend.contact_wrenches_in_world()[:, 2].min() > 0.0


# -------------------------------------------------------------------- contact


def test_robot_with_locked_joints_stands_on_its_penalty_contacts():
    backend = ReferenceBackend("thesis_humanoid")
    backend.reset(backend.standing_state())
    q_lock = backend.configuration
    stiffness, damping = locking_gains(backend)
    for _ in range(1999):
        report = backend.step(locking_torque(backend, q_lock, stiffness, damping), [])
    q_before = backend.configuration
    points_before = backend.contact_point_positions_in_world()
    report = backend.step(locking_torque(backend, q_lock, stiffness, damping), [])
    assert backend.time_s == pytest.approx(2.0)

    assert np.linalg.norm(backend.configuration[:3] - q_lock[:3]) < 0.01
    forces = backend.contact_point_forces_in_world()
    weight_N = backend.total_mass_kg * GRAVITY_M_PER_S2
    assert forces[:, 2].sum() == pytest.approx(weight_N, rel=0.01)
    assert report.contact_flags == [True, True]
    assert backend.contact_flags() == [True, True]
    assert not report.non_foot_contact
    # Unilateral and inside the friction cone.
    assert (forces[:, 2] >= 0).all()
    tangential = np.linalg.norm(forces[:, :2], axis=1)
    assert (tangential <= backend.friction_coefficient * forces[:, 2] + 1e-9).all()

    # Points and site origins from a separately built Pinocchio model.
    model = pin.buildModelFromMJCF(str(builtin_model_path("thesis_humanoid")))
    data = model.createData()
    pin.framesForwardKinematics(model, data, q_before)
    wrenches = backend.contact_wrenches_in_world()
    assert wrenches.shape == (2, 6)
    for index, contact in enumerate(backend.contact_names):
        rows = [i for i, p in enumerate(backend.contact_points) if p.contact == contact]
        site = data.oMf[model.getFrameId(backend.contact_points[rows[0]].frame)]
        expected_points = [
            site.act(np.array(backend.contact_points[i].point_in_frame)) for i in rows
        ]
        np.testing.assert_allclose(points_before[rows], expected_points, atol=1e-12)
        np.testing.assert_allclose(wrenches[index, :3], forces[rows].sum(axis=0), atol=1e-9)
        moment = np.cross(points_before[rows] - site.translation, forces[rows]).sum(axis=0)
        np.testing.assert_allclose(wrenches[index, 3:], moment, atol=1e-9)
    np.testing.assert_allclose(wrenches[:, 2].sum(), forces[:, 2].sum())


@pytest.mark.parametrize("model", BUILTIN_MODELS)
def test_neutral_pose_puts_the_soles_on_the_ground(model):
    backend = ReferenceBackend(model)
    backend.reset(backend.standing_state())
    np.testing.assert_allclose(backend.contact_point_positions_in_world()[:, 2], 0.0, atol=1e-9)
    assert not backend.non_foot_contact()
    assert backend.contact_names == ["left_foot", "right_foot"]


def test_a_body_below_the_ground_is_a_non_foot_contact():
    backend = ReferenceBackend("thesis_humanoid")
    sunk = backend.standing_state()
    sunk.position_base_in_world = sunk.position_base_in_world - np.array([0.0, 0.0, 0.6])
    backend.reset(sunk)
    assert backend.non_foot_contact()
    assert backend.step(zero_torque(backend), []).non_foot_contact
    backend.reset(backend.standing_state())
    assert not backend.step(zero_torque(backend), []).non_foot_contact


# ------------------------------------------------------------------- friction


def push_box_stance(
    path: str, friction_coefficient: float
) -> tuple[float, ReferenceBackend, float]:
    """Settle 0.3 s, push 40 N sideways for 0.3 s, coast 0.2 s.

    Returns the largest horizontal point displacement from before the push,
    the backend, and Σ|f_t| / (μ Σ f_n) in the middle of the push.
    """
    backend = ReferenceBackend(path, friction_coefficient=friction_coefficient)
    backend.reset(backend.standing_state())
    for _ in range(300):
        backend.step(zero_torque(backend), [])
    settled = backend.contact_point_positions_in_world()
    push = Push((40.0, 0.0, 0.0), "pelvis", (0.0, 0.0, 0.0), start_s=0.3005, duration_s=0.3)
    slip_m, cone_ratio = 0.0, np.nan
    for step in range(500):
        backend.step(zero_torque(backend), [push])
        moved = backend.contact_point_positions_in_world()[:, :2] - settled[:, :2]
        slip_m = max(slip_m, float(np.linalg.norm(moved, axis=1).max()))
        if step == 150:
            forces = backend.contact_point_forces_in_world()
            tangential = np.linalg.norm(forces[:, :2], axis=1).sum()
            cone_ratio = tangential / (friction_coefficient * forces[:, 2].sum())
    return slip_m, backend, cone_ratio


def test_high_friction_sticks_and_low_friction_slides(tmp_path):
    path = write_model(tmp_path, BOX_STANCE_MJCF, "box_stance")
    # 40 N against 21 kg: μ m g is 165 N at μ = 0.8 but only 6.2 N at μ = 0.03.
    slip_m, _, _ = push_box_stance(path, friction_coefficient=0.8)
    assert slip_m < 1e-3
    slip_m, backend, cone_ratio = push_box_stance(path, friction_coefficient=0.03)
    assert slip_m > 0.05
    assert cone_ratio == pytest.approx(1.0, rel=1e-9)  # sliding: |f_t| = μ f_n at every point
    assert all(backend.contact_flags())


# ------------------------------------------------------ energy and momentum


def swing_chain(path: str, timestep_s: float) -> tuple[float, float, float]:
    """2 s of the free chain; returns max relative energy drift, momentum drift, rate residual."""
    backend = ReferenceBackend(path, timestep_s=timestep_s, ground_height_m=-100.0)
    start = backend.standing_state()
    start.joint_velocity = np.array([1.0, 0.5, -1.0, 1.0])
    backend.reset(start)
    model = backend.pinocchio_model
    data = model.createData()
    energy0_J = pin.computeKineticEnergy(model, data, backend.configuration, backend.velocity)
    momentum0 = linear_momentum(backend)
    energy_drift = momentum_drift = rate_residual = 0.0
    for _ in range(round(2.0 / timestep_s)):
        rate = momentum_rate(backend, np.zeros(4), [])
        rate_residual = max(rate_residual, np.abs(rate.vector).max())
        energy_J = pin.computeKineticEnergy(model, data, backend.configuration, backend.velocity)
        energy_drift = max(energy_drift, abs(energy_J - energy0_J) / energy0_J)
        momentum_drift = max(
            momentum_drift,
            np.linalg.norm(linear_momentum(backend) - momentum0) / np.linalg.norm(momentum0),
        )
    return energy_drift, momentum_drift, rate_residual


@pytest.mark.parametrize("pitch_rad", [-0.05, 0.05])
def test_a_sliding_edge_that_sinks_is_pushed_back(pitch_rad):
    """Feet on one edge, sliding back and sinking: the ground pushes (every edge, every way).

    The toe edge (pitch +0.05) once got no force at all: the coupled implicit solve asked for
    more stick than friction allows, which pulled every normal below zero, so every point
    was released and the feet sank through the floor.
    """
    backend = ReferenceBackend("revolute_humanoid")
    standing = backend.state()
    turned = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, pitch_rad, 0.0)).coeffs()
    at_rest = RobotState(
        standing.joint_position,
        standing.joint_velocity,
        standing.position_base_in_world,
        turned,
        np.zeros(3),
        np.zeros(3),
    )
    backend.reset(at_rest)
    lowest_m = backend.contact_point_positions_in_world()[:, 2].min()
    sinking = RobotState(
        standing.joint_position,
        standing.joint_velocity,
        standing.position_base_in_world - [0.0, 0.0, lowest_m + 0.003],  # edge 3 mm deep
        turned,
        np.array([-0.3, 0.0, -0.05]),
        np.zeros(3),
    )
    backend.reset(sinking)
    assert (backend.contact_point_positions_in_world()[:, 2] < 0).sum() == 4  # one edge a foot
    backend.step(np.zeros(len(standing.joint_velocity)), [])
    forces = backend.contact_point_forces_in_world()
    touching = backend.contact_point_positions_in_world()[:, 2] < 0
    assert (forces[touching, 2] > 0).all(), forces[touching]
    tangential = np.linalg.norm(forces[:, :2], axis=1)
    assert (tangential <= backend.friction_coefficient * forces[:, 2] + 1e-9).all()
    assert forces[touching, 0].min() > 0  # friction opposes the backward slide


def test_a_foot_twisting_on_the_ground_slides_with_coulomb_friction_and_does_not_sink():
    """A robot spinning on its soles (a twisting jump's thrust): friction within its cone
    brakes the spin, the ground holds the weight without hopping, and no sole sinks.

    The forces were once clamped to the cone after a stick solve; the normals that solve
    implied for the impossible stick forces pulled: here the weight carried swung between
    0.25 and 2.4 m g, and in a twisting jump the soles sank 2.5 cm with no force.
    """
    backend = ReferenceBackend("thesis_humanoid")
    model = backend.pinocchio_model
    data = model.createData()
    standing = backend.state()
    stiffness, damping = locking_gains(backend)
    q_lock = backend.configuration.copy()
    backend.reset(
        RobotState(
            standing.joint_position,
            standing.joint_velocity,
            standing.position_base_in_world,
            standing.orientation_base_in_world_xyzw,
            np.zeros(3),
            np.array([0.0, 0.0, 8.0]),  # yaw, rad/s
        )
    )
    weight_N = backend.total_mass_kg * 9.81
    lowest_m = 0.0
    for step in range(60):
        backend.step(locking_torque(backend, q_lock, stiffness, damping), [])
        forces = backend.contact_point_forces_in_world()
        positions = backend.contact_point_positions_in_world()
        lowest_m = min(lowest_m, positions[:, 2].min())
        tangential = np.linalg.norm(forces[:, :2], axis=1)
        assert (tangential <= backend.friction_coefficient * forces[:, 2] * (1 + 1e-9)).all()
        # Friction's moment about the CM's vertical opposes the spin.
        arms = positions[:, :2] - pin.centerOfMass(model, data, backend.configuration)[:2]
        assert np.sum(arms[:, 0] * forces[:, 1] - arms[:, 1] * forces[:, 0]) < 0.0
        if step >= 5:  # no hopping: the clamped stick solve's normals swung 160–1500 N
            assert 0.5 * weight_N < forces[:, 2].sum() < 1.6 * weight_N
    assert lowest_m > -0.003  # standing sinks 0.4 mm
    assert backend.state().angular_velocity_base_in_base[2] < 8.0  # friction slows the spin


def test_free_chain_conserves_energy_and_momentum_to_first_order(tmp_path):
    path = write_model(tmp_path, CHAIN_MJCF, "chain")
    energy_drift, momentum_drift, rate_residual = swing_chain(path, 1e-3)
    # Each step conserves momentum exactly (rate from Pinocchio's centroidal dynamics)...
    assert rate_residual < 1e-9
    # ...and over 2 s semi-implicit Euler drifts by O(Δt): measured 0.25 % energy and
    # 0.23 % momentum at 1 kHz, both halving with the step.
    assert energy_drift < 0.01
    assert momentum_drift < 0.01
    energy_drift_half, momentum_drift_half, _ = swing_chain(path, 5e-4)
    assert energy_drift / energy_drift_half == pytest.approx(2.0, rel=0.2)
    assert momentum_drift / momentum_drift_half == pytest.approx(2.0, rel=0.2)


@pytest.mark.parametrize(
    ("body", "point_in_body_m"),
    [("pelvis", (0.05, 0.0, 0.02)), ("left_forearm", (0.0, 0.03, -0.3))],
)
def test_push_changes_momentum_by_its_impulse(body, point_in_body_m):
    backend = ReferenceBackend(
        "thesis_humanoid", gravity_in_world_m_per_s2=(0.0, 0.0, 0.0), ground_height_m=-100.0
    )
    model = backend.pinocchio_model
    data = model.createData()
    force_N = np.array([30.0, -20.0, 10.0])
    push = Push(tuple(force_N), body, point_in_body_m, start_s=0.0105, duration_s=0.1)
    step_s = backend.timestep_s
    momentum0 = linear_momentum(backend)
    for step in range(200):
        q = backend.configuration
        rate = momentum_rate(backend, zero_torque(backend), [push])
        # Mid-step ends: the first and last steps see half the force.
        overlap_s = min((step + 1) * step_s, 0.1105) - max(step * step_s, 0.0105)
        expected = force_N * max(overlap_s, 0.0) / step_s
        pin.framesForwardKinematics(model, data, q)
        frame = model.getFrameId(body, pin.FrameType.BODY)
        point_m = data.oMf[frame].act(np.array(point_in_body_m))
        com_m = pin.centerOfMass(model, data, q)
        # Each step: L̇ = F and Ḣ_com = (p − c) × F, to rounding.
        np.testing.assert_allclose(rate.linear, expected, atol=1e-9 * np.linalg.norm(force_N))
        np.testing.assert_allclose(
            rate.angular, np.cross(point_m - com_m, expected), atol=1e-9 * np.linalg.norm(force_N)
        )
    impulse = linear_momentum(backend) - momentum0
    expected_impulse = force_N * 0.1
    # Over the whole push the O(Δt) drift of semi-implicit Euler shows: 0.25 % on the pelvis,
    # 10 % on the forearm, which the free elbow spins at 35 rad/s.
    tolerance = 0.01 if body == "pelvis" else 0.15
    assert np.linalg.norm(impulse - expected_impulse) < tolerance * np.linalg.norm(expected_impulse)


# ------------------------------------------------------------ wire conventions


def random_sim_state(backend: ReferenceBackend, rng: np.random.Generator) -> RobotState:
    model = backend.pinocchio_model
    parts = []
    for joint in model.joints[2:]:
        if joint.nq == 4:
            parts.append(Rotation.from_rotvec(rng.normal(0, 0.5, 3)).as_quat())
        else:
            parts.append(rng.uniform(-1, 1, joint.nq))
    return RobotState(
        joint_position=np.concatenate(parts),
        joint_velocity=rng.normal(0, 1, model.nv - 6),
        position_base_in_world=rng.normal(0, 1, 3),
        orientation_base_in_world_xyzw=Rotation.random(random_state=rng).as_quat(),
        linear_velocity_base_in_world=rng.normal(0, 1, 3),
        angular_velocity_base_in_base=rng.normal(0, 1, 3),
    )


@pytest.mark.parametrize("model", BUILTIN_MODELS)
def test_reset_then_state_round_trips(model):
    backend = ReferenceBackend(model)
    rng = np.random.default_rng(7)
    for _ in range(5):
        state = random_sim_state(backend, rng)
        backend.reset(state)
        assert backend.time_s == 0.0
        back = backend.state()
        for key in vars(state):
            np.testing.assert_allclose(getattr(back, key), getattr(state, key), atol=1e-12)


def test_wire_frames_are_scalar_last_and_world_linear_velocity():
    backend = ReferenceBackend("thesis_humanoid")
    state = backend.standing_state()
    yaw = Rotation.from_euler("z", 90, degrees=True)
    state.orientation_base_in_world_xyzw = yaw.as_quat()  # [0, 0, sin 45°, cos 45°]
    state.linear_velocity_base_in_world = np.array([1.0, 0.0, 0.0])
    state.angular_velocity_base_in_base = np.array([0.0, 0.0, 0.3])
    backend.reset(state)
    q, v = backend.configuration, backend.velocity
    np.testing.assert_allclose(q[3:7], [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    # Pinocchio's free-flyer velocity is in the base frame: world +x is base −y.
    np.testing.assert_allclose(v[:3], [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(v[3:6], [0.0, 0.0, 0.3], atol=1e-12)


# ------------------------------------------------------------- model and API


def test_box_corners_match_mujoco(tmp_path):
    mujoco = pytest.importorskip("mujoco")
    path = write_model(tmp_path, ORIENTED_BOXES_MJCF, "oriented")
    mj_model = mujoco.MjModel.from_xml_path(path)
    mj_data = mujoco.MjData(mj_model)
    mujoco.mj_forward(mj_model, mj_data)
    signs = np.array([[x, y, z] for x in (1, -1) for y in (1, -1) for z in (1, -1)])
    expected: dict[str, list[np.ndarray]] = {}
    for geom in range(mj_model.ngeom):
        body = mj_model.body(mj_model.geom_bodyid[geom]).name
        rotation_body = mj_data.xmat[mj_model.geom_bodyid[geom]].reshape(3, 3)
        rotation_geom = mj_data.geom_xmat[geom].reshape(3, 3)
        corners_world = (signs * mj_model.geom_size[geom]) @ rotation_geom.T + mj_data.geom_xpos[
            geom
        ]
        corners_body = (corners_world - mj_data.xpos[mj_model.geom_bodyid[geom]]) @ rotation_body
        expected.setdefault(body, []).append(corners_body)
    corners = {
        body.name: body.collision_points
        for body in describe_model(path).bodies
        if len(body.collision_points)
    }
    assert corners.keys() == expected.keys()
    for body, blocks in expected.items():
        np.testing.assert_allclose(corners[body], np.vstack(blocks), atol=1e-6)


def test_gravity_comes_from_the_mjcf_option(tmp_path):
    np.testing.assert_allclose(describe_model("dino_biped").model.gravity.linear, [0, 0, -9.81])
    chain = write_model(tmp_path, CHAIN_MJCF, "chain")
    np.testing.assert_allclose(describe_model(chain).model.gravity.linear, 0.0)
    backend = ReferenceBackend(chain, ground_height_m=-100.0)
    backend.step(np.zeros(4), [])
    np.testing.assert_allclose(backend.velocity, 0.0, atol=1e-15)


def test_bad_input_is_refused_with_its_value():
    backend = ReferenceBackend("revolute_humanoid")
    with pytest.raises(ValueError, match="22"):
        backend.step(np.zeros(21), [])
    with pytest.raises(ValueError, match="finite"):
        backend.step(np.full(22, np.nan), [])
    with pytest.raises(BodyNotFound, match="pelvis") as info:
        backend.step(np.zeros(22), [Push((1.0, 0.0, 0.0), "tail", duration_s=1.0)])
    assert isinstance(info.value, KeyError)
    assert "pelvis" in info.value.available
    with pytest.raises(ValueError, match=r"-1\.0"):
        ReferenceBackend("revolute_humanoid", contact_damping_Ns_per_m=-1.0)
    state = backend.standing_state()
    state.joint_position = state.joint_position[:-1]
    with pytest.raises(ValueError, match="joint_position"):
        backend.reset(state)
    q, v = backend.configuration, backend.velocity
    with pytest.raises(SimulationDiverged, match="timestep_s") as diverged:
        backend.step(np.full(22, 1e308), [])
    assert isinstance(diverged.value, FloatingPointError)
    np.testing.assert_array_equal(backend.configuration, q)
    np.testing.assert_array_equal(backend.velocity, v)
    assert backend.time_s == 0.0


def test_implements_the_physics_backend_interface():
    backend = ReferenceBackend("dino_biped", timestep_s=0.002)
    assert backend.name == "reference"
    assert backend.timestep_s == 0.002
    assert backend.time_s == 0.0
    for method in ("reset", "state", "contact_flags", "contact_wrenches_in_world", "step"):
        assert callable(getattr(backend, method))
    backend.step(zero_torque(backend), [])
    assert backend.time_s == pytest.approx(0.002)
    assert isinstance(backend.contact_flags(), list)
