"""The simulated IMU against physics: both backends, Pinocchio, MuJoCo's own sensors, statistics.

The sensor's truth is a finite difference of the backends' velocities, so
every check compares it with something computed another way: gravity at
rest, zero specific force in free fall (uniform gravity has no internal
forces), Pinocchio's classical acceleration from its own forward dynamics,
and MuJoCo's built-in accelerometer and gyro. The noise model is checked
by its sample statistics.
"""

import functools
import math

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from pydantic import ValidationError

import clients.physics.imu as imu_module
from clients.physics.imu import (
    BodyNotFound,
    ImuReading,
    ImuSpec,
    SimulatedImu,
    add_imu_frame,
)
from clients.physics.model_file import builtin_model_path
from clients.physics.mujoco_backend import MujocoBackend
from clients.physics.reference import ReferenceBackend
from clients.state import RobotState

GRAVITY_M_PER_S2 = 9.81
UP = np.array([0.0, 0.0, 1.0])
# An IMU off the body origin and turned about a skew axis, so frame mistakes show.
MOUNT = {
    "position_in_body_m": (0.05, -0.02, 0.03),
    "orientation_in_body_xyzw": (0.3, -0.2, 0.5, 0.8),
}
BACKENDS = {"reference": ReferenceBackend, "mujoco": MujocoBackend}

# A rigid robot (no joints) on two box feet: it comes exactly to rest in both backends.
BOX_STANCE_MJCF = """
<mujoco model="box_stance">
  <compiler angle="radian"/>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1"/>
    <body name="pelvis" pos="0 0 0.1">
      <freejoint name="root"/>
      <inertial pos="0 0 0" mass="20" diaginertia="0.3 0.3 0.3"/>
      <geom name="pelvis_box" type="box" size="0.15 0.2 0.05" contype="0" conaffinity="0"/>
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


def rotation_of(reading: ImuReading) -> np.ndarray:
    return pin.Quaternion(reading.true_orientation_imu_in_world_xyzw).toRotationMatrix()


def run(backend, imu: SimulatedImu, steps: int, torque=None) -> list[ImuReading]:
    """Step ``backend`` and feed the IMU after every step; the samples drawn."""
    torque = np.zeros(len(backend.state().joint_velocity)) if torque is None else torque
    readings = []
    for _ in range(steps):
        backend.step(torque, [])
        reading = imu.update(backend.state(), backend.time_s)
        if reading is not None:
            readings.append(reading)
    return readings


def raised(state: RobotState, height_m: float) -> RobotState:
    state.position_base_in_world = state.position_base_in_world + height_m * UP
    return state


def hold_pose(backend: ReferenceBackend):
    """Per-DoF PD about the current pose plus the static torques of a two-foot stance.

    Gains are capped so the explicit PD stays stable on the lightest link
    (as in ``test_reference_sim.locking_gains``); the feed-forward is the
    min-norm static solution (gravity against the two sole wrenches).
    """
    model = backend.pinocchio_model
    data = model.createData()
    q_hold = backend.configuration
    mass_matrix = pin.crba(model, data, q_hold)
    mass_matrix = np.triu(mass_matrix) + np.triu(mass_matrix, 1).T
    inertia = 1.0 / np.diag(np.linalg.inv(mass_matrix))[6:]
    step_s = backend.timestep_s
    stiffness = np.minimum(1e4, 0.5 * inertia / step_s**2)
    damping = np.minimum(2.0 * np.sqrt(stiffness * inertia), 0.3 * inertia / step_s)
    gravity = pin.computeGeneralizedGravity(model, data, q_hold)
    pin.computeJointJacobians(model, data, q_hold)
    pin.updateFramePlacements(model, data)
    jacobian = np.vstack(
        [
            pin.getFrameJacobian(model, data, model.getFrameId(site), pin.LOCAL_WORLD_ALIGNED)
            for site in ("left_sole", "right_sole")
        ]
    )
    wrenches = np.linalg.lstsq(jacobian[:, :6].T, gravity[:6], rcond=None)[0]
    feedforward = gravity[6:] - jacobian[:, 6:].T @ wrenches

    def torque() -> np.ndarray:
        error = pin.difference(model, q_hold, backend.configuration)[6:]
        return feedforward - stiffness * error - damping * backend.velocity[6:]

    return torque


# ------------------------------------------------------------------ the spec


def test_defaults_are_the_bmi088_in_si_units():
    spec = ImuSpec()
    assert spec.gyro_noise_density_rad_per_s_sqrt_hz == pytest.approx(0.014 * math.pi / 180)
    assert spec.accel_noise_density_m_per_s2_sqrt_hz == pytest.approx(175e-6 * 9.80665)
    assert spec.gyro_initial_bias_std_rad_per_s == pytest.approx(math.pi / 180)
    assert spec.accel_initial_bias_std_m_per_s2 == pytest.approx(0.02 * 9.80665)
    assert spec.gyro_noise_std_rad_per_s == pytest.approx(2.443e-4 * math.sqrt(1000), rel=1e-3)
    assert spec.body == "" and spec.orientation_in_body_xyzw == (0.0, 0.0, 0.0, 1.0)


def test_spec_refuses_unknown_keys_bad_values_and_two_biases():
    with pytest.raises(ValidationError, match="extra"):
        ImuSpec.model_validate({"rate": 200.0})
    with pytest.raises(ValidationError, match="greater than 0"):
        ImuSpec(rate_hz=0.0)
    with pytest.raises(ValidationError, match="finite"):
        ImuSpec(position_in_body_m=(0.0, math.nan, 0.0))
    with pytest.raises(ValidationError, match="non-zero"):
        ImuSpec(orientation_in_body_xyzw=(0.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValidationError, match="not both"):
        ImuSpec(gyro_initial_bias_rad_per_s=(0.0, 0.0, 0.0), gyro_initial_bias_std_rad_per_s=1.0)
    assert ImuSpec(orientation_in_body_xyzw=(0.0, 0.0, 0.0, 2.0)).orientation_in_body_xyzw == (
        0.0,
        0.0,
        0.0,
        1.0,
    )
    with pytest.raises(ValidationError):
        ImuSpec().rate_hz = 10.0  # frozen
    fixed = ImuSpec.ideal(accel_initial_bias_m_per_s2=(0.1, 0.0, 0.0))
    assert fixed.accel_initial_bias_m_per_s2 == (0.1, 0.0, 0.0)
    assert fixed.accel_noise_density_m_per_s2_sqrt_hz == 0.0


def test_public_names_import():
    for name in imu_module.__all__:
        assert hasattr(imu_module, name), name


# ------------------------------------------------------------------ at rest


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_rigid_robot_at_rest_reads_gravity_up_in_the_imu_frame(tmp_path, backend_name):
    path = tmp_path / "box_stance.xml"
    path.write_text(BOX_STANCE_MJCF)
    backend = BACKENDS[backend_name](str(path))
    backend.reset(ReferenceBackend(str(path)).standing_state())
    imu = SimulatedImu(ImuSpec.ideal(**MOUNT), path)
    imu.reset(backend.state(), backend.time_s)
    reading = run(backend, imu, 300)[-1]
    # Settled on its contacts (penalty in one, soft constraints in the other):
    # the residual motion after 0.3 s is below 1e-5 m/s² in both.
    expected = rotation_of(reading).T @ (GRAVITY_M_PER_S2 * UP)
    np.testing.assert_allclose(reading.linear_acceleration_imu_in_imu, expected, atol=1e-4)
    np.testing.assert_allclose(reading.angular_velocity_imu_in_imu, 0.0, atol=1e-9)
    # The mounting rotation is what turns "up" away from the IMU's z axis.
    mount = pin.Quaternion(
        np.array(MOUNT["orientation_in_body_xyzw"])
        / np.linalg.norm(MOUNT["orientation_in_body_xyzw"])
    ).toRotationMatrix()
    np.testing.assert_allclose(rotation_of(reading), mount, atol=1e-6)


@pytest.mark.parametrize("model", ["thesis_humanoid", "revolute_humanoid"])
def test_standing_humanoid_reads_gravity_up_and_its_own_acceleration(model):
    """A PD-held humanoid on the penalty ground: +g up, up to the rocking the backend computes.

    The held humanoid never quite stops: a light foot on a stiff ground keeps
    it rocking at about 1 cm/s, ±0.1 m/s² per sample. So each sample is also
    compared with Pinocchio's classical acceleration of the IMU point given the
    backend's own q̈ over the step (contact forces included), which the finite
    difference matches to O(Δt · |v|), here 1e-3 m/s² at most.
    """
    backend = ReferenceBackend(model)
    backend.reset(backend.standing_state())
    spec = ImuSpec.ideal(**MOUNT)
    imu = SimulatedImu(spec, model)
    imu.reset(backend.state(), backend.time_s)
    pinocchio_model = pin.buildModelFromMJCF(str(builtin_model_path(model)))
    frame = add_imu_frame(pinocchio_model, spec, builtin_model_path(model))
    data = pinocchio_model.createData()
    gravity = GRAVITY_M_PER_S2 * UP
    hold = hold_pose(backend)
    for step in range(300):
        q, v = backend.configuration, backend.velocity
        backend.step(hold(), [])
        acceleration = (backend.velocity - v) / backend.timestep_s
        pin.forwardKinematics(pinocchio_model, data, q, v, acceleration)
        pin.updateFramePlacements(pinocchio_model, data)
        point = pin.getFrameClassicalAcceleration(
            pinocchio_model, data, frame, pin.LOCAL_WORLD_ALIGNED
        ).linear
        expected = data.oMf[frame].rotation.T @ (point + gravity)
        reading = imu.update(backend.state(), backend.time_s)
        np.testing.assert_allclose(reading.linear_acceleration_imu_in_imu, expected, atol=1e-3)
        if step < 100:
            continue  # settling onto the penalty springs from the reset pose (0.4 mm)
        up_in_imu = rotation_of(reading).T @ gravity
        np.testing.assert_allclose(reading.linear_acceleration_imu_in_imu, up_in_imu, atol=0.3)
        assert np.abs(reading.angular_velocity_imu_in_imu).max() < 0.05


# ----------------------------------------------------------------- free fall


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_free_fall_reads_zero_specific_force(backend_name):
    backend = BACKENDS[backend_name]("thesis_humanoid")
    backend.reset(raised(ReferenceBackend("thesis_humanoid").standing_state(), 0.5))
    spec = ImuSpec.ideal(body="left_forearm", **MOUNT)
    imu = SimulatedImu(spec, "thesis_humanoid")
    imu.reset(backend.state(), backend.time_s)
    readings = run(backend, imu, 200)  # 0.2 s: 0.2 m of the 0.5 m drop
    assert backend.contact_flags() == [False, False]
    assert len(readings) == 200
    for reading in readings:
        np.testing.assert_allclose(reading.linear_acceleration_imu_in_imu, 0.0, atol=1e-9)
        np.testing.assert_allclose(reading.angular_velocity_imu_in_imu, 0.0, atol=1e-9)
    # The velocity it carries is the parabola's.
    np.testing.assert_allclose(
        readings[-1].true_linear_velocity_imu_in_world,
        [0.0, 0.0, -GRAVITY_M_PER_S2 * 0.2],
        atol=1e-9,
    )


# --------------------------------------------------- against other computations


def tumbling_start(backend_name: str, timestep_s: float):
    """The thesis humanoid in the air, spinning, with its joints moving."""
    backend = BACKENDS[backend_name]("thesis_humanoid", timestep_s=timestep_s)
    state = raised(ReferenceBackend("thesis_humanoid").standing_state(), 1.0)
    state.linear_velocity_base_in_world = np.array([0.3, 0.1, 0.5])
    state.angular_velocity_base_in_base = np.array([0.5, -0.3, 0.8])
    rng = np.random.default_rng(1)
    state.joint_velocity = rng.uniform(-1.0, 1.0, state.joint_velocity.size)
    backend.reset(state)
    torque = rng.uniform(-0.5, 0.5, state.joint_velocity.size)
    return backend, torque


def specific_force_error(timestep_s: float) -> tuple[float, float]:
    """Largest |IMU − Pinocchio| specific force over 50 ms of tumbling, and the largest |f|.

    Pinocchio's side: ``q̈ = aba(q_k, v_k, τ)`` on a separately built model,
    then the IMU point's classical acceleration (``getFrameClassicalAcceleration``)
    at the start of each step, minus gravity, in the IMU frame.
    """
    backend, torque = tumbling_start("reference", timestep_s)
    path = builtin_model_path("thesis_humanoid")
    spec = ImuSpec.ideal(body="left_forearm", rate_hz=1.0 / timestep_s, **MOUNT)
    imu = SimulatedImu(spec, path)
    imu.reset(backend.state(), backend.time_s)
    model = pin.buildModelFromMJCF(str(path))
    model.gravity = pin.Motion(np.array([0.0, 0.0, -GRAVITY_M_PER_S2]), np.zeros(3))
    frame = add_imu_frame(model, spec, path)
    data = model.createData()
    largest_error = largest_force = 0.0
    for _ in range(round(0.05 / timestep_s)):
        q, v = backend.configuration, backend.velocity
        acceleration = pin.aba(model, data, q, v, np.concatenate([np.zeros(6), torque]))
        pin.forwardKinematics(model, data, q, v, acceleration)
        pin.updateFramePlacements(model, data)
        point = pin.getFrameClassicalAcceleration(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
        expected = data.oMf[frame].rotation.T @ (point.linear - model.gravity.linear)
        backend.step(torque, [])
        reading = imu.update(backend.state(), backend.time_s)
        error = np.linalg.norm(reading.linear_acceleration_imu_in_imu - expected)
        largest_error = max(largest_error, error)
        largest_force = max(largest_force, np.linalg.norm(expected))
    return largest_error, largest_force


def test_specific_force_converges_to_pinocchio_classical_acceleration():
    """The finite difference is Pinocchio's acceleration up to O(Δt), and no more.

    Over a step, ``(J(q_k+1) v_k+1 − J(q_k) v_k) / Δt = J a_k + J̇(q_k, v_k+1) v_k+1
    + O(Δt)`` while the classical acceleration is ``J a_k + J̇(q_k, v_k) v_k``:
    they differ by ``O(Δt)``. So the error must halve with the step (a frame
    or sign mistake would not shrink), and at 1 ms it is a few percent of the
    forearm's 19 m/s² (spinning, with joints moving at up to 1 rad/s).
    """
    error_1ms, force = specific_force_error(1e-3)
    error_half, _ = specific_force_error(5e-4)
    assert force > 10.0
    assert error_1ms < 0.03 * force
    assert 0.45 < error_half / error_1ms < 0.55


def mujoco_sensor_error(timestep_s: float) -> tuple[float, float]:
    """Largest |IMU − MuJoCo accelerometer| over 50 ms of tumbling, and the largest |f|.

    MuJoCo's own accelerometer and gyro sit at a site where the IMU is, on a
    separately compiled copy of the model, fed a copy of the backend's state.
    The gyro must agree to rounding at every step.
    """
    backend, torque = tumbling_start("mujoco", timestep_s)
    spec = ImuSpec.ideal(body="left_forearm", rate_hz=1.0 / timestep_s, **MOUNT)
    imu = SimulatedImu(spec, "thesis_humanoid")
    imu.reset(backend.state(), backend.time_s)

    sensor_spec = mujoco.MjSpec.from_file(str(builtin_model_path("thesis_humanoid")))
    x, y, z, w = spec.orientation_in_body_xyzw
    sensor_spec.body("left_forearm").add_site(
        name="imu", pos=list(spec.position_in_body_m), quat=[w, x, y, z]
    )
    for name, kind in (
        ("accel", mujoco.mjtSensor.mjSENS_ACCELEROMETER),
        ("gyro", mujoco.mjtSensor.mjSENS_GYRO),
    ):
        sensor_spec.add_sensor(
            name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="imu"
        )
    sensor_model = sensor_spec.compile()
    sensor_model.opt.gravity[:] = backend.model.opt.gravity
    sensor_model.opt.timestep = timestep_s
    sensor_data = mujoco.MjData(sensor_model)
    assert sensor_model.nq == backend.model.nq and sensor_model.nu == backend.model.nu

    def sensors(qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Accelerometer and gyro at this state, with the torques of the step taken."""
        sensor_data.qpos[:], sensor_data.qvel[:] = qpos, qvel
        sensor_data.ctrl[:] = backend.data.ctrl
        mujoco.mj_forward(sensor_model, sensor_data)
        return sensor_data.sensor("accel").data.copy(), sensor_data.sensor("gyro").data.copy()

    largest_error = largest_force = 0.0
    for _ in range(round(0.05 / timestep_s)):
        start_qpos, start_qvel = backend.data.qpos.copy(), backend.data.qvel.copy()
        backend.step(torque, [])
        reading = imu.update(backend.state(), backend.time_s)
        accelerometer, _ = sensors(start_qpos, start_qvel)
        _, gyro = sensors(backend.data.qpos, backend.data.qvel)
        error = np.linalg.norm(reading.linear_acceleration_imu_in_imu - accelerometer)
        largest_error = max(largest_error, error)
        largest_force = max(largest_force, np.linalg.norm(accelerometer))
        np.testing.assert_allclose(reading.angular_velocity_imu_in_imu, gyro, atol=1e-9)
    return largest_error, largest_force


def test_mujoco_backend_converges_to_mujocos_own_accelerometer_and_matches_its_gyro():
    """MuJoCo's built-in sensors, where the IMU is, on a copy of the backend's state.

    MuJoCo's accelerometer reads the site's specific force at the state a
    step starts from (with that step's ``qacc``); the IMU's finite difference
    covers the whole step, so they differ by O(Δt), as with Pinocchio: the
    error must halve with the step. The gyro reads the angular velocity at
    the state the step ends in, which is what the IMU reports.
    """
    error_1ms, force = mujoco_sensor_error(1e-3)
    error_half, _ = mujoco_sensor_error(5e-4)
    assert force > 10.0
    assert error_1ms < 0.03 * force
    assert 0.45 < error_half / error_1ms < 0.55


# ---------------------------------------------------------------- the errors


@functools.cache
def standing_still() -> RobotState:
    return ReferenceBackend("thesis_humanoid").standing_state()


def constant_stream(imu: SimulatedImu, steps: int, step_s: float = 1e-3) -> list[ImuReading]:
    """Feed the IMU the thesis humanoid standing still, ``steps`` times: truth is +g up."""
    state = standing_still()
    imu.reset(state, 0.0)
    readings = []
    for step in range(1, steps + 1):
        reading = imu.update(state, step * step_s)
        if reading is not None:
            readings.append(reading)
    return readings


def test_noise_and_bias_walk_have_the_specified_statistics():
    spec = ImuSpec(
        rate_hz=500.0,
        gyro_bias_random_walk_rad_per_s2_sqrt_hz=1e-3,
        accel_bias_random_walk_m_per_s3_sqrt_hz=1e-2,
        seed=7,
    )
    readings = constant_stream(SimulatedImu(spec, "thesis_humanoid"), 20_000)  # 20 s at 1 kHz
    assert len(readings) == 10_000
    np.testing.assert_allclose(np.diff([r.time_s for r in readings]), 1 / 500.0, atol=1e-12)

    def stack(field: str) -> np.ndarray:
        return np.array([getattr(r, field) for r in readings])

    np.testing.assert_allclose(
        stack("true_linear_acceleration_imu_in_imu"),
        np.tile([0.0, 0.0, GRAVITY_M_PER_S2], (10_000, 1)),
        atol=1e-12,
    )
    gyro_noise = (
        stack("angular_velocity_imu_in_imu")
        - stack("true_angular_velocity_imu_in_imu")
        - stack("true_angular_velocity_bias_in_imu")
    )
    accel_noise = (
        stack("linear_acceleration_imu_in_imu")
        - stack("true_linear_acceleration_imu_in_imu")
        - stack("true_linear_acceleration_bias_in_imu")
    )
    # 10 000 samples per axis: the std estimate is within 0.7 % (1σ); allow 3 %.
    np.testing.assert_allclose(gyro_noise.std(axis=0), spec.gyro_noise_std_rad_per_s, rtol=0.03)
    np.testing.assert_allclose(accel_noise.std(axis=0), spec.accel_noise_std_m_per_s2, rtol=0.03)
    np.testing.assert_allclose(
        gyro_noise.mean(axis=0), 0.0, atol=4 * spec.gyro_noise_std_rad_per_s / 100
    )
    # Bias increments per sample: σ_b √(1 / rate).
    walk_s = math.sqrt(1 / 500.0)
    gyro_steps = np.diff(stack("true_angular_velocity_bias_in_imu"), axis=0)
    accel_steps = np.diff(stack("true_linear_acceleration_bias_in_imu"), axis=0)
    np.testing.assert_allclose(gyro_steps.std(axis=0), 1e-3 * walk_s, rtol=0.03)
    np.testing.assert_allclose(accel_steps.std(axis=0), 1e-2 * walk_s, rtol=0.03)


def test_initial_biases_are_seeded_draws_of_the_datasheet_offset():
    draws = []
    for seed in range(400):
        imu = SimulatedImu(ImuSpec(seed=seed), "thesis_humanoid")
        draws.append(constant_stream(imu, 1)[0].true_linear_acceleration_bias_in_imu)
    # 1200 draws: the std estimate is within 2 % (1σ); allow 7 %.
    assert np.std(draws) == pytest.approx(ImuSpec().accel_initial_bias_std_m_per_s2, rel=0.07)
    fixed = ImuSpec(
        gyro_initial_bias_rad_per_s=(0.01, -0.02, 0.03),
        gyro_bias_random_walk_rad_per_s2_sqrt_hz=0.0,
    )
    reading = constant_stream(SimulatedImu(fixed, "thesis_humanoid"), 1)[0]
    np.testing.assert_array_equal(reading.true_angular_velocity_bias_in_imu, [0.01, -0.02, 0.03])


def test_a_rate_that_does_not_divide_the_physics_rate_keeps_its_average():
    readings = constant_stream(SimulatedImu(ImuSpec.ideal(rate_hz=400.0), "thesis_humanoid"), 1000)
    times = np.array([r.time_s for r in readings])
    assert len(readings) == 400
    # Each sample at the first 1 ms step at or after it is due: 2 or 3 ms apart.
    assert set(np.round(np.diff(times) * 1e3).astype(int)) == {2, 3}
    assert np.all(times - 0.0025 * np.arange(1, 401) < 1e-3 + 1e-12)
    assert np.all(times - 0.0025 * np.arange(1, 401) >= -1e-12)


def test_same_seed_same_readings_and_reset_starts_over():
    imu = SimulatedImu(ImuSpec(seed=3), "thesis_humanoid")
    first = constant_stream(imu, 50)
    again = constant_stream(imu, 50)
    other = constant_stream(SimulatedImu(ImuSpec(seed=4), "thesis_humanoid"), 50)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(
            a.linear_acceleration_imu_in_imu, b.linear_acceleration_imu_in_imu
        )
        np.testing.assert_array_equal(a.angular_velocity_imu_in_imu, b.angular_velocity_imu_in_imu)
    assert not np.array_equal(
        first[0].angular_velocity_imu_in_imu, other[0].angular_velocity_imu_in_imu
    )
    assert imu.reading() is again[-1]


def test_misuse_is_refused_with_what_to_do():
    with pytest.raises(BodyNotFound, match=r"no body 'tail'.*pelvis"):
        SimulatedImu(ImuSpec(body="tail"), "thesis_humanoid")
    imu = SimulatedImu(ImuSpec(rate_hz=500.0), "thesis_humanoid")
    state = ReferenceBackend("thesis_humanoid").standing_state()
    with pytest.raises(RuntimeError, match="reset"):
        imu.update(state, 0.001)
    imu.reset(state, 0.0)
    with pytest.raises(ValueError, match="must advance"):
        imu.update(state, 0.0)
    with pytest.raises(ValueError, match="must not exceed the physics rate"):
        imu.update(state, 0.005)
    state.joint_position = state.joint_position[:-1]
    with pytest.raises(ValueError, match="coordinates"):
        imu.update(state, 0.001)


def test_reset_outputs_a_sample_at_rest_and_the_filter_orientation_has_the_tilt_error():
    """The first sample (at reset) reads gravity; the AHRS orientation is off by the spec's tilt."""
    state = ReferenceBackend("thesis_humanoid").standing_state()
    tilts = []
    for seed in range(200):
        imu = SimulatedImu(
            ImuSpec.ideal(orientation_tilt_error_rad=0.01, seed=seed), "thesis_humanoid"
        )
        imu.reset(state, 2.0)
        reading = imu.reading()
        assert reading is not None and reading.time_s == 2.0
        np.testing.assert_allclose(reading.linear_acceleration_imu_in_imu, [0, 0, 9.81], atol=1e-9)
        np.testing.assert_allclose(reading.angular_velocity_imu_in_imu, 0.0, atol=1e-12)
        error = pin.Quaternion(reading.orientation_imu_in_world_xyzw).toRotationMatrix()
        error = (
            error @ pin.Quaternion(reading.true_orientation_imu_in_world_xyzw).toRotationMatrix().T
        )
        axis_angle = pin.log3(error)
        assert abs(axis_angle[2]) < 1e-12  # a tilt: no heading error
        tilts.append(np.linalg.norm(axis_angle))
    assert np.sqrt(np.mean(np.square(tilts))) == pytest.approx(0.01, rel=0.1)
    no_output = SimulatedImu(ImuSpec(orientation_output=False), "thesis_humanoid")
    no_output.reset(state)
    assert no_output.reading().orientation_imu_in_world_xyzw is None
