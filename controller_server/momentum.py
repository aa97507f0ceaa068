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

``Iᵢ`` is body i's inertia about its CM in world axes. Pinocchio supplies
the kinematics (joint placements, velocities, zero-acceleration spatial
accelerations, and the world-frame joint Jacobian); the sums over bodies are
the thesis' own, evaluated for all bodies at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import pinocchio as pin

from controller_server.spatial import cross

__all__ = ["MomentumRates", "compute_momentum_rates"]


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


@dataclass(frozen=True)
class _BodyTable:
    """Constant per-body data of a model: which DoFs move each body, and its inertia."""

    joint_ids: tuple[int, ...]
    masses: np.ndarray
    levers: np.ndarray  # (b, 3) CM in the joint frame
    inertias: np.ndarray  # (b, 3, 3) about the CM, joint axes
    ancestors: np.ndarray  # (b, nv) 1 where the DoF moves the body


@cache
def _body_table(model: pin.Model) -> _BodyTable:
    ids = [j for j in range(1, model.njoints) if model.inertias[j].mass > 0.0]
    ancestors = np.zeros((len(ids), model.nv))
    for row, joint_id in enumerate(ids):
        for support in model.supports[joint_id]:
            if support > 0:
                start = model.idx_vs[support]
                ancestors[row, start : start + model.nvs[support]] = 1.0
    return _BodyTable(
        joint_ids=tuple(ids),
        masses=np.array([model.inertias[j].mass for j in ids]),
        levers=np.array([model.inertias[j].lever for j in ids]),
        inertias=np.array([model.inertias[j].inertia for j in ids]),
        ancestors=ancestors,
    )


def compute_momentum_rates(
    model: pin.Model, data: pin.Data, v: np.ndarray, position_com_in_world: np.ndarray
) -> MomentumRates:
    """App. B matrices from per-body Jacobians and drifts.

    ``data`` must hold ``forwardKinematics(q, v, 0)`` and ``computeJointJacobians(q)``.
    """
    table = _body_table(model)
    ids = table.joint_ids
    rotations = np.array([data.oMi[j].rotation for j in ids])  # (b, 3, 3) joint → world
    origins = np.array([data.oMi[j].translation for j in ids])
    velocities = np.array([data.v[j].vector for j in ids])  # local [v; ω]
    accelerations = np.array([data.a[j].vector for j in ids])  # local, q̈ = 0

    positions = origins + np.einsum("bij,bj->bi", rotations, table.levers)  # body CMs, world
    # World-frame Jacobian columns are spatial velocities at the world origin; the
    # CM of body b moves with v + ω × x_b, through the DoFs that carry it.
    jacobian_linear_world, jacobian_angular = data.J[:3].T, data.J[3:].T  # (nv, 3)
    jacobian_angular_bodies = table.ancestors[:, :, None] * jacobian_angular[None]  # (b, nv, 3)
    jacobian_linear_bodies = table.ancestors[:, :, None] * jacobian_linear_world[None] + cross(
        jacobian_angular_bodies, positions[:, None, :]
    )

    # Classical CM acceleration at q̈ = 0 (App. C, eq. C.3), local axes, then world.
    linear, omega_local = velocities[:, :3], velocities[:, 3:]
    acceleration_linear, alpha_local = accelerations[:, :3], accelerations[:, 3:]
    com_drift_local = (
        acceleration_linear
        + cross(omega_local, linear)
        + cross(alpha_local, table.levers)
        + cross(omega_local, cross(omega_local, table.levers))
    )
    com_drift = np.einsum("bij,bj->bi", rotations, com_drift_local)
    angular_drift = np.einsum("bij,bj->bi", rotations, alpha_local)
    omega = np.einsum("bij,bj->bi", rotations, omega_local)
    inertia_world = rotations @ table.inertias @ rotations.transpose(0, 2, 1)
    offsets = positions - position_com_in_world
    masses = table.masses

    R = np.einsum("b,bkx->xk", masses, jacobian_linear_bodies)
    r_bias = masses @ com_drift
    S = np.einsum(
        "b,bkx->xk", masses, cross(offsets[:, None, :], jacobian_linear_bodies)
    ) + np.einsum("bxy,bky->xk", inertia_world, jacobian_angular_bodies)
    inertia_omega = np.einsum("bij,bj->bi", inertia_world, omega)
    s_bias = (
        masses @ cross(offsets, com_drift)
        + np.einsum("bij,bj->i", inertia_world, angular_drift)
        + cross(omega, inertia_omega).sum(axis=0)
    )
    return MomentumRates(R, r_bias, S, s_bias, R @ v, S @ v)
