"""Poise clients: the shared client library and, per kind, the clients built on it."""

from clients.client import (
    ControllerClient,
    CurveKeys,
    InvalidKeyFile,
    ServerError,
    ServerTimeout,
)
from clients.layout import joint_slices, neutral_joint_position

__all__ = [
    "ControllerClient",
    "CurveKeys",
    "InvalidKeyFile",
    "ServerError",
    "ServerTimeout",
    "joint_slices",
    "neutral_joint_position",
]
