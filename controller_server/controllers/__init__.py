"""Controllers behind one interface, looked up by name."""

from collections.abc import Mapping
from typing import Any

from controller_server.controllers.base import ControlInput, Controller, ControlOutput, ParamSpec
from controller_server.controllers.momentum import MomentumController, TrackingController
from controller_server.controllers.prioritized import PrioritizedController
from controller_server.errors import UnknownController
from controller_server.models import RobotModel

__all__ = [
    "CONTROLLERS",
    "ControlInput",
    "ControlOutput",
    "Controller",
    "MomentumController",
    "ParamSpec",
    "PrioritizedController",
    "TrackingController",
    "create_controller",
]

CONTROLLERS: dict[str, type[Controller]] = {
    cls.name: cls for cls in (TrackingController, MomentumController, PrioritizedController)
}
"""Controller classes by the name a client gives in ``hello``."""


def create_controller(
    name: str, robot: RobotModel, params: Mapping[str, Any] | None = None
) -> Controller:
    """Instantiate the controller called ``name`` for ``robot``.

    Raises:
        UnknownController: No controller has that name.
    """
    cls = CONTROLLERS.get(name)
    if cls is None:
        raise UnknownController("controller", f"{name=!r}; available: {sorted(CONTROLLERS)}")
    return cls(robot, params)
