"""msgpack codec: :class:`~protocol.messages.Message` ⇄ bytes.

Pure functions, no I/O. :func:`decode` validates once, at the edge, and turns
every problem into a :class:`~protocol.errors.ProtocolError` naming the field.
Well-formed messages of the 1 kHz loop (``state``, ``command``, …) are read by
the fast path of :mod:`protocol.fastpath`; anything it cannot vouch for is
validated by pydantic, whose error names the field.
"""

from __future__ import annotations

from typing import Any

import msgpack
from pydantic import ValidationError

from protocol.errors import ErrorCode, ProtocolError
from protocol.fastpath import Fallback, Reader, reader
from protocol.messages import MESSAGE_TYPES, PROTOCOL_VERSION, Message

__all__ = ["MAX_MESSAGE_BYTES", "decode", "encode"]

MAX_MESSAGE_BYTES = 16 * 1024 * 1024
"""Largest message :func:`decode` accepts unless told otherwise (``poise serve``'s default)."""

_ERROR_CODES = {
    "non_finite": ErrorCode.NON_FINITE,
    "bad_shape": ErrorCode.BAD_SHAPE,
    "finite_number": ErrorCode.NON_FINITE,
}

_READERS: dict[type[Message], Reader | None] = {cls: reader(cls) for cls in MESSAGE_TYPES.values()}


def encode(message: Message) -> bytes:
    """Serialise a message to msgpack bytes (arrays as little-endian float64)."""
    return msgpack.packb(message.model_dump(mode="python"), use_bin_type=True)


def _seq_of(payload: dict[Any, Any]) -> int:
    seq = payload.get("seq")
    return seq if type(seq) is int and 0 <= seq < 2**63 else -1


def decode(data: bytes, max_bytes: int = MAX_MESSAGE_BYTES) -> Message:
    """Parse and validate one message.

    Args:
        data: The bytes of one ZeroMQ frame.
        max_bytes: Longer data is refused before it is parsed (a server passes its
            ``--max-message-bytes``).

    Returns:
        The validated message, an instance of the class its ``type`` names.

    Raises:
        ProtocolError: With the code and field of the first problem found.
    """
    if len(data) > max_bytes:
        raise ProtocolError(
            ErrorCode.MALFORMED, "", f"message of {len(data)} bytes exceeds {max_bytes}"
        )
    try:
        payload = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises many unrelated types on garbage
        raise ProtocolError(
            ErrorCode.MALFORMED, "", f"not a msgpack message ({type(exc).__name__}: {exc})"
        ) from None
    if not isinstance(payload, dict):
        raise ProtocolError(
            ErrorCode.MALFORMED, "", f"expected a msgpack map, got {type(payload).__name__}"
        )
    seq = _seq_of(payload)
    version = payload.get("version")
    if version != PROTOCOL_VERSION or isinstance(version, bool):
        raise ProtocolError(
            ErrorCode.UNSUPPORTED_VERSION,
            "version",
            f"{version=!r}; this server speaks protocol version {PROTOCOL_VERSION}",
            seq,
        )
    kind = payload.get("type")
    cls = MESSAGE_TYPES.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ProtocolError(
            ErrorCode.UNKNOWN_TYPE,
            "type",
            f"type={kind!r}; expected one of {sorted(MESSAGE_TYPES)}",
            seq,
        )
    read = _READERS[cls]
    if read is not None:
        try:
            return read(payload)  # type: ignore[return-value]
        except Fallback:  # pydantic says what is wrong, or converts what it may
            pass
    try:
        return cls.model_validate(payload)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        field = ".".join(str(part) for part in first["loc"])
        code = _ERROR_CODES.get(first["type"], ErrorCode.INVALID_FIELD)
        raise ProtocolError(code, field, f"{first['msg']} (in {kind!r})", seq) from None
