"""Tracking objective: PD + feed-forward toward a reference motion.

Macchietto 2008, eq. 5.3–5.4::

    q̈_des = k_s (q_ref ⊖ q) + k_d (v_ref − v) + a_ref
    C_t   = ‖W_t (q̈_des − q̈)‖²

``q_ref ⊖ q`` is Pinocchio's ``difference`` on the configuration manifold, so
ball joints and the root orientation track by their rotation vector rather
than by quaternion components.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from controller_server.features.objective import Objective

__all__ = ["compute_tracking_objective"]


def compute_tracking_objective(
    model: pin.Model,
    q: np.ndarray,
    v: np.ndarray,
    q_ref: np.ndarray,
    v_ref: np.ndarray,
    a_ref: np.ndarray,
    stiffness: float | np.ndarray,
    damping: float | np.ndarray,
    weight: np.ndarray,
) -> Objective:
    """Rows ``A = I``, ``b = q̈_des`` with per-DoF weights (eq. 5.3–5.4).

    Args:
        model: Pinocchio model.
        q: Current configuration, ``(nq,)``.
        v: Current velocity, ``(nv,)``.
        q_ref: Reference configuration, ``(nq,)``.
        v_ref: Reference velocity, ``(nv,)``.
        a_ref: Feed-forward reference acceleration, ``(nv,)``.
        stiffness: ``k_s`` (1/s²), scalar or per DoF.
        damping: ``k_d`` (1/s), scalar or per DoF.
        weight: ``(nv,)`` diagonal of ``W_tᵀ W_t``; zero rows are not tracked.

    Returns:
        The tracking objective over ``x = q̈``.
    """
    acceleration_desired = (
        stiffness * pin.difference(model, q, q_ref) + damping * (v_ref - v) + a_ref
    )
    return Objective("tracking", np.eye(model.nv), acceleration_desired, weight)
