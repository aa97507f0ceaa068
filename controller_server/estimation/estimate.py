"""The base estimator's settings, output and input error.

Settings: where the IMU sits (:class:`ImuMount`), the noise model (:class:`EstimatorNoise`,
BMI088-class defaults) and the initial uncertainty (:class:`EstimatorPrior`). Output:
:class:`BaseEstimate`, with the covariance for diagnostics. Bad input raises
:class:`EstimatorInputError` naming the field.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from controller_server.errors import EstimatorInputError
from controller_server.estimation.lie import so3_gamma

__all__ = [
    "STANDARD_GRAVITY",
    "BaseEstimate",
    "EstimatorInputError",
    "EstimatorNoise",
    "EstimatorPrior",
    "ImuMount",
    "checked_array",
    "level_rotation",
]

STANDARD_GRAVITY = 9.80665
"""Standard gravity (m/s²); gravity in the world is in the world is ``(0, 0, −g)``."""


@dataclass(frozen=True)
class ImuMount:
    """Where the IMU sits on the base.

    Attributes:
        rotation_imu_to_base: ``R_BI``, the IMU axes in the base frame, ``(3, 3)``.
        position_imu_in_base: ``r_BI``, the IMU origin in the base frame (m), ``(3,)``.
    """

    rotation_imu_to_base: np.ndarray = field(default_factory=lambda: np.eye(3))
    position_imu_in_base: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class EstimatorNoise:
    """Noise model, continuous-time densities (BMI088-class MEMS IMU defaults).

    White-noise densities are the Bosch BMI088 data sheet's output noise densities
    (BST-BMI088-DS001, specifications: gyroscope 0.014 °/s/√Hz, accelerometer 175 µg/√Hz). The
    data sheet gives no bias random walk: the defaults are consumer-MEMS Allan-deviation values
    (a bias drifting ~0.6 °/s and ~0.06 m/s² per hour, 1σ). The simulated IMU's accelerometer
    walks three times faster (EuRoC's 3e-3 m/s³/√Hz), which over a run of seconds moves its
    bias by under 0.01 m/s²; a filter that lets the bias move that fast instead turned the
    contact transients of pushes into bias, and tilt (in MuJoCo's ``head_push`` with the
    prioritized controller, the default IMU seed fell with 3e-3 and stood with 1e-3).

    Attributes:
        gyro_noise_density: rad/s/√Hz.
        accel_noise_density: m/s²/√Hz.
        gyro_bias_random_walk: rad/s²/√Hz.
        accel_bias_random_walk: m/s³/√Hz.
        joint_position_noise: Encoder noise per joint, rad (or m), 1σ.
        contact_position_noise: Kinematic model error of each contact point (link lengths,
            sole compliance), m, 1σ.
        contact_slip_random_walk: Stance contact point velocity noise (slip), m/s/√Hz.
        flat_ground: 1σ (m) of the assumption that stance contact points lie on flat, level
            ground at ``z = 0`` (the ground under the feet at start), or ``None`` for no such
            assumption. It makes the height observable after every foot has been lifted
            and set down again (else heights are relative to where the feet landed, and
            drift); it is wrong on stairs and slopes. Default 5 mm: a soft contact's
            penetration at impact (MuJoCo's, measured).
    """

    gyro_noise_density: float = float(np.deg2rad(0.014))
    accel_noise_density: float = 175e-6 * STANDARD_GRAVITY
    gyro_bias_random_walk: float = 1e-4
    accel_bias_random_walk: float = 1e-3
    joint_position_noise: float = 1e-3
    contact_position_noise: float = 2e-3
    contact_slip_random_walk: float = 3e-3
    flat_ground: float | None = 5e-3


@dataclass(frozen=True)
class EstimatorPrior:
    """Initial 1σ uncertainties (conventional errors, world frame).

    Attributes:
        roll_pitch_rad: Tilt after levelling on the accelerometer (rad).
        yaw_rad: Heading (rad); yaw is a free choice at start (zero or given).
        velocity: m/s (the robot is assumed still at start).
        position: m (horizontal is a free choice; height comes from the feet).
        gyro_bias: rad/s (BMI088 zero-rate offset ±1 °/s, typical: 2–3 °/s occur).
        gyro_bias_at_rest: rad/s, when the filter starts from a gyro reading with the robot
            still (``still_at_start``): the reading is the bias, up to its white noise
            (BMI088 at 1 kHz: 0.44 °/s per sample) and any slight motion.
        still_at_start: The robot stands still when the filter starts, so the first gyro
            reading is its bias. Learning a 2.6 °/s bias from the feet alone took about
            1 s, during which the error reached the controller as a turning of the base
            and the prioritized controller let the robot fold (``head_push``, IMU seed 3).
        accel_bias: m/s² (10 mg: the BMI088's zero-g offset, ±20 mg, after calibration).
    """

    roll_pitch_rad: float = float(np.deg2rad(2.0))
    yaw_rad: float = float(np.deg2rad(0.5))
    velocity: float = 0.05
    position: float = 0.01
    gyro_bias: float = float(np.deg2rad(1.0))
    gyro_bias_at_rest: float = float(np.deg2rad(0.5))
    still_at_start: bool = True
    accel_bias: float = 0.1


@dataclass(frozen=True)
class BaseEstimate:
    """The estimated base state and its uncertainty.

    Attributes:
        position_base_in_world: m.
        orientation_base_in_world_xyzw: Unit quaternion.
        linear_velocity_base_in_world: m/s.
        angular_velocity_base_in_base: Bias-corrected gyro in base axes (rad/s).
        gyro_bias_in_imu: rad/s.
        accel_bias_in_imu: m/s².
        position_contacts_in_world: Stance contact points held by the filter, by name (m).
        covariance: ``(15, 15)`` of ``[δθ_world, δv_base, δp_base, δb_g, δb_a]`` (rotation
            error ``R̂ = exp(δθ) R`` in world axes, so ``δθ_z`` is the yaw error).
    """

    position_base_in_world: np.ndarray
    orientation_base_in_world_xyzw: np.ndarray
    linear_velocity_base_in_world: np.ndarray
    angular_velocity_base_in_base: np.ndarray
    gyro_bias_in_imu: np.ndarray
    accel_bias_in_imu: np.ndarray
    position_contacts_in_world: dict[str, np.ndarray]
    covariance: np.ndarray

    @property
    def standard_deviations(self) -> dict[str, np.ndarray]:
        """1σ of each 3-block of :attr:`covariance`, by name (diagnostics)."""
        sigma = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        names = ("orientation", "linear_velocity", "position", "gyro_bias", "accel_bias")
        return {name: sigma[3 * i : 3 * i + 3] for i, name in enumerate(names)}


def checked_array(value, field_name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """``value`` as a finite float array of ``shape`` (``None``: any size on that axis).

    Raises:
        EstimatorInputError: Not numeric, another shape, or a NaN or infinity in it.
    """
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise EstimatorInputError(field_name, f"not numeric: {value!r}") from None
    if array.ndim != len(shape) or any(
        want is not None and have != want for have, want in zip(array.shape, shape, strict=True)
    ):
        raise EstimatorInputError(field_name, f"shape {array.shape}, expected {shape}")
    if not np.all(np.isfinite(array)):
        raise EstimatorInputError(field_name, f"not finite: {array.tolist()}")
    return array


def level_rotation(specific_force_in_base: np.ndarray) -> np.ndarray:
    """``R_WB`` with zero yaw whose ``R_WBᵀ e_z`` is the measured specific force direction."""
    fx, fy, fz = specific_force_in_base
    roll = np.arctan2(fy, fz)
    pitch = np.arctan2(-fx, np.hypot(fy, fz))
    return so3_gamma(np.array([0.0, pitch, 0.0]), 0) @ so3_gamma(np.array([roll, 0.0, 0.0]), 0)
