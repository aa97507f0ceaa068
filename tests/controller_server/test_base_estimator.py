"""The base estimator against an analytic ground truth, and its equations against math.

A floating base moves smoothly (sinusoidal translation, small roll, pitch and yaw) over two
feet fixed in the world; the IMU readings are computed exactly from that motion (gyro =
angular velocity in the IMU frame, specific force = ``Rᵀ (a − g)`` at the IMU point with
the lever-arm terms), then corrupted with BMI088-class white noise and biases from a seed.
Finite differences on the group check the propagation and measurement Jacobians, and
Pinocchio's frame placements check the leg-kinematics helper.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from controller_server.estimation import (
    BaseEstimator,
    EstimatorInputError,
    EstimatorNoise,
    EstimatorPrior,
    ImuMount,
    LegKinematics,
    compute_leg_kinematics,
    robot_leg_kinematics,
)
from controller_server.estimation.inekf import (
    error_dynamics_matrix,
    error_transition_matrix,
    ground_innovation,
    kinematic_innovation,
    propagate_mean,
)
from controller_server.estimation.lie import sek3_exp, sek3_log, so3_exp, so3_gamma, so3_log
from controller_server.math.spatial import skew
from controller_server.models import load_robot_model

GRAVITY = np.array([0.0, 0.0, -9.80665])
RATE_HZ = 500.0
LEG_JACOBIAN = 0.8 * np.eye(3)
"""The synthetic legs: three joints moving the foot with a 0.8 m lever (m/rad)."""

MOUNT = ImuMount(
    rotation_imu_to_base=so3_exp(np.array([np.pi, 0.0, 0.0])) @ so3_exp(np.array([0, 0, 0.5])),
    position_imu_in_base=np.array([0.06, -0.03, 0.12]),
)
FEET_IN_WORLD = np.array([[0.02, 0.1, 0.0], [-0.01, -0.1, 0.0]])


def _rx(angle):
    return so3_exp(np.array([angle, 0.0, 0.0]))


def _ry(angle):
    return so3_exp(np.array([0.0, angle, 0.0]))


def _rz(angle):
    return so3_exp(np.array([0.0, 0.0, angle]))


def _cross(a, b):
    """``a × b`` (``np.cross`` costs ten times more on 3-vectors)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _sine(amplitude, frequency_hz, phase, t):
    """Value, first and second derivative of ``A sin(2π f t + c)``."""
    w = 2 * np.pi * frequency_hz
    return (
        amplitude * np.sin(w * t + phase),
        amplitude * w * np.cos(w * t + phase),
        -amplitude * w * w * np.sin(w * t + phase),
    )


def base_motion(t: float):
    """Ground truth at ``t``: ``R_WB``, ``p_B``, ``v_B``, ``a_B``, ``ω``, ``ω̇`` (world)."""
    px, py, pz = (
        _sine(0.03, 0.5, 0.0, t),
        _sine(0.02, 0.7, 0.3, t),
        _sine(0.02, 0.9, 0.0, t),
    )
    position = np.array([px[0], py[0], 0.9 + pz[0]])
    velocity = np.array([px[1], py[1], pz[1]])
    acceleration = np.array([px[2], py[2], pz[2]])
    roll, pitch, yaw = _sine(0.05, 0.6, 0.0, t), _sine(0.06, 0.4, 0.5, t), _sine(0.1, 0.3, 0, t)
    rz, ry, rx = _rz(yaw[0]), _ry(pitch[0]), _rx(roll[0])
    e_x, e_y, e_z = np.eye(3)
    axis_pitch, axis_roll = rz @ e_y, rz @ ry @ e_x
    omega_zy = yaw[1] * e_z + pitch[1] * axis_pitch
    omega = omega_zy + roll[1] * axis_roll
    omega_dot = (
        yaw[2] * e_z
        + pitch[2] * axis_pitch
        + pitch[1] * _cross(yaw[1] * e_z, axis_pitch)
        + roll[2] * axis_roll
        + roll[1] * _cross(omega_zy, axis_roll)
    )
    return rz @ ry @ rx, position, velocity, acceleration, omega, omega_dot


def exact_imu(t: float, mount: ImuMount = MOUNT, truth=None):
    """Gyro and specific force of a perfect IMU at ``t`` (IMU frame)."""
    rotation, _, _, acceleration, omega, omega_dot = truth or base_motion(t)
    lever = rotation @ mount.position_imu_in_base
    acceleration_imu = acceleration + _cross(omega_dot, lever) + _cross(omega, _cross(omega, lever))
    rotation_imu = rotation @ mount.rotation_imu_to_base
    return rotation_imu.T @ omega, rotation_imu.T @ (acceleration_imu - GRAVITY)


def feet_in_base(t: float, feet_in_world=FEET_IN_WORLD, truth=None):
    rotation, position, *_ = truth or base_motion(t)
    return (feet_in_world - position) @ rotation


class NoisyImu:
    """BMI088-class white noise and random-walk biases on top of :func:`exact_imu`."""

    def __init__(self, rng, noise: EstimatorNoise, gyro_bias, accel_bias):
        self.rng, self.noise = rng, noise
        self.gyro_bias, self.accel_bias = np.array(gyro_bias), np.array(accel_bias)

    def read(self, t, dt, truth=None):
        gyro, accel = exact_imu(t, truth=truth)
        n = self.noise
        self.gyro_bias = self.gyro_bias + n.gyro_bias_random_walk * np.sqrt(
            dt
        ) * self.rng.standard_normal(3)
        self.accel_bias = self.accel_bias + n.accel_bias_random_walk * np.sqrt(
            dt
        ) * self.rng.standard_normal(3)
        gyro = (
            gyro + self.gyro_bias + n.gyro_noise_density / np.sqrt(dt) * self.rng.standard_normal(3)
        )
        accel = (
            accel
            + self.accel_bias
            + n.accel_noise_density / np.sqrt(dt) * self.rng.standard_normal(3)
        )
        return gyro, accel


def noisy_kinematics(rng, positions, noise: EstimatorNoise) -> LegKinematics:
    """Feet in the base from encoders with the estimator's noise model (1 mm model error)."""
    count = len(positions)
    joint_noise = noise.joint_position_noise * rng.standard_normal((count, 3))
    measured = positions + joint_noise @ LEG_JACOBIAN.T + 1e-3 * rng.standard_normal((count, 3))
    return LegKinematics(measured, np.repeat(LEG_JACOBIAN[None], count, axis=0))


def errors(estimate, truth):
    """Tilt (rad), yaw (rad), velocity (m/s, vector) and height (m) errors against ``truth``."""
    rotation, position, velocity, *_ = truth
    rotation_est = pin.Quaternion(estimate.orientation_base_in_world_xyzw).toRotationMatrix()
    up_true, up_est = rotation.T @ np.array([0, 0, 1.0]), rotation_est.T @ np.array([0, 0, 1.0])
    tilt = np.arccos(np.clip(up_true @ up_est, -1.0, 1.0))
    yaw = so3_log(rotation_est @ rotation.T)[2]
    return (
        tilt,
        yaw,
        estimate.linear_velocity_base_in_world - velocity,
        estimate.position_base_in_world[2] - position[2],
    )


def run(duration_s, seed, *, flags_at=lambda t: (True, True), feet_at=None):
    """Run the estimator over the synthetic motion; return the error histories."""
    rng = np.random.default_rng(seed)
    noise = EstimatorNoise()
    imu = NoisyImu(rng, noise, gyro_bias=[0.006, -0.004, 0.008], accel_bias=[0.08, -0.06, 0.1])
    # The synthetic base moves from the start: its first gyro reading is no bias.
    prior = EstimatorPrior(still_at_start=False)
    estimator = BaseEstimator(["left", "right"], imu_mount=MOUNT, noise=noise, prior=prior)
    dt = 1.0 / RATE_HZ
    history = []
    for i in range(int(duration_s * RATE_HZ) + 1):
        t = i * dt
        truth = base_motion(t)
        gyro, accel = imu.read(t, dt, truth)
        feet_world = FEET_IN_WORLD if feet_at is None else feet_at(t)
        kinematics = noisy_kinematics(rng, feet_in_base(t, feet_world, truth), noise)
        estimate = estimator.step(gyro, accel, dt, kinematics, flags_at(t))
        history.append((t, *errors(estimate, truth)))
    return estimator, estimate, imu, history


def test_synthetic_imu_matches_finite_differences_of_the_motion():
    """The test's own ground truth: ω and the specific force against differentiated poses."""
    h = 1e-5
    for t in (0.3, 1.7, 4.2):
        gyro, accel = exact_imu(t)
        r_minus, _p_minus, *_ = base_motion(t - h)
        r_plus, _p_plus, *_ = base_motion(t + h)
        rotation, _position, *_ = base_motion(t)
        omega_world = so3_log(r_plus @ r_minus.T) / (2 * h)
        rotation_imu = rotation @ MOUNT.rotation_imu_to_base
        np.testing.assert_allclose(rotation_imu @ gyro, omega_world, atol=1e-7)

        def imu_point(s):
            r, p, *_ = base_motion(s)
            return p + r @ MOUNT.position_imu_in_base

        acceleration = (imu_point(t + 1e-4) - 2 * imu_point(t) + imu_point(t - 1e-4)) / 1e-8
        np.testing.assert_allclose(rotation_imu @ accel + GRAVITY, acceleration, atol=1e-5)


def test_tracks_roll_pitch_velocity_height_and_biases_over_ten_seconds():
    _estimator, estimate, imu, history = run(10.0, seed=7)
    t, tilt, yaw, velocity_error, height_error = (
        np.array(c, dtype=object) for c in zip(*history, strict=True)
    )
    t = t.astype(float)
    settled = t >= 1.0
    tilt_max = np.rad2deg(np.max(tilt[settled].astype(float)))
    velocity_rms = np.sqrt(np.mean([e @ e for e in velocity_error[settled]]))
    height_max = np.max(np.abs(height_error[settled].astype(float)))
    yaw_drift = np.rad2deg(np.max(np.abs(yaw.astype(float))))
    gyro_bias_error = estimate.gyro_bias_in_imu - imu.gyro_bias
    accel_bias_error = estimate.accel_bias_in_imu - imu.accel_bias
    print(
        f"\nroll/pitch error max {tilt_max:.3f} deg, velocity RMS {velocity_rms:.4f} m/s, "
        f"height error max {100 * height_max:.3f} cm, |yaw drift| max {yaw_drift:.3f} deg; "
        f"gyro bias error {np.rad2deg(gyro_bias_error).round(3)} deg/s "
        f"(truth {np.rad2deg(imu.gyro_bias).round(3)}), accel bias error "
        f"{accel_bias_error.round(3)} m/s² (truth {imu.accel_bias.round(3)}); "
        f"1σ { ({k: v.round(4) for k, v in estimate.standard_deviations.items()}) }"
    )
    assert tilt_max <= 1.0
    assert velocity_rms <= 0.05
    assert height_max <= 0.01
    assert yaw_drift <= 1.0
    assert np.linalg.norm(gyro_bias_error) < 0.2 * np.linalg.norm(imu.gyro_bias)
    assert np.linalg.norm(accel_bias_error) < 0.3 * np.linalg.norm(imu.accel_bias)
    assert set(estimate.position_contacts_in_world) == {"left", "right"}
    np.testing.assert_allclose(
        estimate.position_contacts_in_world["right"][2], FEET_IN_WORLD[1, 2], atol=0.01
    )
    covariance = estimate.covariance
    assert covariance.shape == (15, 15)
    np.testing.assert_allclose(covariance, covariance.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(covariance) > 0)


def test_contact_switching_lift_and_land_elsewhere_does_not_diverge():
    """The left foot lifts twice and lands 8 cm further each time; the right one stands."""

    def flags_at(t):
        return (not (1.0 <= t < 1.4 or 2.4 <= t < 2.8), True)

    def feet_at(t):
        feet = FEET_IN_WORLD.copy()
        steps = (t >= 1.4) + (t >= 2.8)
        feet[0, 0] += 0.08 * steps
        for start in (1.0, 2.4):
            if start <= t < start + 0.4:  # swinging: forward and up
                phase = (t - start) / 0.4
                feet[0, 0] += 0.08 * phase
                feet[0, 2] = 0.05 * np.sin(np.pi * phase)
        return feet

    _estimator, estimate, _, history = run(4.0, seed=3, flags_at=flags_at, feet_at=feet_at)
    tilt = np.array([h[1] for h in history])
    velocity_error = np.array([h[3] for h in history])
    height_error = np.array([h[4] for h in history])
    print(
        f"\ncontact switching: tilt max {np.rad2deg(tilt[500:].max()):.3f} deg, velocity RMS "
        f"{np.sqrt(np.mean(np.sum(velocity_error[500:] ** 2, axis=1))):.4f} m/s, height max "
        f"{100 * np.abs(height_error[500:]).max():.3f} cm"
    )
    assert np.rad2deg(tilt[500:].max()) <= 1.0
    assert np.sqrt(np.mean(np.sum(velocity_error[500:] ** 2, axis=1))) <= 0.05
    assert np.abs(height_error[500:]).max() <= 0.01
    landed = estimate.position_contacts_in_world["left"]
    right = estimate.position_contacts_in_world["right"]
    # Horizontal positions drift together; the step between the feet is observable.
    np.testing.assert_allclose(landed - right, feet_at(4.0)[0] - feet_at(4.0)[1], atol=0.02)


def test_a_lifted_foot_leaves_the_state_and_rejoins():
    estimator = BaseEstimator(["left", "right"], imu_mount=MOUNT)
    gyro, accel = exact_imu(0.0)
    both = LegKinematics(feet_in_base(0.0), np.repeat(LEG_JACOBIAN[None], 2, axis=0))
    estimator.step(gyro, accel, 0.002, both, [True, True])
    estimate = estimator.step(gyro, accel, 0.002, both, [False, True])
    assert set(estimate.position_contacts_in_world) == {"right"}
    estimate = estimator.step(gyro, accel, 0.002, both, [True, True])
    assert set(estimate.position_contacts_in_world) == {"left", "right"}


def test_initialises_level_from_the_accelerometer_with_feet_on_the_ground():
    """A still, tilted base: roll and pitch from gravity, the lowest stance foot at z = 0."""
    rotation_base = _ry(0.1) @ _rx(-0.15)  # zero yaw
    position_base = np.array([0.0, 0.0, 0.87])
    rotation_imu = rotation_base @ MOUNT.rotation_imu_to_base
    accel = rotation_imu.T @ -GRAVITY
    feet = (FEET_IN_WORLD - position_base) @ rotation_base
    estimator = BaseEstimator(["left", "right"], imu_mount=MOUNT)
    estimate = estimator.step(
        np.zeros(3), accel, 0.002, LegKinematics(feet, np.repeat(LEG_JACOBIAN[None], 2, 0)), [1, 1]
    )
    rotation_est = pin.Quaternion(estimate.orientation_base_in_world_xyzw).toRotationMatrix()
    np.testing.assert_allclose(rotation_est, rotation_base, atol=1e-9)
    np.testing.assert_allclose(estimate.position_base_in_world, position_base, atol=1e-3)
    np.testing.assert_allclose(estimate.linear_velocity_base_in_world, 0.0, atol=1e-9)


@pytest.mark.parametrize("given_orientation", [False, True])
def test_a_turned_mount_starts_at_the_base_orientation(given_orientation):
    """A mount that is not its own inverse (MOUNT is: π about x, then z) maps R_WI = R_WB R_BI."""
    mount = ImuMount(rotation_imu_to_base=_rz(np.pi / 2) @ _rx(0.3))
    rotation_base = _rz(0.4) @ _ry(0.1) @ _rx(-0.15) if given_orientation else _ry(0.1)
    rotation_imu = rotation_base @ mount.rotation_imu_to_base
    feet = (FEET_IN_WORLD - np.array([0.0, 0.0, 0.87])) @ rotation_base
    kinematics = LegKinematics(feet, np.repeat(LEG_JACOBIAN[None], 2, 0))
    estimator = BaseEstimator(["left", "right"], imu_mount=mount)
    if given_orientation:
        quaternion = pin.Quaternion(rotation_base).coeffs()
        estimator.initialize(kinematics, [1, 1], orientation_base_in_world_xyzw=quaternion)
    else:
        estimator.initialize(
            kinematics, [1, 1], specific_force_imu_in_imu=rotation_imu.T @ -GRAVITY
        )
    estimate = estimator.estimate()
    rotation_est = pin.Quaternion(estimate.orientation_base_in_world_xyzw).toRotationMatrix()
    np.testing.assert_allclose(rotation_est, rotation_base, atol=1e-9)
    np.testing.assert_allclose(estimator.rotation_base_in_world, rotation_base, atol=1e-9)
    # One still step: gravity as measured in the turned IMU keeps the estimate where it is.
    estimate = estimator.step(np.zeros(3), rotation_imu.T @ -GRAVITY, 0.002, kinematics, [1, 1])
    rotation_est = pin.Quaternion(estimate.orientation_base_in_world_xyzw).toRotationMatrix()
    np.testing.assert_allclose(rotation_est, rotation_base, atol=1e-6)


def test_nan_and_misshapen_inputs_raise_typed_errors_naming_the_field():
    estimator = BaseEstimator(["left", "right"], imu_mount=MOUNT)
    gyro, accel = exact_imu(0.0)
    kinematics = LegKinematics(feet_in_base(0.0), np.repeat(LEG_JACOBIAN[None], 2, axis=0))
    estimator.step(gyro, accel, 0.002, kinematics, [True, True])
    before = estimator.estimate()
    bad_kinematics = LegKinematics(np.full((2, 3), np.nan), kinematics.jacobians)
    cases = [
        (
            (np.array([np.nan, 0, 0]), accel, 0.002, kinematics, [1, 1]),
            "angular_velocity_imu_in_imu",
        ),
        ((gyro, [0, np.inf, 9.8], 0.002, kinematics, [1, 1]), "specific_force_imu_in_imu"),
        ((gyro, accel, float("nan"), kinematics, [1, 1]), "dt"),
        ((gyro, accel, -0.01, kinematics, [1, 1]), "dt"),
        ((gyro, accel, 0.002, bad_kinematics, [1, 1]), "kinematics.position_points_in_base"),
        ((gyro, accel, 0.002, kinematics, [1]), "contact_flags"),
        ((gyro[:2], accel, 0.002, kinematics, [1, 1]), "angular_velocity_imu_in_imu"),
    ]
    for args, field in cases:
        with pytest.raises(EstimatorInputError) as info:
            estimator.step(*args)
        assert info.value.field == field
        assert isinstance(info.value, ValueError)
    after = estimator.estimate()
    np.testing.assert_array_equal(after.position_base_in_world, before.position_base_in_world)
    np.testing.assert_array_equal(after.covariance, before.covariance)
    estimator.reset()
    assert not estimator.initialized
    with pytest.raises(EstimatorInputError, match="rotation_imu_to_base"):
        BaseEstimator(["left"], imu_mount=ImuMount(rotation_imu_to_base=2 * np.eye(3)))
    with pytest.raises(EstimatorInputError):
        estimator.estimate()


# -- the equations against finite differences ----------------------------------------------


def _random_state(rng, contacts=2):
    rotation = so3_exp(rng.uniform(-2, 2, 3))
    columns = rng.uniform(-1.5, 1.5, (2 + contacts, 3))
    return rotation, columns


def test_gamma_series_and_group_exp_log_round_trip():
    rng = np.random.default_rng(0)
    for scale in (1e-7, 1e-3, 0.5, 2.5):
        phi = scale * rng.standard_normal(3)
        phi_x = skew(phi)
        for order in (0, 1, 2):
            series = sum(
                np.linalg.matrix_power(phi_x, n) / math.factorial(n + order) for n in range(30)
            )
            np.testing.assert_allclose(so3_gamma(phi, order), series, atol=1e-14)
        xi = np.concatenate([phi, rng.standard_normal(9)])
        np.testing.assert_allclose(sek3_log(*sek3_exp(xi)), xi, atol=1e-10)


def test_right_invariant_error_propagation_matches_the_group_exactly_without_bias_errors():
    """``ξ⁺ = Φ ξ`` for the log of ``X̂⁺ X⁺⁻¹`` (log-linearity, Hartley 2020)."""
    rng = np.random.default_rng(1)
    dt = 0.01
    for _ in range(5):
        rotation, columns = _random_state(rng)
        omega, accel = rng.normal(0, 2, 3), rng.normal(0, 5, 3)
        xi = 0.3 * rng.standard_normal(3 + 3 * len(columns))
        step_r, step_c = sek3_exp(xi)
        rotation_est, columns_est = step_r @ rotation, columns @ step_r.T + step_c
        true_next = propagate_mean(rotation, columns, omega, accel, GRAVITY, dt)
        est_next = propagate_mean(rotation_est, columns_est, omega, accel, GRAVITY, dt)
        rotation_err = est_next[0] @ true_next[0].T
        columns_err = est_next[1] - true_next[1] @ rotation_err.T
        a_matrix, _ = error_dynamics_matrix(rotation_est, columns_est, GRAVITY)
        phi = error_transition_matrix(a_matrix, dt)
        group = np.r_[0:9, 15 : len(phi)]
        np.testing.assert_allclose(
            sek3_log(rotation_err, columns_err), phi[np.ix_(group, group)] @ xi, atol=1e-10
        )


def test_bias_columns_of_the_transition_match_finite_differences():
    """``∂ξ⁺/∂ζ`` against propagating with biases ``b̂ = b + ε ζ``, ``A`` at mid-step."""
    rng = np.random.default_rng(2)
    dt, eps = 0.002, 1e-6
    rotation, columns = _random_state(rng)
    omega, accel = rng.normal(0, 1, 3), rng.normal(0, 5, 3)
    middle = propagate_mean(rotation, columns, omega, accel, GRAVITY, dt / 2)
    a_matrix, _ = error_dynamics_matrix(*middle, GRAVITY)
    phi = error_transition_matrix(a_matrix, dt)
    group = np.r_[0:9, 15 : len(phi)]
    true_next = propagate_mean(rotation, columns, omega, accel, GRAVITY, dt)
    for j in range(6):
        zeta = np.zeros(6)
        zeta[j] = eps
        est_next = propagate_mean(
            rotation, columns, omega - zeta[:3], accel - zeta[3:], GRAVITY, dt
        )
        rotation_err = est_next[0] @ true_next[0].T
        columns_err = est_next[1] - true_next[1] @ rotation_err.T
        derivative = sek3_log(rotation_err, columns_err) / eps
        expected = phi[group, 9 + j]
        np.testing.assert_allclose(derivative, expected, rtol=1e-4, atol=1e-8)


def test_kinematic_innovation_is_linear_in_the_invariant_error():
    """``z(exp(ξ) X, y(X)) = −H ξ`` to first order, ``H`` independent of the state."""
    rng = np.random.default_rng(4)
    eps = 1e-6
    for _ in range(5):
        rotation, columns = _random_state(rng)
        slot = int(rng.integers(0, 2))
        measurement = rotation.T @ (columns[2 + slot] - columns[1])
        xi = rng.standard_normal(3 + 3 * len(columns))
        innovations = []
        for sign in (1.0, -1.0):
            step_r, step_c = sek3_exp(sign * eps * xi)
            innovation, h_matrix = kinematic_innovation(
                step_r @ rotation, columns @ step_r.T + step_c, slot, measurement
            )
            innovations.append(innovation)
        derivative = (innovations[0] - innovations[1]) / (2 * eps)
        group = np.r_[0:9, 15 : h_matrix.shape[1]]
        np.testing.assert_allclose(derivative, -h_matrix[:, group] @ xi, atol=1e-8)
        assert not np.any(h_matrix[:, 9:15])


def test_ground_innovation_is_linear_in_the_invariant_error():
    """The flat-ground row: ``z(exp(ξ) X) = −H ξ`` to first order, for a stance point on z = 0."""
    rng = np.random.default_rng(5)
    eps = 1e-6
    for _ in range(5):
        _, columns = _random_state(rng)
        slot = int(rng.integers(0, 2))
        columns[2 + slot, 2] = 0.0  # the true stance point is on the ground
        innovation, h_row = ground_innovation(columns, slot)
        assert innovation == pytest.approx(0.0, abs=1e-12)
        xi = rng.standard_normal(3 + 3 * len(columns))
        innovations = []
        for sign in (1.0, -1.0):
            step_r, step_c = sek3_exp(sign * eps * xi)
            innovations.append(ground_innovation(columns @ step_r.T + step_c, slot)[0])
        derivative = (innovations[0] - innovations[1]) / (2 * eps)
        group = np.r_[0:9, 15 : h_row.size]
        assert derivative == pytest.approx(-h_row[group] @ xi, abs=1e-8)
        assert not np.any(h_row[3:15])


# -- leg kinematics with Pinocchio ---------------------------------------------------------


def test_leg_kinematics_match_pinocchio_placements_and_finite_differences():
    robot = load_robot_model("revolute_humanoid")
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(5)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    q_joints = q[7:]
    kinematics = robot_leg_kinematics(robot, data, q_joints)
    # Against placements at an arbitrary base pose, expressed in the base frame.
    check = model.createData()
    pin.forwardKinematics(model, check, q)
    pin.updateFramePlacements(model, check)
    base = pin.XYZQUATToSE3(q[:7])
    for k, contact in enumerate(robot.contacts):
        point = np.mean(contact.points_in_frame, axis=0)
        in_world = check.oMf[contact.frame_id].act(point)
        np.testing.assert_allclose(
            kinematics.position_points_in_base[k], base.actInv(in_world), atol=1e-12
        )
    # Jacobians: central differences along the joints' tangent directions.
    h = 1e-6
    for column in rng.choice(model.nv - 6, size=6, replace=False):
        dv = np.zeros(model.nv)
        dv[6 + column] = h
        plus = pin.integrate(model, q, dv)[7:]
        minus = pin.integrate(model, q, -dv)[7:]
        frames = [c.frame_id for c in robot.contacts]
        points = [np.mean(c.points_in_frame, axis=0) for c in robot.contacts]
        p_plus = compute_leg_kinematics(model, data, plus, frames, points).position_points_in_base
        p_minus = compute_leg_kinematics(model, data, minus, frames, points).position_points_in_base
        np.testing.assert_allclose(
            kinematics.jacobians[:, :, column], (p_plus - p_minus) / (2 * h), atol=1e-6
        )


def test_reported_covariance_maps_invariant_errors_to_base_errors():
    """The output covariance is ``T P Tᵀ``; ``T`` against perturbing the filter's state."""
    rng = np.random.default_rng(6)
    estimator = BaseEstimator(["left", "right"], imu_mount=MOUNT)
    truth = base_motion(0.7)
    gyro, accel = exact_imu(0.7, truth=truth)
    kinematics = LegKinematics(
        feet_in_base(0.7, truth=truth), np.repeat(LEG_JACOBIAN[None], 2, axis=0)
    )
    estimator.step(gyro, accel, 0.002, kinematics, [True, True])
    estimator.step(gyro, accel, 0.002, kinematics, [True, True])
    state = (estimator._rotation.copy(), estimator._columns.copy(), estimator._bias.copy())
    base = estimator.estimate()
    dim = len(estimator._covariance)
    eps = 1e-6
    for j in rng.choice(15, size=8, replace=False):
        xi = np.zeros(dim)
        xi[j] = eps
        step_r, step_c = sek3_exp(np.r_[xi[0:9], xi[15:]])
        estimator._rotation = step_r @ state[0]
        estimator._columns = state[1] @ step_r.T + step_c
        estimator._bias = state[2] + xi[9:15]
        moved = estimator.estimate()
        rotation_0 = pin.Quaternion(base.orientation_base_in_world_xyzw).toRotationMatrix()
        rotation_1 = pin.Quaternion(moved.orientation_base_in_world_xyzw).toRotationMatrix()
        difference = np.concatenate(
            [
                so3_log(rotation_1 @ rotation_0.T),
                moved.linear_velocity_base_in_world - base.linear_velocity_base_in_world,
                moved.position_base_in_world - base.position_base_in_world,
                moved.gyro_bias_in_imu - base.gyro_bias_in_imu,
                moved.accel_bias_in_imu - base.accel_bias_in_imu,
            ]
        )
        estimator._covariance = np.zeros((dim, dim))
        estimator._covariance[j, j] = 1.0
        # T e_j e_jᵀ Tᵀ against the outer product of the finite difference (signs included).
        column = difference / eps
        np.testing.assert_allclose(
            estimator.estimate().covariance, np.outer(column, column), atol=1e-4
        )
        estimator._rotation, estimator._columns, estimator._bias = (a.copy() for a in state)
