"""A session's base state from the ``imu`` block of its states (server side).

A client without motion capture sends, instead of the base pose and twist, the IMU
reading of the instant (``state.imu``) with its joints and contact flags. Per session,
:class:`ImuBaseEstimator` runs the contact-aided invariant EKF
(:class:`~controller_server.estimation.BaseEstimator`, Hartley et al. 2020) on them:
propagation over the time since the previous state, the stance feet's kinematics
(Pinocchio, the session's own model and contacts) as measurements. The IMU's mount comes
from ``hello`` (``imu_frame`` and offset) and must be rigid on the root body.

Start: the first ``imu`` state (and the first after a restart) initialises the filter,
the robot standing on at least one flagged foot: orientation from the IMU's own filter
when the sample carries one (prior roll/pitch σ :data:`AHRS_TILT_PRIOR_RAD`), else levelled
on the accelerometer with yaw zero (prior σ 2°, a BMI088's zero-g offset is up to 1.1°
of tilt); the gyro bias from the first gyro reading (the robot still); height from the
lowest stance foot at ``z = 0``, ``x = y = 0``. Each foot is measured at its sole corners
on the ground (:func:`grounded_leg_kinematics`), and re-added to the filter when they
change. A gap between states longer than :data:`MAX_STATE_GAP_S` cannot be integrated:
the filter restarts at the next state, and the state of the gap is answered with an error.

Kernel: each call names the kernel that runs it, the session's controller's ``kernel``
parameter in force (``"python"``: this module, the specification; ``"compiled"``: the same
tick in C++, :class:`~.compiled_estimator.CompiledImuBaseEstimator`). The filter's state
follows the kernel from call to call.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from controller_server.dynamics import KERNELS
from controller_server.errors import EstimatorInputError, ImuFrameError
from controller_server.estimation.base_estimator import BaseEstimator
from controller_server.estimation.compiled_estimator import CompiledImuBaseEstimator
from controller_server.estimation.estimate import BaseEstimate, EstimatorPrior, ImuMount
from controller_server.estimation.leg_kinematics import grounded_leg_kinematics
from controller_server.models import RobotModel
from protocol.errors import did_you_mean
from protocol.messages import Hello, State

__all__ = ["AHRS_TILT_PRIOR_RAD", "MAX_STATE_GAP_S", "ImuBaseEstimator", "imu_mount"]

MAX_STATE_GAP_S = 0.05
"""Longest time between two ``imu`` states the filter integrates (s); longer restarts it."""
AHRS_TILT_PRIOR_RAD = float(np.deg2rad(0.5))
"""Roll/pitch 1σ of an orientation from the IMU's own filter (AHRS data sheets give
0.2–0.5° static roll/pitch accuracy)."""

_WIRE_FIELDS = {
    "angular_velocity_imu_in_imu": "imu.angular_velocity_imu_in_imu",
    "specific_force_imu_in_imu": "imu.linear_acceleration_imu_in_imu",
    "orientation_base_in_world_xyzw": "imu.orientation_imu_in_world_xyzw",
    "dt": "time_s",
    "kinematics.position_points_in_base": "joint_position",
    "kinematics.jacobians": "joint_position",
}
"""The estimator's input names → the ``state`` fields they come from."""


def imu_mount(robot: RobotModel, hello: Hello) -> ImuMount:
    """Where the IMU sits on the base, from ``hello``'s frame and offset.

    Raises:
        ImuFrameError: The frame is unknown (the message suggests the closest) or moves
            relative to the root body.
    """
    model = robot.model
    offset = pin.SE3(
        pin.Quaternion(np.array(hello.imu_orientation_in_frame_xyzw, dtype=float))
        .normalized()
        .toRotationMatrix(),
        np.array(hello.imu_position_in_frame, dtype=float),
    )
    if hello.imu_frame is None:
        return ImuMount(offset.rotation, offset.translation)
    names = [frame.name for frame in model.frames if frame.name not in ("universe", "root_joint")]
    if hello.imu_frame not in names:
        hint = did_you_mean(hello.imu_frame, names)
        raise ImuFrameError(
            "imu_frame",
            f"{robot.name} has no frame {hello.imu_frame!r}; {hint}frames on the root body: "
            + ", ".join(f.name for f in model.frames if f.parentJoint == 1),
        )
    frame = model.frames[model.getFrameId(hello.imu_frame)]
    if frame.parentJoint != 1:
        raise ImuFrameError(
            "imu_frame",
            f"frame {hello.imu_frame!r} moves relative to the root body (joint "
            f"{model.names[frame.parentJoint]!r} between them): mount the IMU on the root body",
        )
    mount = frame.placement * offset
    return ImuMount(mount.rotation.copy(), mount.translation.copy())


class ImuBaseEstimator:
    """One session's base estimator: ``state.imu`` + joints + contacts → base estimate.

    Call it with each state carrying ``imu`` (joints and contact flags already checked
    against the robot); errors leave the filter as it was, except a gap (see the module).
    """

    def __init__(self, robot: RobotModel, hello: Hello):
        """Set up the filter for ``robot`` with the IMU mount of ``hello``.

        Raises:
            ImuFrameError: See :func:`imu_mount`.
        """
        self.robot = robot
        self._data = robot.model.createData()
        self.mount = imu_mount(robot, hello)
        self.estimator = BaseEstimator(
            [contact.name for contact in robot.contacts],
            imu_mount=self.mount,
            max_time_step_s=MAX_STATE_GAP_S,
        )
        self._level_prior = self.estimator.prior
        self._ahrs_prior = EstimatorPrior(roll_pitch_rad=AHRS_TILT_PRIOR_RAD)
        self._time_s = 0.0
        self._corners: list[tuple[int, ...]] = []
        self._kernel = "python"  # the side holding the filter's state
        self._compiled: CompiledImuBaseEstimator | None = None

    def __call__(self, state: State, kernel: str = "python") -> BaseEstimate:
        """The base estimate at ``state.time_s``.

        Args:
            state: A state carrying ``imu``.
            kernel: ``"python"``: this module's filter, the specification; ``"compiled"``:
                the same tick in C++ (:class:`CompiledImuBaseEstimator`, created at its first
                tick). The session passes its controller's ``kernel`` parameter in force, per
                call; when it differs from the previous call's, the filter's state (and the
                time and corners of the previous state) is handed over, so a change of kernel
                does not restart the filter.

        Raises:
            EstimatorInputError: Naming the ``state`` field: time not advancing or a gap
                (then the filter restarts at the next state), no foot in stance at the
                start, or a reading the filter refuses.
            CompiledCoreUnavailable: ``kernel`` is ``"compiled"`` and the core is not built
                (or was built for another Pinocchio).
            ValueError: An unknown ``kernel``.
        """
        if kernel != self._kernel:
            self._hand_over(kernel)
        try:
            if kernel == "compiled":
                assert self._compiled is not None  # made by the hand-over
                return self._compiled(state)
            return self._step(state)
        except EstimatorInputError as error:
            field = _WIRE_FIELDS.get(error.field, error.field)
            raise EstimatorInputError(field, error.detail) from None

    def _step(self, state: State) -> BaseEstimate:
        """The tick by this module's filter (the specification), with the filter's field names."""
        imu = state.imu
        assert imu is not None
        joint_position = pin.normalize(
            self.robot.model, np.concatenate([[0, 0, 0, 0, 0, 0, 1.0], state.joint_position])
        )[7:]
        estimator = self.estimator
        kinematics, corners = grounded_leg_kinematics(
            self.robot,
            self._data,
            joint_position,
            estimator.rotation_base_in_world,
            self._corners if estimator.initialized else (),
        )
        if not estimator.initialized:
            self._initialize(state, kinematics)
            estimate = estimator.estimate()
        else:
            dt = state.time_s - self._time_s
            if dt > MAX_STATE_GAP_S:
                estimator.reset()
                raise EstimatorInputError(
                    "dt",
                    f"{dt * 1e3:.0f} ms since the previous state, more than "
                    f"{MAX_STATE_GAP_S * 1e3:.0f} ms: the base estimator restarts at the "
                    "next state (the robot should then stand still on its flagged feet)",
                )
            if not dt > 0:
                raise EstimatorInputError(
                    "dt", f"time_s {state.time_s} does not advance from {self._time_s}"
                )
            # A foot whose corners on the ground changed stands on another point now.
            estimator.forget_contacts(
                [k for k, used in enumerate(corners) if used != self._corners[k]]
            )
            estimate = estimator.step(
                imu.angular_velocity_imu_in_imu,
                imu.linear_acceleration_imu_in_imu,
                dt,
                kinematics,
                state.contact_flags,
            )
        self._time_s = state.time_s
        self._corners = corners
        return estimate

    def _hand_over(self, kernel: str) -> None:
        """Move the filter's state to ``kernel``'s side (the other side's goes stale)."""
        if kernel not in KERNELS:
            raise ValueError(f"{kernel=} is not one of {', '.join(KERNELS)}")
        estimator = self.estimator
        if kernel == "compiled":
            if self._compiled is None:
                self._compiled = CompiledImuBaseEstimator(
                    self.robot,
                    self.mount,
                    estimator.noise,
                    self._level_prior,
                    self._ahrs_prior,
                    gravity=-float(estimator._gravity[2]),
                    max_state_gap_s=MAX_STATE_GAP_S,
                )
            self._compiled.set_state(
                {
                    "rotation": estimator._rotation,
                    "columns": estimator._columns,
                    "bias": estimator._bias,
                    "covariance": estimator._covariance,
                    "stance": list(estimator._stance),
                    "gyro_reading": estimator._gyro_reading,
                    "initialized": estimator.initialized,
                    "time_s": self._time_s,
                    "corners": list(self._corners),
                }
            )
        else:
            assert self._compiled is not None  # the compiled side held the state
            values = self._compiled.state()
            estimator._rotation = values["rotation"]
            estimator._columns = values["columns"]
            estimator._bias = values["bias"]
            estimator._covariance = values["covariance"]
            estimator._stance = list(values["stance"])
            estimator._gyro_reading = values["gyro_reading"]
            estimator.initialized = values["initialized"]
            self._time_s = values["time_s"]
            self._corners = list(values["corners"])
        self._kernel = kernel

    def _initialize(self, state: State, kinematics) -> None:
        imu = state.imu
        assert imu is not None
        estimator = self.estimator
        if imu.orientation_imu_in_world_xyzw is None:
            estimator.prior = self._level_prior
            estimator.initialize(
                kinematics,
                state.contact_flags,
                specific_force_imu_in_imu=imu.linear_acceleration_imu_in_imu,
                angular_velocity_imu_in_imu=imu.angular_velocity_imu_in_imu,
            )
            return
        rotation_imu = pin.Quaternion(imu.orientation_imu_in_world_xyzw).normalized()
        rotation_base = rotation_imu.toRotationMatrix() @ self.mount.rotation_imu_to_base.T
        estimator.prior = self._ahrs_prior
        estimator.initialize(
            kinematics,
            state.contact_flags,
            orientation_base_in_world_xyzw=pin.Quaternion(rotation_base).coeffs(),
            angular_velocity_imu_in_imu=imu.angular_velocity_imu_in_imu,
        )
