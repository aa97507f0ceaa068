"""Typed errors of the wire protocol.

Every problem the server finds with a request is answered with an ``error``
message carrying one of these codes, the offending field and a sentence that
says what to fix. The same codes raise as :class:`ProtocolError` in Python.
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["ErrorCode", "PoiseError", "ProtocolError"]


class ErrorCode(IntEnum):
    """Error codes carried by the ``error`` message (stable on the wire)."""

    MALFORMED = 1
    """The bytes are not a msgpack map (garbage, truncated, too large)."""
    UNSUPPORTED_VERSION = 2
    """The ``version`` key is missing or not the server's protocol version."""
    UNKNOWN_TYPE = 3
    """The ``type`` key names no message of this protocol."""
    INVALID_FIELD = 4
    """A key is missing, unknown, or has the wrong type or range."""
    BAD_SHAPE = 5
    """A numeric array has the wrong length for the robot of this session."""
    NON_FINITE = 6
    """A numeric array holds NaN or infinity where finite values are required."""
    NO_SESSION = 7
    """A session message (``state``, ``set_params``) arrived before ``hello``."""
    MODEL_NOT_FOUND = 8
    """The model named in ``hello`` is neither built in nor a readable file."""
    MODEL_INVALID = 9
    """The model file could not be parsed or lacks what the controller needs."""
    MODEL_MISMATCH = 10
    """The client's expected model hash differs from the server's model."""
    UNKNOWN_CONTROLLER = 11
    """The controller named in ``hello`` does not exist."""
    INVALID_PARAMS = 12
    """A controller parameter is unknown or its value is out of range."""
    UNEXPECTED_MESSAGE = 13
    """A reply-only message (``welcome``, ``command``, …) was sent to the server."""
    INTERNAL = 14
    """The controller failed on a valid request; the session is kept."""


class PoiseError(Exception):
    """Base class of every error Poise raises on purpose."""


class ProtocolError(PoiseError):
    """A request or reply that breaks the protocol.

    Attributes:
        code: What kind of problem it is.
        field: Dotted path of the offending key (``""`` if the whole message).
        detail: Human-readable explanation, including the bad value.
        seq: Sequence number of the offending request, ``-1`` if unknown.
    """

    def __init__(self, code: ErrorCode, field: str, detail: str, seq: int = -1):
        self.code = ErrorCode(code)
        self.field = field
        self.detail = detail
        self.seq = seq
        where = f" at {field!r}" if field else ""
        super().__init__(f"{self.code.name}{where}: {detail}")
