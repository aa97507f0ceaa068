"""Point targets of the weighted controller as ``set_params`` gives them (Macchietto eq. 6.1–6.3).

``point:<name>`` adds or moves a soft point-acceleration objective on a frame of the robot;
``null`` removes it. :func:`point_target` validates one as the other parameters are
validated: a typed :class:`~controller_server.errors.InvalidParams` naming the key.
"""

from __future__ import annotations

import math
from typing import Any

from controller_server.controllers.base import vector_value
from controller_server.errors import InvalidParams
from controller_server.features import PointTarget
from controller_server.models import RobotModel
from controller_server.tasks import POINT_PREFIX

__all__ = ["POINT_DEFAULTS", "POINT_PREFIX", "point_target"]

POINT_DEFAULTS: dict[str, Any] = {
    "offset_in_frame": [0.0, 0.0, 0.0],
    "target_velocity_in_world": [0.0, 0.0, 0.0],
    "stiffness": 100.0,
    "damping": 20.0,
    "weight": 1.0,
}
"""Defaults of a point target's optional keys."""


def point_target(robot: RobotModel, key: str, value: Any) -> PointTarget | None:
    """The point target ``value`` of parameter ``key`` (``point:<name>``), or ``None`` to remove it.

    Raises:
        InvalidParams: Not a map, an unknown key, no such frame, a gain or weight that is not
            a finite number ≥ 0, a vector that is not three finite numbers, or no target.
    """
    field = f"params.{key}"
    if value is None:
        return None
    if not isinstance(value, dict):
        raise InvalidParams(field, "a point target is a map (frame, target_position_in_world, …)")
    unknown = set(value) - {"frame", "target_position_in_world", *POINT_DEFAULTS}
    if unknown:
        raise InvalidParams(field, f"unknown keys {sorted(unknown)}")
    frame = value.get("frame")
    if not isinstance(frame, str) or not robot.model.existFrame(frame):
        frames = [f.name for f in robot.model.frames]
        raise InvalidParams(f"{field}.frame", f"{frame=!r} is not a frame; available: {frames}")
    merged = {**POINT_DEFAULTS, **value}
    scalars = {}
    for name in ("stiffness", "damping", "weight"):
        number = merged[name]
        if isinstance(number, bool) or not isinstance(number, int | float):
            raise InvalidParams(f"{field}.{name}", f"{number!r} is not a number")
        try:
            scalars[name] = float(number)
        except OverflowError:  # a Python int beyond the float range (not printed: huge)
            raise InvalidParams(f"{field}.{name}", "beyond the float range") from None
        if not math.isfinite(number) or number < 0:
            raise InvalidParams(f"{field}.{name}", f"{number!r} must be finite and ≥ 0")
    if "target_position_in_world" not in value:
        raise InvalidParams(f"{field}.target_position_in_world", "required")
    return PointTarget(
        frame=frame,
        offset_in_frame=vector_value(f"{field}.offset_in_frame", merged["offset_in_frame"], 3),
        target_position_in_world=vector_value(
            f"{field}.target_position_in_world", merged["target_position_in_world"], 3
        ),
        target_velocity_in_world=vector_value(
            f"{field}.target_velocity_in_world", merged["target_velocity_in_world"], 3
        ),
        **scalars,
    )
