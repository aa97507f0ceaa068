"""Points held at an offset from the centre of mass: de Lasa's E_ankle (§5).

During a jump's flight the ankles are kept "at a fixed position relative to
the COM, throughout flight, improving stability upon landing". The feature
is a point's position relative to the CM, ``y = p − c``; its Jacobian and
drift are the point's less the CM's (the linear momentum rate divided by
the mass, App. B)::

    ÿ = (J_p − R / m) q̈ + (J̇_p q̇ − r_bias / m)

and the setpoint objective (eq. 3–4) asks ``ÿ_d = k_p (y_r − y) − k_v ẏ``.
Each foot also keeps its orientation in the world (flat, as it left the
ground, so that it lands on its sole: de Lasa set the ankles' rest pose to
the ground's slope before touch-down), with the orientation setpoint
``ω̇_d = k_p log(R_r Rᵀ) − k_v ω`` on the frame's angular acceleration.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from controller_server.features.objective import Objective
from controller_server.momentum import MomentumRates

__all__ = ["compute_point_from_com_objective"]


def compute_point_from_com_objective(
    point_jacobians: list[np.ndarray],
    point_drifts: list[np.ndarray],
    point_positions: np.ndarray,
    v: np.ndarray,
    momentum: MomentumRates,
    total_mass: float,
    position_com_in_world: np.ndarray,
    reference_offsets: np.ndarray | None,
    stiffness: float,
    damping: float,
    weight: float,
    rotations: list[np.ndarray] | None = None,
    reference_rotations: np.ndarray | None = None,
    angular_jacobians: list[np.ndarray] | None = None,
    angular_drifts: list[np.ndarray] | None = None,
    name: str = "ankle",
) -> Objective:
    """Rows ``(J_p − R/m)`` and ``ÿ_d − drift`` for each point, then its orientation rows.

    Args:
        point_jacobians: Per point, ``(3, nv)`` velocity Jacobian in world axes.
        point_drifts: Per point, ``(3,)`` acceleration at ``q̈ = 0``.
        point_positions: ``(k, 3)`` positions in the world (m).
        v: Generalized velocity.
        momentum: Momentum rates (App. B) at this state.
        total_mass: ``m`` (kg).
        position_com_in_world: ``c`` (m).
        reference_offsets: ``(k, 3)`` ``y_r``: each point's offset from the CM (m, world
            axes); ``None``: no position rows.
        stiffness: ``k_p`` (1/s²).
        damping: ``k_v`` (1/s).
        weight: Weight of every row.
        rotations: Per point, its frame's ``(3, 3)`` rotation in the world.
        reference_rotations: ``(k, 3, 3)`` ``R_r`` (``None``: no orientation rows).
        angular_jacobians: Per point, ``(3, nv)`` angular velocity Jacobian, world axes.
        angular_drifts: Per point, ``(3,)`` angular acceleration at ``q̈ = 0``.
        name: Objective name.
    """
    com_jacobian = momentum.R / total_mass
    com_velocity = momentum.linear_momentum / total_mass
    com_drift = momentum.r_bias / total_mass
    rows, targets = [], []
    references = [] if reference_offsets is None else reference_offsets
    for jacobian, drift, position, reference in zip(
        point_jacobians, point_drifts, point_positions, references, strict=False
    ):
        offset = position - position_com_in_world
        offset_velocity = jacobian @ v - com_velocity
        desired = stiffness * (reference - offset) - damping * offset_velocity
        rows.append(jacobian - com_jacobian)
        targets.append(desired - (drift - com_drift))
    if reference_rotations is not None:
        assert rotations is not None and angular_jacobians is not None
        assert angular_drifts is not None
        for rotation, reference_rotation, angular, angular_drift in zip(
            rotations, reference_rotations, angular_jacobians, angular_drifts, strict=True
        ):
            omega = angular @ v
            desired = stiffness * pin.log3(reference_rotation @ rotation.T) - damping * omega
            rows.append(angular)
            targets.append(desired - angular_drift)
    return Objective(name, np.vstack(rows), np.concatenate(targets), np.full(3 * len(rows), weight))
