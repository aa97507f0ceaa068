"""Posture objectives: the trunk upright and the joints at a rest pose (de Lasa et al. 2010, §4).

One setpoint (eq. 4) on the configuration error ``q_rest ⊖ q``, ``q̈_des =
k_p (q_rest ⊖ q) − k_v q̇`` (the tracking objective of
:mod:`~controller_server.features.tracking` with zero reference velocity and
acceleration), split into two objectives
with their own gains and weights: ``trunk``, the root orientation rows
(cf. E_trunk of Table 2), and ``pose``, the joint rows (E_pose). The root
position is left free.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin

from controller_server.features.objective import Objective
from controller_server.features.setpoint import critical_damping

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
    q_rest = np.concatenate([q[:3], orientation_trunk_in_world_xyzw, joint_position_reference])
    error = pin.difference(model, q, q_rest)  # q_rest ⊖ q
    trunk_desired = (
        trunk_stiffness * error[ROOT_ORIENTATION]
        - critical_damping(trunk_stiffness, damping_ratio) * v[ROOT_ORIENTATION]
    )
    pose_desired = (
        pose_stiffness * error[JOINTS] - critical_damping(pose_stiffness, damping_ratio) * v[JOINTS]
    )
    rows = _identity_rows(model.nv)
    trunk = Objective("trunk", rows[ROOT_ORIENTATION], trunk_desired, np.full(3, trunk_weight))
    pose = Objective("pose", rows[JOINTS], pose_desired, np.full(model.nv - 6, pose_weight))
    return trunk, pose


@cache
def _identity_rows(size: int) -> np.ndarray:
    """The ``(size, size)`` identity, read only (objectives share its row blocks)."""
    identity = np.eye(size)
    identity.setflags(write=False)
    return identity
