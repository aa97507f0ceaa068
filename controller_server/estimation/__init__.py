"""Base state estimation from an IMU and leg kinematics (contact-aided invariant EKF)."""

from controller_server.estimation.base_estimator import BaseEstimator
from controller_server.estimation.estimate import (
    BaseEstimate,
    EstimatorInputError,
    EstimatorNoise,
    EstimatorPrior,
    ImuMount,
)
from controller_server.estimation.imu_base import ImuBaseEstimator, imu_mount
from controller_server.estimation.leg_kinematics import (
    LegKinematics,
    compute_leg_kinematics,
    robot_leg_kinematics,
)

__all__ = [
    "BaseEstimate",
    "BaseEstimator",
    "EstimatorInputError",
    "EstimatorNoise",
    "EstimatorPrior",
    "ImuBaseEstimator",
    "ImuMount",
    "LegKinematics",
    "compute_leg_kinematics",
    "imu_mount",
    "robot_leg_kinematics",
]
