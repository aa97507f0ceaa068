"""Dynamixel X-series servo catalogue and torque ↔ current map (current-control mode).

Each supported servo (:data:`DYNAMIXEL_MODELS`) with its model number,
Current Limit (38) default and torque ↔ current map. The model numbers and
Current Limit defaults are from the ROBOTIS e-Manual's model pages (source
``ROBOTIS-GIT/emanual``, ``docs/en/dxl/x/xm430-w350.md``, ``xm540-w270.md``,
``xh430-w350.md``, ``xh540-w270.md``); the torque ↔ current map per model is
from their stall-torque specifications (``docs/en/dxl/x/x.md``), see
:class:`DynamixelModel`. Goal Current (102) for a torque is computed here.
Imported through :mod:`clients.bridge.protocols.dynamixel`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass

from clients.bridge.protocols.dynamixel_packets import CommandError
from clients.bridge.protocols.dynamixel_registers import CURRENT_UNIT_A

__all__ = [
    "DYNAMIXEL_MODELS",
    "DynamixelModel",
    "current_from_torque",
    "get_model",
    "goal_current_from_torque",
    "torque_from_current",
]


# --------------------------------------------------------------------------- models


@dataclass(frozen=True)
class DynamixelModel:
    """One X-series model in current-control mode: its limits and torque ↔ current map.

    Datasheet values (ROBOTIS e-Manual, model pages and the X-series table
    ``docs/en/dxl/x/x.md``): model number, Current Limit (38) default, the
    current unit, and the stall torque and stall current at 11.1, 12.0 and
    14.8 V. At stall the speed is zero, so torque depends on current alone:
    the three stall points lie on the servo's torque(current) curve. The map
    is piecewise linear through (0 A, 0 N·m) and those three points
    (``torque_table``), extrapolated with the last segment's slope beyond
    them. That is an approximation: it ignores the no-load current and the
    gearbox's static friction near zero, which the performance graph shows
    but which we did not digitise; replace ``torque_table`` with points read
    off the 12 V graph for better low-torque accuracy.

    Commands are clamped to the stall torque at 12 V (``stall_torque_Nm``,
    the recommended supply) and to Current Limit (38).

    Positions and velocities are of the output shaft (the gear is inside the
    servo), so the bridge's gear ratio for a Dynamixel joint is 1.
    """

    name: str
    model_number: int
    current_limit_units: int
    stall_torque_Nm: float
    stall_current_A: float
    torque_table: tuple[tuple[float, float], ...]
    """(current A, output torque N·m) points, increasing, starting at (0, 0)."""
    gear_ratio: float
    current_unit_A: float = CURRENT_UNIT_A

    @property
    def current_limit_A(self) -> float:
        """Current Limit (38) default in amperes."""
        return self.current_limit_units * self.current_unit_A


def _model(
    name: str,
    model_number: int,
    current_limit_units: int,
    stall_points: tuple[tuple[float, float], ...],
    gear_ratio: float,
) -> DynamixelModel:
    """A model from its stall points at 11.1, 12.0 and 14.8 V ((A, N·m) each)."""
    current_12V_A, torque_12V_Nm = stall_points[1]
    return DynamixelModel(
        name=name,
        model_number=model_number,
        current_limit_units=current_limit_units,
        stall_torque_Nm=torque_12V_Nm,
        stall_current_A=current_12V_A,
        torque_table=((0.0, 0.0), *stall_points),
        gear_ratio=gear_ratio,
    )


DYNAMIXEL_MODELS: Mapping[str, DynamixelModel] = {
    model.name: model
    for model in (
        # Stall torque (N·m) at 11.1 / 12.0 / 14.8 V and its current (A), e-Manual x.md.
        _model("XM430-W350", 1020, 1193, ((2.1, 3.8), (2.3, 4.1), (2.7, 4.8)), 353.5),
        _model("XH430-W350", 1000, 648, ((1.2, 3.1), (1.3, 3.4), (1.5, 4.2)), 353.5),
        _model("XM540-W270", 1120, 2047, ((4.2, 10.0), (4.4, 10.6), (5.5, 12.9)), 272.5),
        _model("XH540-W270", 1100, 2047, ((4.5, 9.2), (4.9, 9.9), (5.9, 11.7)), 272.5),
    )
}
"""Supported servos by name (model numbers and Current Limit from their control tables)."""


def get_model(model: DynamixelModel | str) -> DynamixelModel:
    """The catalogue entry for a model name (a model passes through).

    Raises:
        CommandError: The name is not in :data:`DYNAMIXEL_MODELS`.
    """
    if isinstance(model, DynamixelModel):
        return model
    try:
        return DYNAMIXEL_MODELS[model]
    except KeyError:
        raise CommandError(
            -1, "model", f"{model!r} is not one of {sorted(DYNAMIXEL_MODELS)}"
        ) from None


def _interpolate(points: tuple[tuple[float, float], ...], x: float) -> float:
    """Piecewise-linear y(x) for increasing x ≥ 0, extrapolating the last segment."""
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        if x <= x1:
            return y0 + (y1 - y0) * (x - x0) / (x1 - x0)
    (x0, y0), (x1, y1) = points[-2], points[-1]
    return y1 + (y1 - y0) * (x - x1) / (x1 - x0)


def torque_from_current(model: DynamixelModel | str, current_A: float) -> float:
    """Output torque (N·m) the servo makes at ``current_A`` (odd: sign follows current)."""
    spec = get_model(model)
    magnitude = _interpolate(spec.torque_table, abs(current_A))
    return math.copysign(magnitude, current_A) if current_A else 0.0


def current_from_torque(model: DynamixelModel | str, torque_Nm: float) -> float:
    """Current (A) that makes ``torque_Nm`` (the inverse of :func:`torque_from_current`)."""
    spec = get_model(model)
    inverse = tuple((torque, current) for current, torque in spec.torque_table)
    magnitude = _interpolate(inverse, abs(torque_Nm))
    return math.copysign(magnitude, torque_Nm) if torque_Nm else 0.0


def goal_current_from_torque(model: DynamixelModel | str, torque_Nm: float) -> int:
    """Goal Current (102) in 2.69 mA units for an output torque.

    The torque is clamped to ± the stall torque at 12 V, mapped through the
    model's torque table, rounded to the unit and clamped to ± Current Limit.

    Raises:
        CommandError: ``torque_Nm`` is NaN or infinite (never sent).
    """
    spec = get_model(model)
    if not math.isfinite(torque_Nm):
        raise CommandError(-1, "torque_Nm", f"{torque_Nm=} is not finite; nothing was sent")
    torque_Nm = max(-spec.stall_torque_Nm, min(spec.stall_torque_Nm, torque_Nm))
    units = round(current_from_torque(spec, torque_Nm) / spec.current_unit_A)
    return max(-spec.current_limit_units, min(spec.current_limit_units, units))
