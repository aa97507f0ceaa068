"""Per-tick rigid-body terms the controllers need, computed by Pinocchio.

A thin layer: no rigid-body algorithm is written here. One call to
:func:`compute_dynamics_terms` runs Pinocchio's ``computeAllTerms`` and a
zero-acceleration forward kinematics pass, then reads off

* the joint-space mass matrix ``M`` and bias forces ``h`` (Macchietto 2008,
  eq. 2.1: ``h = C + G``),
* the centre of mass,
* for every contact frame, the 6-row support Jacobian ``J`` and the drift
  ``J̇ q̇`` in the world-aligned frame at the contact frame's origin (thesis
  App. A; these are the rows of the support constraint, eq. 5.1),
* for every contact point, the 3-row point Jacobian and its drift, used to
  map contact forces to generalized forces (``J_cᵀ f`` of eq. 4.2).

Pinocchio's free-flyer convention holds inside the server: ``q = [p, quat_xyzw,
q_joints]``, ``v = [v_base_in_base, ω_base_in_base, v_joints]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from controller_server.models import RobotModel

__all__ = ["DynamicsTerms", "compute_dynamics_terms", "cross", "skew"]

WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def skew(u: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[u]×`` (Macchietto 2008, eq. A.4)."""
    return np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcasting (``numpy.cross`` without its overhead)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


@dataclass(frozen=True)
class DynamicsTerms:
    """Dynamics of one robot at one state ``(q, v)``.

    Attributes:
        q: Configuration (Pinocchio convention), ``(nq,)``.
        v: Generalized velocity, ``(nv,)``.
        mass_matrix: Symmetric ``M(q)``, ``(nv, nv)``.
        bias_forces: ``h(q, v)`` = Coriolis, centrifugal and gravity, ``(nv,)``.
        position_com_in_world: Centre of mass (m).
        support_jacobians: Per contact, ``(6, nv)``: ``[v_origin; ω]`` of the
            contact frame in world axes.
        support_drifts: Per contact, ``(6,)``: ``J̇ q̇`` (classical linear and
            angular acceleration at ``q̈ = 0``).
        point_jacobians: Per contact, ``(3k, nv)``: velocity of each point in world axes.
        point_drifts: Per contact, ``(3k,)``: point acceleration at ``q̈ = 0``.
        position_points_in_world: Per contact, ``(k, 3)`` point positions (m).
    """

    q: np.ndarray
    v: np.ndarray
    mass_matrix: np.ndarray
    bias_forces: np.ndarray
    position_com_in_world: np.ndarray
    support_jacobians: tuple[np.ndarray, ...]
    support_drifts: tuple[np.ndarray, ...]
    point_jacobians: tuple[np.ndarray, ...]
    point_drifts: tuple[np.ndarray, ...]
    position_points_in_world: tuple[np.ndarray, ...]


def compute_dynamics_terms(
    robot: RobotModel, data: pin.Data, q: np.ndarray, v: np.ndarray
) -> DynamicsTerms:
    """Evaluate every term a controller needs at ``(q, v)``.

    Args:
        robot: The robot model.
        data: This session's Pinocchio data (overwritten).
        q: Configuration, ``(nq,)``.
        v: Generalized velocity, ``(nv,)``.

    Returns:
        The terms, as fresh arrays (safe to keep after ``data`` changes).
    """
    model = robot.model
    pin.computeAllTerms(model, data, q, v)
    mass_matrix = np.triu(data.M) + np.triu(data.M, 1).T
    bias_forces = data.nle.copy()
    position_com = data.com[0].copy()
    # Drift terms: classical accelerations with q̈ = 0 (App. A, eq. A.9–A.10).
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)

    support_jacobians, support_drifts = [], []
    point_jacobians, point_drifts, point_positions = [], [], []
    for contact in robot.contacts:
        frame_id = contact.frame_id
        jacobian = pin.getFrameJacobian(model, data, frame_id, WORLD_ALIGNED)
        velocity = pin.getFrameVelocity(model, data, frame_id, WORLD_ALIGNED)
        drift = pin.getFrameClassicalAcceleration(model, data, frame_id, WORLD_ALIGNED)
        support_jacobians.append(jacobian)
        support_drifts.append(np.concatenate([drift.linear, drift.angular]))

        offsets_in_world = contact.points_in_frame @ data.oMf[frame_id].rotation.T
        # v_p = v_o + ω × r  and  a_p = a_o + α × r + ω × (ω × r), all points at once.
        angular_rows = np.broadcast_to(
            jacobian[3:].T, (len(offsets_in_world), *jacobian[3:].T.shape)
        )
        lever_rows = cross(angular_rows, offsets_in_world[:, None, :])  # (k, nv, 3): J_ω × r
        point_jacobians.append(
            (jacobian[None, :3, :] + lever_rows.transpose(0, 2, 1)).reshape(-1, model.nv)
        )
        omega = velocity.angular
        point_drifts.append(
            (
                drift.linear
                + cross(drift.angular, offsets_in_world)
                + cross(omega, cross(omega, offsets_in_world))
            ).reshape(-1)
        )
        point_positions.append(data.oMf[frame_id].translation + offsets_in_world)

    return DynamicsTerms(
        q=q,
        v=v,
        mass_matrix=mass_matrix,
        bias_forces=bias_forces,
        position_com_in_world=position_com,
        support_jacobians=tuple(support_jacobians),
        support_drifts=tuple(support_drifts),
        point_jacobians=tuple(point_jacobians),
        point_drifts=tuple(point_drifts),
        position_points_in_world=tuple(point_positions),
    )
