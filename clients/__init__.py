"""Poise clients: the shared client library and, per kind, the clients built on it."""

from clients.client import (
    ControllerClient,
    CurveKeys,
    InvalidKeyFile,
    ServerError,
    ServerTimeout,
)
from clients.layout import joint_slices, neutral_joint_position
from protocol.recording import BadLog, Recorder, read_log

__all__ = [
    "BadLog",
    "ControllerClient",
    "CurveKeys",
    "InvalidKeyFile",
    "Recorder",
    "ServerError",
    "ServerTimeout",
    "joint_slices",
    "neutral_joint_position",
    "read_log",
]
