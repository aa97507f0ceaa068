"""Robot models: built-in MJCF files and the loader that reads them with Pinocchio."""

from controller_server.models.robot_model import (
    BUILTIN_MODELS,
    Contact,
    RobotModel,
    load_robot_model,
)

__all__ = ["BUILTIN_MODELS", "Contact", "RobotModel", "load_robot_model"]
