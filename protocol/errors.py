"""Typed errors of the wire protocol.

Every problem the server finds with a request is answered with an ``error``
message carrying one of these codes, the offending field and a sentence that
says what to fix. The same codes raise as :class:`ProtocolError` in Python.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from enum import IntEnum
from typing import Any

__all__ = ["AssetsMissing", "ErrorCode", "PoiseError", "ProtocolError", "did_you_mean"]


class ErrorCode(IntEnum):
    """Error codes carried by the ``error`` message (stable on the wire).

    Each member has a ``description`` (what it means and what to check).
    """

    description: str

    def __new__(cls, value: int, description: str) -> ErrorCode:  # noqa: D102
        member = int.__new__(cls, value)
        member._value_ = value
        member.description = description
        return member

    MALFORMED = 1, "The bytes are not one msgpack map (garbage, truncated, several frames)."
    UNSUPPORTED_VERSION = 2, "`version` is missing or not the server's protocol version."
    UNKNOWN_TYPE = 3, "`type` names no message of this protocol."
    INVALID_FIELD = 4, "A key is missing, unknown, or has the wrong type or range."
    BAD_SHAPE = 5, "A numeric array has the wrong length (for the message or this robot)."
    NON_FINITE = 6, "A numeric value is NaN or infinite where finite values are required."
    NO_SESSION = 7, "`state`, `set_params` or `bye` arrived before `hello` (or after expiry)."
    MODEL_NOT_FOUND = 8, "The model in `hello` is neither built in nor a readable server file."
    MODEL_INVALID = 9, "The model could not be parsed, or lacks contacts or supported joints."
    MODEL_MISMATCH = 10, "`expected_model_hash` differs from the hash of the server's model."
    UNKNOWN_CONTROLLER = 11, "The controller named in `hello` does not exist."
    INVALID_PARAMS = 12, "A controller parameter is unknown or its value is out of range."
    UNEXPECTED_MESSAGE = 13, "A reply-only message (`welcome`, `command`, …) was sent as a request."
    INTERNAL = (
        14,
        (
            "The server failed on a valid request (a bug: please report it with the request); "
            "the session is kept."
        ),
    )
    DEADLINE_EXCEEDED = (
        15,
        (
            "The request was not served within the server's deadline (`poise serve --deadline`); "
            "nothing was computed for it that could reach an actuator."
        ),
    )
    LIMIT_EXCEEDED = (
        16,
        (
            "A server cap was hit (sessions per server or client, requests in flight per "
            "session, message size, model size, asset uploads); the detail names the cap and "
            "its option."
        ),
    )
    ASSETS_MISSING = (
        17,
        (
            "The server's asset cache lacks files `hello.model_asset_hashes` names (or this "
            "client has not uploaded them): `missing_asset_hashes` lists their SHA-256; upload "
            "each with `asset`, then repeat the `hello`."
        ),
    )
    SOLVE_FAILED = (
        18,
        (
            "The controller could not find a command for this state (no solution within its "
            "iteration caps or `qp_time_budget_s`, a linear solve failed, or the dynamics "
            "overflow); nothing was sent that could reach an actuator: hold the robot's safe "
            "behaviour, the session is kept and the next state is solved afresh."
        ),
    )


class PoiseError(Exception):
    """Base class of every error Poise raises on purpose.

    It survives pickling whatever its subclass's ``__init__`` takes (a run on
    a worker process or a Dask worker raises it in the caller as it was).
    """

    def __reduce__(self) -> tuple[Any, ...]:
        return _rebuild_error, (type(self), self.args, self.__dict__)


def _rebuild_error(cls: type[PoiseError], args: tuple[Any, ...], state: dict[str, Any]) -> Any:
    """An unpickled :class:`PoiseError`: its arguments and attributes, without ``__init__``."""
    error = cls.__new__(cls, *args)
    error.args = args
    error.__dict__.update(state)
    return error


class ProtocolError(PoiseError):
    """A request or reply that breaks the protocol.

    Attributes:
        code: What kind of problem it is.
        field: Dotted path of the offending key (``""`` if the whole message).
        detail: Human-readable explanation, including the bad value.
        seq: Sequence number of the offending request, ``-1`` if unknown.
    """

    def __init__(self, code: ErrorCode, field: str, detail: str, seq: int = -1):
        self.code = code
        self.field = field
        self.detail = detail
        self.seq = seq
        where = f" at {field!r}" if field else ""
        super().__init__(f"{self.code.name}{where}: {detail}")


class AssetsMissing(ProtocolError):
    """A ``hello`` names files by SHA-256 that the server does not hold for this client.

    Attributes:
        missing: SHA-256 (lowercase hex) of each file to upload, sorted, without repeats.
    """

    def __init__(self, missing: list[str], seq: int = -1):
        self.missing = sorted(set(missing))
        super().__init__(
            ErrorCode.ASSETS_MISSING,
            "model_asset_hashes",
            f"the server's asset cache lacks {len(self.missing)} of the files named in "
            "`model_asset_hashes` (or this client never uploaded them): upload each with "
            "`asset`, then repeat the hello",
            seq,
        )


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``"did you mean 'left_knee'? "`` for the closest of ``known`` to a misspelled ``name``.

    Empty when nothing is close (``difflib``'s ratio under 0.6): every "no such
    name" message in Poise puts this before the list of the names it knows.
    """
    close = difflib.get_close_matches(name, list(known), n=1)
    return f"did you mean {close[0]!r}? " if close else ""
