"""A session's base estimator by the compiled core: the tick of :mod:`.imu_base` in C++.

:class:`CompiledImuBaseEstimator` runs the whole tick of
:class:`~controller_server.estimation.ImuBaseEstimator` (the joints normalised, the sole
corners on the ground by Pinocchio's forward kinematics, the gap and time checks, the
propagation and leg-kinematics correction of the contact-aided invariant EKF of Hartley et
al. 2020, and the estimate) in one call to ``controller_server._core.ImuBaseEstimator``
(``controller_server/core/estimator.cpp``), with the GIL released and no allocation in C++
after its first tick. The Python modules are its specification: the same equations in the
same order, so that the two agree to rounding
(``tests/controller_server/test_compiled_estimator.py``), and the same
:class:`EstimatorInputError` (field and words) on the same inputs, leaving the filter as the
Python leaves it. :class:`~controller_server.estimation.ImuBaseEstimator` owns one and
hands the filter's state over when the kernel changes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller_server.compiled import load_core
from controller_server.estimation.estimate import (
    BaseEstimate,
    EstimatorNoise,
    EstimatorPrior,
    ImuMount,
)
from controller_server.estimation.leg_kinematics import GROUNDED_TOLERANCE_M
from controller_server.models import RobotModel
from protocol.messages import State

__all__ = ["CompiledImuBaseEstimator"]


class CompiledImuBaseEstimator:
    """One session's estimator tick in C++ (see the module).

    The model, the noise and the priors are copied into C++ at construction: a later change
    of the Python filter's ``noise`` does not reach this one.

    Raises:
        CompiledCoreUnavailable: The core is not built or was built for another Pinocchio.
    """

    def __init__(
        self,
        robot: RobotModel,
        mount: ImuMount,
        noise: EstimatorNoise,
        level_prior: EstimatorPrior,
        ahrs_prior: EstimatorPrior,
        *,
        gravity: float,
        max_state_gap_s: float,
    ):
        """Copy the robot's model (``pin.Model.saveToString()``, ~1 ms) and settings into C++.

        Args:
            robot: The session's robot (its contacts and their sole corners).
            mount: The IMU's placement on the base.
            noise: The filter's noise model.
            level_prior: The prior of a start levelled on the accelerometer.
            ahrs_prior: The prior of a start from the IMU's own orientation.
            gravity: Magnitude of gravity (m/s²).
            max_state_gap_s: The longest time between two states the filter integrates (s).
        """
        self._core = load_core().ImuBaseEstimator(
            robot.model.saveToString(),
            [contact.frame_id for contact in robot.contacts],
            [np.ascontiguousarray(c.points_in_frame, dtype=float) for c in robot.contacts],
            np.asarray(mount.rotation_imu_to_base, dtype=float),
            np.asarray(mount.position_imu_in_base, dtype=float),
            noise,
            level_prior,
            ahrs_prior,
            gravity,
            max_state_gap_s,
            GROUNDED_TOLERANCE_M,
        )
        self._contact_names = tuple(contact.name for contact in robot.contacts)

    def __call__(self, state: State) -> BaseEstimate:
        """The base estimate at ``state.time_s`` (fresh arrays).

        Raises:
            EstimatorInputError: As the Python filter, with its input names (not yet the
                ``state`` fields: :class:`~controller_server.estimation.ImuBaseEstimator`
                maps them).
        """
        imu = state.imu
        assert imu is not None
        (
            position,
            orientation,
            linear_velocity,
            angular_velocity,
            gyro_bias,
            accel_bias,
            points,
            stance,
            covariance,
        ) = self._core.step(
            state.time_s,
            state.joint_position,
            state.contact_flags,
            imu.angular_velocity_imu_in_imu,
            imu.linear_acceleration_imu_in_imu,
            imu.orientation_imu_in_world_xyzw,
        )
        names = self._contact_names
        return BaseEstimate(
            position_base_in_world=position,
            orientation_base_in_world_xyzw=orientation,
            linear_velocity_base_in_world=linear_velocity,
            angular_velocity_base_in_base=angular_velocity,
            gyro_bias_in_imu=gyro_bias,
            accel_bias_in_imu=accel_bias,
            position_contacts_in_world={names[k]: points[i] for i, k in enumerate(stance)},
            covariance=covariance,
        )

    def state(self) -> dict[str, Any]:
        """The filter's state and the session's (time, corners in use), as copies.

        Keys: ``rotation`` (``R_WI``), ``columns`` (``[v, p, d_1 …]`` as rows), ``bias``,
        ``covariance``, ``stance`` (contact indices), ``gyro_reading``, ``initialized``,
        ``time_s``, ``corners`` (per contact, the indices of its corners in use).
        """
        return self._core.state()

    def set_state(self, values: dict[str, Any]) -> None:
        """Take over a :meth:`state` (the Python estimator's, handed over)."""
        self._core.set_state(values)
