"""Robot models: built-in MJCF files and the loader that reads them with Pinocchio."""

from controller_server.models.robot_model import (
    BUILTIN_MODELS,
    DEFAULT_MODEL_CACHE_SIZE,
    MODEL_FILES,
    Contact,
    RobotModel,
    load_robot_model,
    set_model_cache_size,
)

__all__ = [
    "BUILTIN_MODELS",
    "DEFAULT_MODEL_CACHE_SIZE",
    "MODEL_FILES",
    "Contact",
    "RobotModel",
    "load_robot_model",
    "set_model_cache_size",
]
