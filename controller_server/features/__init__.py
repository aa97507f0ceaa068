"""Objectives: each returns weighted rows ``(A, b)`` of a least-squares term."""

from controller_server.features.angular_momentum import (
    angular_momentum_weight,
    compute_angular_momentum_objective,
)
from controller_server.features.contact_points import compute_ground_contact_objective
from controller_server.features.joint_limits import (
    BallJointLimit,
    JointLimitSet,
    RevoluteJointLimit,
    default_joint_limits,
    joint_limit_errors,
    soft_limit_gains,
)
from controller_server.features.linear_momentum import (
    admissible_linear_momentum_rate,
    compute_linear_momentum_objective,
    desired_linear_momentum_rate,
)
from controller_server.features.motion_clip import ClipSample, MotionClip, load_motion_clip
from controller_server.features.objective import Objective
from controller_server.features.point_acceleration import PointTarget, compute_point_objective
from controller_server.features.posture import compute_posture_objectives
from controller_server.features.tracking import compute_tracking_objective

__all__ = [
    "BallJointLimit",
    "ClipSample",
    "JointLimitSet",
    "MotionClip",
    "Objective",
    "PointTarget",
    "RevoluteJointLimit",
    "admissible_linear_momentum_rate",
    "angular_momentum_weight",
    "compute_angular_momentum_objective",
    "compute_ground_contact_objective",
    "compute_linear_momentum_objective",
    "compute_point_objective",
    "compute_posture_objectives",
    "compute_tracking_objective",
    "default_joint_limits",
    "desired_linear_momentum_rate",
    "joint_limit_errors",
    "load_motion_clip",
    "soft_limit_gains",
]
