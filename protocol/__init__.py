"""The Poise wire contract: messages, msgpack codec, version, error codes; logs of it."""

from protocol.codec import MAX_MESSAGE_BYTES, decode, encode
from protocol.endpoints import InvalidEndpoint, check_endpoint
from protocol.errors import ErrorCode, PoiseError, ProtocolError
from protocol.messages import (
    MESSAGE_TYPES,
    PROTOCOL_VERSION,
    Bye,
    Command,
    ContactSpec,
    Diagnostics,
    Error,
    Hello,
    JointInfo,
    Message,
    Params,
    PriorityLevelReport,
    SessionStats,
    SetParams,
    State,
    Stats,
    Welcome,
)

__all__ = [
    "MAX_MESSAGE_BYTES",
    "MESSAGE_TYPES",
    "PROTOCOL_VERSION",
    "Bye",
    "Command",
    "ContactSpec",
    "Diagnostics",
    "Error",
    "ErrorCode",
    "Hello",
    "InvalidEndpoint",
    "JointInfo",
    "Message",
    "Params",
    "PoiseError",
    "PriorityLevelReport",
    "ProtocolError",
    "SessionStats",
    "SetParams",
    "State",
    "Stats",
    "Welcome",
    "check_endpoint",
    "decode",
    "encode",
]
