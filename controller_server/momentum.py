"""Momentum derivative matrices of the whole body (Macchietto 2008, App. B).

With every body's centre-of-mass acceleration ``aᵢ = J_lin,i q̈ + J̇_lin,i q̇``
and angular acceleration ``αᵢ = J_ang,i q̈ + J̇_ang,i q̇`` (world axes):

* linear momentum rate (eq. 5.7, B.1–B.6)::

      L̇ = Σ mᵢ aᵢ = R q̈ + r_bias,   R = Σ mᵢ J_lin,i,  r_bias = Σ mᵢ J̇_lin,i q̇

* angular momentum rate about the CM (eq. 5.13, B.7–B.10)::

      Ḣ = Σ Iᵢ αᵢ + ωᵢ × Iᵢ ωᵢ + mᵢ rᵢ × aᵢ = S q̈ + s_bias,   rᵢ = xᵢ − c
      S = Σ mᵢ [rᵢ]× J_lin,i + Iᵢ J_ang,i
      s_bias = Σ mᵢ rᵢ × J̇_lin,i q̇ + Iᵢ J̇_ang,i q̇ + ωᵢ × Iᵢ ωᵢ

  (the ``ṙᵢ × mᵢ vᵢ`` terms of eq. 5.13 sum to ``−ċ × m_T ċ = 0``).

``Iᵢ`` is body i's inertia about its CM in world axes. The per-body
Jacobians and drifts come from Pinocchio; the sums are the thesis' own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from controller_server.spatial import cross, skew

__all__ = ["MomentumRates", "compute_momentum_rates"]

WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass(frozen=True)
class MomentumRates:
    """``L̇ = R q̈ + r_bias`` and ``Ḣ = S q̈ + s_bias`` at one state, plus the momenta.

    Attributes:
        R: ``(3, nv)`` linear momentum rate matrix.
        r_bias: ``(3,)`` linear momentum rate at ``q̈ = 0`` (N).
        S: ``(3, nv)`` angular momentum rate matrix (about the CM).
        s_bias: ``(3,)`` angular momentum rate at ``q̈ = 0`` (N·m).
        linear_momentum: ``L = R q̇`` (kg·m/s).
        angular_momentum: ``H = S q̇`` about the CM (kg·m²/s).
    """

    R: np.ndarray
    r_bias: np.ndarray
    S: np.ndarray
    s_bias: np.ndarray
    linear_momentum: np.ndarray
    angular_momentum: np.ndarray


def compute_momentum_rates(
    model: pin.Model, data: pin.Data, v: np.ndarray, position_com_in_world: np.ndarray
) -> MomentumRates:
    """App. B matrices from per-body Jacobians and drifts.

    ``data`` must hold ``forwardKinematics(q, v, 0)`` and ``computeJointJacobians(q)``.
    """
    nv = model.nv
    R = np.zeros((3, nv))
    S = np.zeros((3, nv))
    r_bias = np.zeros(3)
    s_bias = np.zeros(3)
    for joint_id in range(1, model.njoints):
        inertia = model.inertias[joint_id]
        mass = inertia.mass
        if mass <= 0.0:
            continue
        placement = data.oMi[joint_id]
        rotation = placement.rotation
        lever_in_world = rotation @ inertia.lever
        jacobian = pin.getJointJacobian(model, data, joint_id, WORLD_ALIGNED)
        jacobian_linear = jacobian[:3] - skew(lever_in_world) @ jacobian[3:]
        jacobian_angular = jacobian[3:]

        velocity, acceleration = data.v[joint_id], data.a[joint_id]  # local, q̈ = 0
        omega_local = velocity.angular
        lever = inertia.lever
        # Classical acceleration of the body CM at q̈ = 0 (App. C, eq. C.3), local axes.
        com_drift_local = (
            acceleration.linear
            + cross(omega_local, velocity.linear)
            + cross(acceleration.angular, lever)
            + cross(omega_local, cross(omega_local, lever))
        )
        com_drift = rotation @ com_drift_local
        angular_drift = rotation @ acceleration.angular
        omega = rotation @ omega_local
        inertia_in_world = rotation @ inertia.inertia @ rotation.T
        offset = placement.translation + lever_in_world - position_com_in_world

        R += mass * jacobian_linear
        r_bias += mass * com_drift
        S += mass * skew(offset) @ jacobian_linear + inertia_in_world @ jacobian_angular
        s_bias += (
            mass * cross(offset, com_drift)
            + inertia_in_world @ angular_drift
            + cross(omega, inertia_in_world @ omega)
        )
    return MomentumRates(R, r_bias, S, s_bias, R @ v, S @ v)
