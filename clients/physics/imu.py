"""A simulated IMU for either physics backend: gyroscope and accelerometer on a body.

The sensor sees only what every backend offers, :meth:`PhysicsBackend.state`
and ``time_s`` after each physics step, and a Pinocchio model of the same
MJCF file, so the reference simulator and MuJoCo get the same sensor.

**Truth.** Over a physics step ``[t_k, t_k+1]`` both backends integrate by
semi-implicit Euler: ``v_k+1 = v_k + Δt a_k``, then ``q_k+1 = q_k ⊕ Δt v_k+1``.
The sensor therefore takes, for that step,

* angular velocity: the IMU frame's angular velocity at ``(q_k+1, v_k+1)``,
  in the IMU frame (for an IMU on the root body that is exactly the constant
  body rate that turned the base from ``R_k`` to ``R_k+1``);
* specific force (what an accelerometer measures, ``a − g``; +9.81 m/s²
  upward at rest):
  ``f = ½ (R_k + R_k+1)ᵀ ((ṗ_k+1 − ṗ_k) / Δt − g)``, with ``ṗ`` the world
  velocity of the IMU point and ``R`` the IMU's orientation in world. The
  finite difference is the backend's own acceleration over the step (no
  second dynamics model to disagree with it, contact forces included); it
  matches Pinocchio's classical acceleration of the point to ``O(Δt)``
  (``tests/clients/test_simulated_imu.py`` checks this, and that the error
  halves with ``Δt``). The mean of the two rotations is the trapezoidal
  average of ``Rᵀ`` over the step.

A sample covers the physics steps since the previous one: its truth is the
time average of the per-step values (a box-car decimation, as a sensor
averages internally), stamped with the time of the last step. A sample is
due every ``1 / rate_hz`` from :meth:`SimulatedImu.reset`; when the physics
step does not divide that period, each sample is taken at the first step
at or after it is due.

**Errors** (the Kalibr / VIO noise model, e.g. Furgale et al. 2013; Kalibr
wiki "IMU Noise Model"): per axis, ``measured = truth + bias + n``, with
white noise ``n ~ N(0, (σ √rate_hz)²)`` from the noise density ``σ``, and a
bias that starts at a seeded draw within the datasheet's typical offset and
then walks, ``b ← b + σ_b √Δt ξ`` per sample. The on-chip low-pass filter is
not modelled: samples are independent, so the noise is that of the density
over the full Nyquist band (more than the datasheet RMS at its filter
bandwidth, i.e. conservative). Scale-factor errors, axis misalignment,
g-sensitivity, quantization and saturation are not modelled.

**Defaults** are the Bosch Sensortec BMI088 (data sheet BST-BMI088-DS001,
section 1 "Specification", accelerometer and gyroscope tables, typical
values at 25 °C): gyroscope output noise density 0.014 °/s/√Hz, zero-rate
offset ±1 °/s; accelerometer output noise density 175 µg/√Hz, zero-g offset
±20 mg (https://www.bosch-sensortec.com/media/boschsensortec/downloads/
datasheets/bst-bmi088-ds001.pdf). The data sheet gives no bias random walk;
the defaults are the Kalibr values of the EuRoC MAV data set's MEMS IMU
(ADIS16448), which OpenVINS ships as its example
(https://github.com/rpng/open_vins, ``config/euroc_mav/kalibr_imu_chain.yaml``):
gyroscope 1.9393e-5 rad/s²/√Hz, accelerometer 3.0e-3 m/s³/√Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from clients.physics.model_file import body_names, describe_model, resolve_model_path
from clients.physics.reference import BodyNotFound
from clients.state import RobotState
from protocol.messages import ImuSample

__all__ = [
    "BMI088_ACCEL_NOISE_DENSITY_M_PER_S2_SQRT_HZ",
    "BMI088_ACCEL_ZERO_G_OFFSET_M_PER_S2",
    "BMI088_GYRO_NOISE_DENSITY_RAD_PER_S_SQRT_HZ",
    "BMI088_GYRO_ZERO_RATE_OFFSET_RAD_PER_S",
    "IMU_FRAME_NAME",
    "BodyNotFound",
    "ImuReading",
    "ImuSpec",
    "SimulatedImu",
    "add_imu_frame",
]

STANDARD_GRAVITY_M_PER_S2 = 9.80665
"""The unit g of the data sheet's µg and mg."""

BMI088_GYRO_NOISE_DENSITY_RAD_PER_S_SQRT_HZ = math.radians(0.014)
"""BMI088 gyroscope output noise density, 0.014 °/s/√Hz (typ.) = 2.443e-4 rad/s/√Hz."""
BMI088_GYRO_ZERO_RATE_OFFSET_RAD_PER_S = math.radians(1.0)
"""BMI088 gyroscope zero-rate offset, ±1 °/s (typ.) = 1.745e-2 rad/s."""
BMI088_ACCEL_NOISE_DENSITY_M_PER_S2_SQRT_HZ = 175e-6 * STANDARD_GRAVITY_M_PER_S2
"""BMI088 accelerometer output noise density, 175 µg/√Hz (typ.) = 1.716e-3 m/s²/√Hz."""
BMI088_ACCEL_ZERO_G_OFFSET_M_PER_S2 = 20e-3 * STANDARD_GRAVITY_M_PER_S2
"""BMI088 accelerometer zero-g offset, ±20 mg (typ.) = 0.196 m/s²."""

IMU_FRAME_NAME = "imu"
"""Name of the operational frame :func:`add_imu_frame` adds to a Pinocchio model."""

_Vector3 = tuple[float, float, float]


class ImuSpec(BaseModel):
    """Where the IMU sits and how it errs (a scenario's ``imu`` table).

    Defaults: a Bosch BMI088 at the root body's origin, axes along the
    body's, sampled at 1 kHz (see the module docstring for the sources).
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    body: str = Field(
        default="",
        description="MJCF body the IMU is fixed to; empty: the root (floating-base) body.",
    )
    position_in_body_m: _Vector3 = Field(
        default=(0.0, 0.0, 0.0), description="IMU origin in the body frame (m)."
    )
    orientation_in_body_xyzw: tuple[float, float, float, float] = Field(
        default=(0.0, 0.0, 0.0, 1.0),
        description="IMU axes in the body frame, quaternion x y z w (normalised on load).",
    )
    rate_hz: float = Field(
        default=1000.0,
        gt=0.0,
        le=100_000.0,
        description="Output rate (Hz); at most the physics rate. The BMI088 gyroscope offers "
        "100–2000 Hz, its accelerometer 12.5–1600 Hz.",
    )
    gyro_noise_density_rad_per_s_sqrt_hz: float = Field(
        default=BMI088_GYRO_NOISE_DENSITY_RAD_PER_S_SQRT_HZ,
        ge=0.0,
        description="Gyroscope white noise density (rad/s/√Hz); per-sample std is this × "
        "√rate_hz. Default: BMI088 data sheet (BST-BMI088-DS001, section 1, gyroscope "
        "table), output noise density 0.014 °/s/√Hz.",
    )
    accel_noise_density_m_per_s2_sqrt_hz: float = Field(
        default=BMI088_ACCEL_NOISE_DENSITY_M_PER_S2_SQRT_HZ,
        ge=0.0,
        description="Accelerometer white noise density (m/s²/√Hz); per-sample std is this × "
        "√rate_hz. Default: BMI088 data sheet (BST-BMI088-DS001, section 1, accelerometer "
        "table), output noise density 175 µg/√Hz.",
    )
    gyro_bias_random_walk_rad_per_s2_sqrt_hz: float = Field(
        default=1.9393e-5,
        ge=0.0,
        description="Gyroscope bias random walk (rad/s²/√Hz). Not in the BMI088 data sheet: "
        "the Kalibr value of the EuRoC MAV MEMS IMU (OpenVINS "
        "config/euroc_mav/kalibr_imu_chain.yaml).",
    )
    accel_bias_random_walk_m_per_s3_sqrt_hz: float = Field(
        default=3.0e-3,
        ge=0.0,
        description="Accelerometer bias random walk (m/s³/√Hz). Not in the BMI088 data sheet: "
        "the Kalibr value of the EuRoC MAV MEMS IMU (OpenVINS "
        "config/euroc_mav/kalibr_imu_chain.yaml).",
    )
    gyro_initial_bias_std_rad_per_s: float = Field(
        default=BMI088_GYRO_ZERO_RATE_OFFSET_RAD_PER_S,
        ge=0.0,
        description="Std per axis of the seeded initial gyroscope bias (rad/s). Default: the "
        "BMI088 zero-rate offset, ±1 °/s typ. (data sheet, gyroscope table).",
    )
    accel_initial_bias_std_m_per_s2: float = Field(
        default=BMI088_ACCEL_ZERO_G_OFFSET_M_PER_S2,
        ge=0.0,
        description="Std per axis of the seeded initial accelerometer bias (m/s²). Default: "
        "the BMI088 zero-g offset, ±20 mg typ. (data sheet, accelerometer table).",
    )
    gyro_initial_bias_rad_per_s: _Vector3 | None = Field(
        default=None,
        description="Initial gyroscope bias in the IMU frame (rad/s), instead of a draw.",
    )
    accel_initial_bias_m_per_s2: _Vector3 | None = Field(
        default=None,
        description="Initial accelerometer bias in the IMU frame (m/s²), instead of a draw.",
    )
    orientation_output: bool = Field(
        default=True,
        description="Whether the sensor also outputs its orientation from an onboard filter "
        "(an AHRS; the BMI088 alone has none). It is the truth turned by a fixed tilt error.",
    )
    orientation_tilt_error_rad: float = Field(
        default=math.radians(0.5),
        ge=0.0,
        le=math.radians(45.0),
        description="RMS tilt (roll/pitch) error of that orientation (rad), drawn once per "
        "reset. Default: 0.5°, the static roll/pitch accuracy of the Xsens MTi (MTi and MTx "
        "User Manual MT0100P, section 4.2).",
    )
    seed: int = Field(default=0, ge=0, description="Seed of the noise and bias draws.")

    @field_validator("orientation_in_body_xyzw")
    @classmethod
    def _unit_quaternion(
        cls, value: tuple[float, float, float, float]
    ) -> tuple[float, float, float, float]:
        norm = math.sqrt(sum(c * c for c in value))
        if not (math.isfinite(norm) and norm > 1e-9):
            raise ValueError(f"a rotation needs a non-zero finite quaternion, got {value}")
        x, y, z, w = (c / norm for c in value)
        return (x, y, z, w)

    @model_validator(mode="after")
    def _one_initial_bias(self) -> ImuSpec:
        for bias, std in (
            ("gyro_initial_bias_rad_per_s", "gyro_initial_bias_std_rad_per_s"),
            ("accel_initial_bias_m_per_s2", "accel_initial_bias_std_m_per_s2"),
        ):
            if bias in self.model_fields_set and std in self.model_fields_set:
                raise ValueError(f"give {bias} (a fixed bias) or {std} (a draw), not both")
        return self

    @classmethod
    def ideal(cls, **fields: object) -> ImuSpec:
        """A spec without noise or bias (the truth), with ``fields`` set on top.

        E.g. ``ImuSpec.ideal(accel_initial_bias_m_per_s2=(0.1, 0, 0))``: a
        fixed bias and nothing else.
        """
        perfect: dict[str, object] = {
            "gyro_noise_density_rad_per_s_sqrt_hz": 0.0,
            "accel_noise_density_m_per_s2_sqrt_hz": 0.0,
            "gyro_bias_random_walk_rad_per_s2_sqrt_hz": 0.0,
            "accel_bias_random_walk_m_per_s3_sqrt_hz": 0.0,
            "gyro_initial_bias_std_rad_per_s": 0.0,
            "accel_initial_bias_std_m_per_s2": 0.0,
            "orientation_tilt_error_rad": 0.0,
        }
        for bias, std in (
            ("gyro_initial_bias_rad_per_s", "gyro_initial_bias_std_rad_per_s"),
            ("accel_initial_bias_m_per_s2", "accel_initial_bias_std_m_per_s2"),
        ):
            if bias in fields:
                del perfect[std]
        perfect.update(fields)
        return cls.model_validate(perfect)

    @property
    def gyro_noise_std_rad_per_s(self) -> float:
        """Per-sample std of the gyroscope white noise, density × √rate (rad/s)."""
        return self.gyro_noise_density_rad_per_s_sqrt_hz * math.sqrt(self.rate_hz)

    @property
    def accel_noise_std_m_per_s2(self) -> float:
        """Per-sample std of the accelerometer white noise, density × √rate (m/s²)."""
        return self.accel_noise_density_m_per_s2_sqrt_hz * math.sqrt(self.rate_hz)


@dataclass(frozen=True)
class ImuReading:
    """One IMU sample: what the sensor outputs, and the truth behind it.

    Only ``time_s``, ``angular_velocity_imu_in_imu``,
    ``linear_acceleration_imu_in_imu`` and ``orientation_imu_in_world_xyzw``
    are what a real IMU gives; the
    ``true_*`` fields are simulator ground truth for tests and for grading
    an estimator, never for feeding it.

    Attributes:
        time_s: Simulation time of the sample (end of the steps it covers) (s).
        angular_velocity_imu_in_imu: Gyroscope output, IMU axes (rad/s).
        linear_acceleration_imu_in_imu: Accelerometer output: specific force
            ``a − g`` of the IMU point, IMU axes (m/s²; +9.81 up at rest).
        orientation_imu_in_world_xyzw: The onboard filter's orientation output
            (``None`` without ``orientation_output``).
        true_angular_velocity_imu_in_imu: The gyroscope's truth, averaged
            over the sample (rad/s).
        true_linear_acceleration_imu_in_imu: The accelerometer's truth,
            averaged over the sample (m/s²).
        true_angular_velocity_bias_in_imu: Gyroscope bias in this sample (rad/s).
        true_linear_acceleration_bias_in_imu: Accelerometer bias in this sample (m/s²).
        true_orientation_imu_in_world_xyzw: IMU axes in world at ``time_s``.
        true_position_imu_in_world: IMU origin in world at ``time_s`` (m).
        true_linear_velocity_imu_in_world: IMU origin's velocity at ``time_s``,
            world axes (m/s).
    """

    time_s: float
    angular_velocity_imu_in_imu: np.ndarray
    linear_acceleration_imu_in_imu: np.ndarray
    orientation_imu_in_world_xyzw: np.ndarray | None
    true_angular_velocity_imu_in_imu: np.ndarray
    true_linear_acceleration_imu_in_imu: np.ndarray
    true_angular_velocity_bias_in_imu: np.ndarray
    true_linear_acceleration_bias_in_imu: np.ndarray
    true_orientation_imu_in_world_xyzw: np.ndarray
    true_position_imu_in_world: np.ndarray
    true_linear_velocity_imu_in_world: np.ndarray

    def to_sample(self) -> ImuSample:
        """The wire's ``state.imu``: what the sensor outputs (no truth), unvalidated."""
        return ImuSample.model_construct(
            angular_velocity_imu_in_imu=self.angular_velocity_imu_in_imu,
            linear_acceleration_imu_in_imu=self.linear_acceleration_imu_in_imu,
            orientation_imu_in_world_xyzw=self.orientation_imu_in_world_xyzw,
        )


def add_imu_frame(model: pin.Model, spec: ImuSpec, path: str | Path) -> int:
    """Add the IMU's operational frame (:data:`IMU_FRAME_NAME`) to ``model``.

    Args:
        model: Pinocchio model of the MJCF at ``path`` (modified in place).
        spec: Where the IMU sits.
        path: The MJCF file (its first body is the root, used when
            ``spec.body`` is empty).

    Returns:
        The new frame's index.

    Raises:
        BodyNotFound: ``spec.body`` is not a body of the model.
    """
    bodies = body_names(str(path))
    name = spec.body or (bodies[0] if bodies else "")
    frames = [
        index
        for index, frame in enumerate(model.frames)
        if frame.type == pin.FrameType.BODY and frame.name == name
    ]
    if not frames:
        raise BodyNotFound(name, bodies)
    body = model.frames[frames[0]]
    mount = pin.SE3(
        pin.Quaternion(np.array(spec.orientation_in_body_xyzw)).toRotationMatrix(),
        np.array(spec.position_in_body_m, dtype=float),
    )
    return model.addFrame(
        pin.Frame(
            IMU_FRAME_NAME,
            body.parentJoint,
            frames[0],
            body.placement * mount,
            pin.FrameType.OP_FRAME,
        )
    )


class SimulatedImu:
    """An IMU fixed to a body of the simulated robot, fed after every physics step.

    Usage: ``imu.reset(backend.state(), backend.time_s)`` after the
    backend's reset, then ``imu.update(backend.state(), backend.time_s)``
    after each ``backend.step``; :meth:`reading` is the newest sample.

    Args:
        spec: Mounting, rate and error model.
        model_path: The MJCF the backend simulates (built-in name or path).
        gravity_in_world_m_per_s2: The backend's gravity; default the MJCF
            ``<option gravity>`` (both backends use −9.81 m/s² along z for the
            built-ins).

    Raises:
        BodyNotFound: ``spec.body`` names no body of the model.
        FileNotFoundError: No such model.
    """

    def __init__(
        self,
        spec: ImuSpec,
        model_path: str | Path,
        gravity_in_world_m_per_s2: tuple[float, float, float] | None = None,
    ):
        self.spec = spec
        self.path = resolve_model_path(str(model_path))
        self._model = pin.Model(describe_model(str(model_path)).model)
        self.frame_id = add_imu_frame(self._model, spec, str(model_path))
        self._data = self._model.createData()
        frame = self._model.frames[self.frame_id]
        self.body_name = self._model.frames[frame.parentFrame].name
        self.gravity_in_world_m_per_s2 = (
            np.array(self._model.gravity.linear)
            if gravity_in_world_m_per_s2 is None
            else np.asarray(gravity_in_world_m_per_s2, dtype=float).reshape(3)
        )
        self.period_s = 1.0 / spec.rate_hz
        self._noise_std = np.repeat(
            [spec.gyro_noise_std_rad_per_s, spec.accel_noise_std_m_per_s2], 3
        )
        self._walk_density = np.repeat(
            [
                spec.gyro_bias_random_walk_rad_per_s2_sqrt_hz,
                spec.accel_bias_random_walk_m_per_s3_sqrt_hz,
            ],
            3,
        )
        self._started = False
        self._reading: ImuReading | None = None

    # ----------------------------------------------------------------- mounting

    @property
    def transform_imu_to_body(self) -> pin.SE3:
        """The IMU frame in its body's frame (from the spec)."""
        return pin.SE3(
            pin.Quaternion(np.array(self.spec.orientation_in_body_xyzw)).toRotationMatrix(),
            np.array(self.spec.position_in_body_m, dtype=float),
        )

    @property
    def pinocchio_model(self) -> pin.Model:
        """The sensor's Pinocchio model, with the IMU frame added (do not modify)."""
        return self._model

    # -------------------------------------------------------------- the stream

    def reset(self, state: RobotState, time_s: float = 0.0) -> None:
        """Start over at ``state``: re-seed, draw the initial biases, drop the samples.

        The sensor outputs one sample at once, of ``state`` at rest (zero acceleration;
        :meth:`reading`), so that a client has a reading for its first state. The next
        sample is due ``1 / rate_hz`` after ``time_s``.
        """
        spec = self.spec
        self._rng = np.random.default_rng(spec.seed)
        self._gyro_bias = (
            np.array(spec.gyro_initial_bias_rad_per_s, dtype=float)
            if spec.gyro_initial_bias_rad_per_s is not None
            else spec.gyro_initial_bias_std_rad_per_s * self._rng.standard_normal(3)
        )
        self._accel_bias = (
            np.array(spec.accel_initial_bias_m_per_s2, dtype=float)
            if spec.accel_initial_bias_m_per_s2 is not None
            else spec.accel_initial_bias_std_m_per_s2 * self._rng.standard_normal(3)
        )
        # The onboard filter's fixed tilt error: its own stream, so the noise stays as it was.
        tilt = np.random.default_rng((spec.seed, 1)).standard_normal(2)
        tilt *= spec.orientation_tilt_error_rad / math.sqrt(2.0)
        self._orientation_error = pin.exp3(np.array([tilt[0], tilt[1], 0.0]))
        self._time_s = float(time_s)
        self._start_s = float(time_s)
        self._samples = 0
        self._kinematics = self._frame_kinematics(state)
        rotation, _, _, angular_velocity = self._kinematics
        self._window_s = 1.0  # the sample at rest: its averages are the values now
        self._angular_sum = angular_velocity.copy()
        self._specific_force_sum = -rotation.T @ self.gravity_in_world_m_per_s2
        self._reading = self._sample()
        self._started = True

    def update(self, state: RobotState, time_s: float) -> ImuReading | None:
        """Account for the physics step that ended at ``time_s`` in ``state``.

        Returns:
            The new sample if one fell due at this step, else None.

        Raises:
            RuntimeError: Called before :meth:`reset`.
            ValueError: ``time_s`` does not advance, or advances by more
                than the IMU period (``rate_hz`` above the physics rate).
        """
        if not self._started:
            raise RuntimeError("call SimulatedImu.reset(state, time_s) after the backend's reset")
        step_s = float(time_s) - self._time_s
        if not step_s > 0.0:
            raise ValueError(
                f"time_s must advance: {time_s=} after {self._time_s}; after a backend reset, "
                "reset the IMU too"
            )
        if step_s > self.period_s * (1.0 + 1e-9):
            raise ValueError(
                f"a physics step of {step_s} s is longer than the IMU period {self.period_s} s: "
                f"rate_hz ({self.spec.rate_hz}) must not exceed the physics rate"
            )
        rotation_before, _, velocity_before, _ = self._kinematics
        self._kinematics = self._frame_kinematics(state)
        rotation, _, velocity, angular_velocity = self._kinematics
        acceleration = (velocity - velocity_before) / step_s
        # Trapezoidal mean of Rᵀ over the step: the accelerometer integrates in moving axes.
        specific_force = (
            0.5 * (rotation_before + rotation).T @ (acceleration - self.gravity_in_world_m_per_s2)
        )
        self._time_s = float(time_s)
        self._window_s += step_s
        self._angular_sum += step_s * angular_velocity
        self._specific_force_sum += step_s * specific_force
        due_s = self._start_s + (self._samples + 1) * self.period_s
        if self._time_s < due_s - 1e-9 * self.period_s - 1e-12:
            return None
        self._samples += 1
        self._reading = self._sample()
        return self._reading

    def reading(self) -> ImuReading | None:
        """The newest sample, or None before the first."""
        return self._reading

    @property
    def true_orientation_imu_in_world_xyzw(self) -> np.ndarray:
        """IMU axes in world after the last update (truth)."""
        return pin.Quaternion(self._kinematics[0]).coeffs().copy()

    # --------------------------------------------------------------- internals

    def _frame_kinematics(
        self, state: RobotState
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """IMU rotation in world, position, point velocity (world) and angular velocity (IMU)."""
        model, data = self._model, self._data
        quaternion = np.asarray(state.orientation_base_in_world_xyzw, dtype=float)
        quaternion = quaternion / np.linalg.norm(quaternion)
        q = np.concatenate(
            [
                np.asarray(state.position_base_in_world, dtype=float),
                quaternion,
                np.asarray(state.joint_position, dtype=float),
            ]
        )
        base_rotation = pin.Quaternion(quaternion).toRotationMatrix()
        v = np.concatenate(
            [
                base_rotation.T @ np.asarray(state.linear_velocity_base_in_world, dtype=float),
                np.asarray(state.angular_velocity_base_in_base, dtype=float),
                np.asarray(state.joint_velocity, dtype=float),
            ]
        )
        if q.size != model.nq or v.size != model.nv:
            raise ValueError(
                f"the state has {q.size} coordinates and {v.size} velocities, the model "
                f"{self.path.name} {model.nq} and {model.nv}"
            )
        pin.forwardKinematics(model, data, q, v)
        placement = pin.updateFramePlacement(model, data, self.frame_id)
        rotation = placement.rotation.copy()
        velocity = pin.getFrameVelocity(model, data, self.frame_id, pin.LOCAL_WORLD_ALIGNED)
        return (
            rotation,
            placement.translation.copy(),
            velocity.linear.copy(),
            rotation.T @ velocity.angular,
        )

    def _sample(self) -> ImuReading:
        """Average the window, add noise and bias, walk the biases; start a new window."""
        window_s = self._window_s
        true_angular = self._angular_sum / window_s
        true_specific_force = self._specific_force_sum / window_s
        gyro_bias, accel_bias = self._gyro_bias.copy(), self._accel_bias.copy()
        # One draw per sample, in a fixed order (gyro noise, accel noise, gyro
        # walk, accel walk): the same seed gives the same run.
        draws = self._rng.standard_normal(12)
        draws[:6] *= self._noise_std
        draws[6:] *= self._walk_density * math.sqrt(window_s)
        self._gyro_bias += draws[6:9]
        self._accel_bias += draws[9:]
        gyro_noise, accel_noise = draws[:3], draws[3:6]
        self._window_s = 0.0
        self._angular_sum = np.zeros(3)
        self._specific_force_sum = np.zeros(3)
        rotation, position, velocity, _ = self._kinematics
        orientation = None
        if self.spec.orientation_output:
            orientation = pin.Quaternion(self._orientation_error @ rotation).coeffs().copy()
        return ImuReading(
            time_s=self._time_s,
            angular_velocity_imu_in_imu=true_angular + gyro_bias + gyro_noise,
            linear_acceleration_imu_in_imu=true_specific_force + accel_bias + accel_noise,
            orientation_imu_in_world_xyzw=orientation,
            true_angular_velocity_imu_in_imu=true_angular,
            true_linear_acceleration_imu_in_imu=true_specific_force,
            true_angular_velocity_bias_in_imu=gyro_bias,
            true_linear_acceleration_bias_in_imu=accel_bias,
            true_orientation_imu_in_world_xyzw=pin.Quaternion(rotation).coeffs().copy(),
            true_position_imu_in_world=position,
            true_linear_velocity_imu_in_world=velocity,
        )
