"""Contact points relative to the base from joint encoders, computed by Pinocchio.

The leg-kinematics measurement of the base estimator (Hartley et al. 2020, forward
kinematic measurements; Bloesch et al. 2012, kinematic measurement model) is the position of each
stance contact point in the base frame, ``s(α)``, with its Jacobian ``J(α) = ∂s/∂α`` with
respect to the joint positions, which maps encoder noise to measurement noise:
``Cov[s] = J Σ_α Jᵀ``. With the free-flyer at the identity the world frame *is* the base
frame, so Pinocchio's world-aligned frame Jacobians are the base-frame ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

__all__ = [
    "GROUNDED_TOLERANCE_M",
    "LegKinematics",
    "compute_leg_kinematics",
    "grounded_leg_kinematics",
    "robot_leg_kinematics",
]

GROUNDED_TOLERANCE_M = 0.003
"""A sole corner is on the ground if at most this far above its foot's lowest corner (m)."""

_BASE_AT_IDENTITY = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])


@dataclass(frozen=True)
class LegKinematics:
    """Where the contact points are relative to the base, from the encoders.

    Attributes:
        position_points_in_base: ``(K, 3)`` contact points (m) in the base frame, one per
            contact, in the estimator's contact order.
        jacobians: ``(K, 3, n)`` derivatives of those points with respect to the joint
            positions (m/rad, or m/m for prismatic joints); ``n`` is the number of joint
            velocities (for ball joints the derivative is along the joint's tangent).
    """

    position_points_in_base: np.ndarray
    jacobians: np.ndarray


def compute_leg_kinematics(
    model: pin.Model,
    data: pin.Data,
    joint_position: np.ndarray,
    frame_ids: Sequence[int],
    points_in_frame: Sequence[np.ndarray] | None = None,
) -> LegKinematics:
    """Contact points in the base frame and their joint Jacobians (Pinocchio).

    Runs ``computeJointJacobians`` (forward kinematics included) and
    ``updateFramePlacements`` at ``q = [0, 0, 0, 0, 0, 0, 1, joint_position]``. For a point
    ``r`` in frame ``f`` the point is ``p_f + R_f r`` and its Jacobian
    ``J_lin − [R_f r]× J_ang`` (world-aligned frame Jacobian, joint columns only).

    Args:
        model: Pinocchio model whose joint 1 is a free flyer (the base).
        data: Its data (overwritten).
        joint_position: ``(model.nq − 7,)`` joint positions (Pinocchio order).
        frame_ids: One frame per contact.
        points_in_frame: Per contact, the point ``(3,)`` in its frame (m); default the origin.

    Returns:
        The points and Jacobians.
    """
    q = np.concatenate([_BASE_AT_IDENTITY, np.asarray(joint_position, dtype=float)])
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    count = len(frame_ids)
    offsets = np.zeros((count, 3)) if points_in_frame is None else np.asarray(points_in_frame)
    positions = np.zeros((count, 3))
    jacobians = np.zeros((count, 3, model.nv - 6))
    for frame_id in dict.fromkeys(frame_ids):  # once per frame: a foot's corners share one
        rows = [k for k, frame in enumerate(frame_ids) if frame == frame_id]
        placement = data.oMf[frame_id]
        offsets_in_base = offsets[rows] @ placement.rotation.T
        positions[rows] = placement.translation + offsets_in_base
        frame_jacobian = pin.getFrameJacobian(
            model, data, frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )[:, 6:]
        # J_lin − [r]× J_ang for every point r (its offset from the frame origin, world axes).
        x, y, z = offsets_in_base.T
        skews = np.zeros((len(rows), 3, 3))
        skews[:, 0, 1], skews[:, 0, 2], skews[:, 1, 2] = -z, y, -x
        skews[:, 1, 0], skews[:, 2, 0], skews[:, 2, 1] = z, -y, x
        jacobians[rows] = frame_jacobian[:3] - skews @ frame_jacobian[3:]
    return LegKinematics(position_points_in_base=positions, jacobians=jacobians)


def robot_leg_kinematics(robot, data: pin.Data, joint_position: np.ndarray) -> LegKinematics:
    """:func:`compute_leg_kinematics` for a ``RobotModel``'s contacts, one point per contact.

    Each contact is represented by the centroid of its points (the sole centre for the
    built-in models' four-corner soles).

    Args:
        robot: A :class:`controller_server.models.RobotModel`.
        data: ``pin.Data`` of ``robot.model`` (overwritten).
        joint_position: ``(robot.nq_joints,)`` joint positions in wire order.

    Returns:
        The points and Jacobians, in ``robot.contacts`` order.
    """
    return compute_leg_kinematics(
        robot.model,
        data,
        joint_position,
        [contact.frame_id for contact in robot.contacts],
        [np.mean(contact.points_in_frame, axis=0) for contact in robot.contacts],
    )


def grounded_leg_kinematics(
    robot,
    data: pin.Data,
    joint_position: np.ndarray,
    rotation_base_in_world: np.ndarray,
    previous: Sequence[tuple[int, ...]] = (),
) -> tuple[LegKinematics, list[tuple[int, ...]]]:
    """One point per contact: the centroid of its corners on the ground, and their Jacobian.

    A foot flagged in stance stands still only where it touches: flat, its whole sole
    (the centroid of its corners); rolled onto an edge or a corner, that edge or corner,
    while the sole centre rises and moves. The corners on the ground are those within
    :data:`GROUNDED_TOLERANCE_M` of the foot's lowest corner in the world's vertical, from
    the estimated base orientation (a 0.5° error moves a 20 cm sole's ends by 1.7 mm).
    A foot keeps its ``previous`` corners while they all stay within twice that (a foot
    that rolled onto its edge and back is still standing on that edge): each change of
    corners costs the filter that foot's history, and a foot near the threshold would
    otherwise flicker between two sets. The Jacobian of the centroid is the mean of the
    corners' Jacobians.

    Args:
        robot: A :class:`controller_server.models.RobotModel`.
        data: ``pin.Data`` of ``robot.model`` (overwritten).
        joint_position: ``(robot.nq_joints,)`` joint positions in wire order.
        rotation_base_in_world: ``R_WB`` estimated.
        previous: The corners each contact used last time (empty: none).

    Returns:
        The points and Jacobians in ``robot.contacts`` order, and per contact the indices
        of the corners used.
    """
    frame_ids, points = [], []
    for contact in robot.contacts:
        for point in contact.points_in_frame:
            frame_ids.append(contact.frame_id)
            points.append(point)
    corners = compute_leg_kinematics(robot.model, data, joint_position, frame_ids, points)
    heights = corners.position_points_in_base @ rotation_base_in_world[2]
    positions: list[np.ndarray] = []
    jacobians: list[np.ndarray] = []
    used: list[tuple[int, ...]] = []
    start = 0
    for contact in robot.contacts:
        rows = slice(start, start + len(contact.points_in_frame))
        start = rows.stop
        height = heights[rows] - heights[rows].min()
        kept = previous[len(used)] if len(previous) > len(used) else ()
        if kept and np.all(height[list(kept)] <= 2 * GROUNDED_TOLERANCE_M):
            chosen = kept
        else:
            chosen = tuple(int(i) for i in np.flatnonzero(height <= GROUNDED_TOLERANCE_M))
        low = list(chosen)
        positions.append(corners.position_points_in_base[rows][low].mean(axis=0))
        jacobians.append(corners.jacobians[rows][low].mean(axis=0))
        used.append(chosen)
    return LegKinematics(np.array(positions), np.array(jacobians)), used
