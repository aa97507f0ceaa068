"""``angular_momentum``: the centroidal angular momentum damped toward a reference.

Two references, one per paper: de Lasa et al.'s setpoint ``L̇_d = k_p (L_r − L)``
(2010, eq. 8–9; :class:`AngularMomentumTask`) and Macchietto's damping
``Ḣ_des = −k_H H`` weighted by how far the CMP strays from the COP
(2008, eq. 5.15–5.17; :class:`CopWeightedAngularMomentumTask`).
"""

from __future__ import annotations

import numpy as np

from controller_server.balance_points import ground_reference_points
from controller_server.features import (
    Objective,
    angular_momentum_weight,
    compute_angular_momentum_objective,
)
from controller_server.tasks.task import Task, Tick

__all__ = ["AngularMomentumTask", "CopWeightedAngularMomentumTask"]


class AngularMomentumTask(Task):
    """``L̇_d = k_p (L_r − L)`` (de Lasa 2010, eq. 8–9), weight α.

    Parameters: ``angular_momentum_stiffness`` (k_p), ``reference_angular_momentum`` (L_r).
    Reports ``angular_momentum_rate`` (``L̇_d``).
    """

    def __init__(self, name: str = "angular_momentum"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows ``S / m_T`` toward ``L̇_d``, weight α."""
        p, momentum = tick.params, tick.terms.momentum
        desired_rate = p["angular_momentum_stiffness"] * (
            p["reference_angular_momentum"] - momentum.angular_momentum
        )
        tick.reports["angular_momentum_rate"] = desired_rate
        return compute_angular_momentum_objective(
            momentum, tick.terms.total_mass, weight, desired_rate=desired_rate
        )


class CopWeightedAngularMomentumTask(Task):
    """``Ḣ_des = −k_H H`` with weight ``β_0 + γ ‖p − g‖`` (Macchietto 2008, eq. 5.15–5.17).

    The stack's weight is β_0; the COP ``p`` and CMP ``g`` are of the tick's
    ``contact_wrench_in_world`` (measured, or the last command's). No rows while the
    weight is 0. Parameters: ``angular_momentum_gain`` (γ), ``angular_momentum_damping``
    (k_H). Reports ``angular_momentum_weight`` and ``angular_momentum_rate``.
    """

    uniform = False  # its weight is its own, from the COP and CMP

    def __init__(self, name: str = "angular_momentum"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows ``S / m_T`` toward ``−k_H H``, weight ``β_0 + γ ‖p − g‖``; none at 0."""
        p, terms = tick.params, tick.terms
        cop, cmp_ = ground_reference_points(
            terms.position_contact_frames_in_world,
            terms.position_com_in_world,
            tick.contact_wrench_in_world,
            tick.supports,
            p["ground_height"],
        )
        effective = angular_momentum_weight(p["angular_momentum_gain"], cop, cmp_, weight)
        tick.reports["angular_momentum_weight"] = effective
        if effective <= 0:
            tick.reports["angular_momentum_rate"] = np.full(3, np.nan)
            return None
        damping = p["angular_momentum_damping"]
        tick.reports["angular_momentum_rate"] = -damping * terms.momentum.angular_momentum
        return compute_angular_momentum_objective(
            terms.momentum, terms.total_mass, effective, damping
        )
