"""Posture objectives: the trunk upright and the joints at a rest pose (de Lasa et al. 2010, §4).

One setpoint (eq. 4) on the configuration error ``q_rest ⊖ q``
(:func:`~controller_server.features.tracking.compute_tracking_objective`
with zero reference velocity and acceleration), split into two objectives
with their own gains and weights: ``trunk``, the root orientation rows
(cf. E_trunk of Table 2), and ``pose``, the joint rows (E_pose). The root
position is left free.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from controller_server.features.objective import Objective
from controller_server.features.setpoint import critical_damping
from controller_server.features.tracking import compute_tracking_objective

__all__ = ["compute_posture_objectives"]

ROOT_ORIENTATION = slice(3, 6)
JOINTS = slice(6, None)


def compute_posture_objectives(
    model: pin.Model,
    q: np.ndarray,
    v: np.ndarray,
    orientation_trunk_in_world_xyzw: np.ndarray,
    joint_position_reference: np.ndarray,
    trunk_stiffness: float,
    pose_stiffness: float,
    damping_ratio: float,
    trunk_weight: float,
    pose_weight: float,
) -> tuple[Objective, Objective]:
    """The ``trunk`` and ``pose`` objectives over ``q̈`` (floating-base models).

    Args:
        model: Pinocchio model with a free-flyer root.
        q: Configuration ``(nq,)``.
        v: Velocity ``(nv,)``.
        orientation_trunk_in_world_xyzw: Reference root orientation.
        joint_position_reference: Rest pose of the joints, ``(nq − 7,)``.
        trunk_stiffness: ``k_p`` of the root orientation (1/s²).
        pose_stiffness: ``k_p`` of the joints (1/s²).
        damping_ratio: ζ of ``k_v = 2 ζ √k_p``.
        trunk_weight: α of ``trunk``.
        pose_weight: α of ``pose``.
    """
    q_rest = pin.neutral(model)
    q_rest[:3] = q[:3]
    q_rest[3:7] = orientation_trunk_in_world_xyzw
    q_rest[7:] = joint_position_reference
    stiffness = np.concatenate(
        [np.zeros(3), np.full(3, trunk_stiffness), np.full(model.nv - 6, pose_stiffness)]
    )
    zero = np.zeros(model.nv)
    servo = compute_tracking_objective(
        model,
        q,
        v,
        q_rest,
        zero,
        zero,
        stiffness,
        critical_damping(stiffness, damping_ratio),
        zero,
    )
    trunk = Objective(
        "trunk", servo.A[ROOT_ORIENTATION], servo.b[ROOT_ORIENTATION], np.full(3, trunk_weight)
    )
    pose = Objective("pose", servo.A[JOINTS], servo.b[JOINTS], np.full(model.nv - 6, pose_weight))
    return trunk, pose
