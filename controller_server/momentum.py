"""Momentum derivative matrices of the whole body (Macchietto 2008, App. B).

The thesis writes the momentum rates as linear maps of the accelerations:

* linear momentum (eq. 5.7, B.1–B.6): ``L̇ = Σ mᵢ aᵢ = R q̈ + r_bias``;
* angular momentum about the CM (eq. 5.13, B.7–B.10):
  ``Ḣ = Σ Iᵢ αᵢ + ωᵢ × Iᵢ ωᵢ + mᵢ rᵢ × aᵢ = S q̈ + s_bias``, ``rᵢ = xᵢ − c``.

Stacked, ``[R; S]`` is the centroidal momentum matrix ``A_g`` and
``[r_bias; s_bias] = Ȧ_g q̇``, which Pinocchio computes in one pass
(``computeCentroidalMapTimeVariation``, Orin & Goswami's centroidal
dynamics). Momentum is rigid-body dynamics, so it comes from Pinocchio; the
per-body sums of App. B are kept as the independent reference in
``tests/controller_server/test_momentum.py``, where both agree to 1e-8.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

__all__ = ["MomentumRates", "compute_momentum_rates"]


@dataclass(frozen=True)
class MomentumRates:
    """``L̇ = R q̈ + r_bias`` and ``Ḣ = S q̈ + s_bias`` at one state, plus the momenta.

    Attributes:
        R: ``(3, nv)`` linear momentum rate matrix.
        r_bias: ``(3,)`` linear momentum rate at ``q̈ = 0`` (N).
        S: ``(3, nv)`` angular momentum rate matrix (about the CM, world axes).
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
    model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray
) -> MomentumRates:
    """``R, r_bias, S, s_bias`` (App. B) as ``A_g`` and ``Ȧ_g q̇`` from Pinocchio.

    Overwrites the kinematics in ``data`` with those of ``(q, v)``.
    """
    pin.computeCentroidalMapTimeVariation(model, data, q, v)
    centroidal_matrix = data.Ag.copy()
    bias = data.dAg @ v
    momentum = centroidal_matrix @ v
    return MomentumRates(
        R=centroidal_matrix[:3],
        r_bias=bias[:3],
        S=centroidal_matrix[3:],
        s_bias=bias[3:],
        linear_momentum=momentum[:3],
        angular_momentum=momentum[3:],
    )
