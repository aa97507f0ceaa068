"""Swaying: the CM shifted from one foot toward the other and back, on any controller.

A weight shift is the first thing a biped does before it lifts a foot (de Lasa §6's walk
starts with one; the thesis' ``stand_sway`` clip shows the weighted controller following
one). Here it is a behaviour every controller can host: it moves the reference of the CM
objective (``com_offset_xy``: the CM's offset from the centre of the supports, which both
the weighted controller's linear momentum objective, eq. 5.9, and the prioritized
controller's ``com`` setpoint track) sideways along the feet's axis,

    o(t) = o₀ + A sin(2π (t − t₀) / T) · l,

with ``A`` = ``sway_amplitude``, ``T`` = ``sway_period_s``, ``o₀`` the client's offset when
the sway starts and ``l`` the unit vector along the feet then. It sways until another
``behavior`` is set; the client's offset is untouched. (The ``tracking`` baseline weighs
the linear momentum objective 0: there it sways only with ``weight_linear_momentum``
raised.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from controller_server.behaviors.behavior import Behavior, Targets
from controller_server.behaviors.observation import Observation
from controller_server.models import RobotModel
from controller_server.params import ParamSpec

__all__ = ["SWAY_PARAMETERS", "Sway"]

SWAY_PARAMETERS: dict[str, ParamSpec] = {
    "sway_amplitude": ParamSpec(
        0.03,
        minimum=0.0,
        maximum=0.5,
        doc="sway: how far the CM reference moves toward each foot (m)",
    ),
    "sway_period_s": ParamSpec(
        2.0, minimum=0.2, maximum=60.0, doc="sway: one sway, left and right and back (s)"
    ),
}
"""The sway's parameters (``set_params``, also while swaying)."""


class Sway(Behavior):
    """The CM reference swayed sideways (module docstring); state ``sway`` throughout."""

    name = "sway"
    SUMMARY = "the CM shifted toward each foot in turn (the `sway_` parameters)"
    PARAMETERS = SWAY_PARAMETERS
    HOSTS = ("momentum", "tracking", "prioritized")

    def __init__(self, robot: RobotModel):
        super().__init__(robot)
        self.state = "sway"
        self._start_s: float | None = None
        self._offset_xy = np.zeros(2)
        self._toward_left = np.array([0.0, 1.0])

    def update(self, observation: Observation, params: Mapping[str, Any]) -> Targets:
        """This tick's ``com_offset_xy``."""
        o, p = observation, params
        if self._start_s is None:
            self._start_s = o.time_s
            self._offset_xy = np.array(p["com_offset_xy"], dtype=float)
            feet = o.position_contact_frames_in_world[:, :2]
            if len(feet) >= 2:
                across = feet[0] - feet[-1]  # left minus right, or the other way: the sign
                norm = float(np.linalg.norm(across))  # only sets which foot comes first
                if norm > 1e-6:
                    self._toward_left = across / norm
        phase = 2.0 * math.pi * (o.time_s - self._start_s) / p["sway_period_s"]
        offset = self._offset_xy + p["sway_amplitude"] * math.sin(phase) * self._toward_left
        self._set(com_offset_xy=[float(x) for x in offset])
        return self._targets()
