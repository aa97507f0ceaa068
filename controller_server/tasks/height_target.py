"""The CM height objective's reference: a target objective while a new height is reached.

de Lasa et al.'s target objective (eq. 6–7) reaches a new value ``y_T`` with velocity
``ẏ_T`` at time ``T``; after it (and without a change under way) a setpoint (eq. 4) holds
the height. A new ``com_height`` (from the client, or a behaviour's request) restarts it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from controller_server.features.setpoint import (
    critical_damping,
    setpoint_acceleration,
    target_acceleration,
)

__all__ = ["TARGET_HANDOVER_S", "HeightTarget"]

TARGET_HANDOVER_S = 0.05
"""The target objective hands over to the setpoint this long before T: re-planned every tick,
eq. 7 amplifies what is left of a velocity error as T → 0."""


class HeightTarget:
    """``z̈_d`` of the CM height objective, tick by tick (``com_height*`` parameters)."""

    def __init__(self) -> None:
        self._start_s: float | None = None  # state time a new height was set
        self._pending = False

    def restart(self) -> None:
        """A new height: the target objective starts at the next tick."""
        self._pending = True

    def acceleration(
        self,
        time_s: float,
        com: np.ndarray,
        com_velocity: np.ndarray,
        params: Mapping[str, Any],
    ) -> float:
        """``z̈_d``: the target objective (eq. 6–7) while a change runs, else eq. 4."""
        p = params
        target = p["com_height"] + p["ground_height"]
        if self._pending:
            self._start_s = time_s
            self._pending = False
        if self._start_s is not None:
            remaining = p["com_height_duration_s"] - (time_s - self._start_s)
            if remaining > TARGET_HANDOVER_S:
                return float(
                    target_acceleration(
                        com[2], com_velocity[2], target, p["com_height_velocity"], remaining
                    )
                )
            self._start_s = None
        stiffness = p["com_height_stiffness"]
        if p["com_height_velocity"]:
            # A target that ends in motion (a jump's thrust) holds that speed after T.
            damping = critical_damping(stiffness, p["damping_ratio"])
            return float(damping * (p["com_height_velocity"] - com_velocity[2]))
        return float(
            setpoint_acceleration(
                target,
                com[2],
                com_velocity[2],
                stiffness,
                critical_damping(stiffness, p["damping_ratio"]),
            )
        )
