"""msgpack codec: :class:`~protocol.messages.Message` ⇄ bytes.

Pure functions, no I/O. :func:`decode` validates once, at the edge, and turns
every problem into a :class:`~protocol.errors.ProtocolError` naming the field.
Well-formed messages of the 1 kHz loop (``state``, ``command``, …) are read by
the fast path of :mod:`protocol.fastpath`; anything it cannot vouch for is
validated by pydantic, whose error names the field.
"""

from __future__ import annotations

import io
from typing import Any, NamedTuple

import msgpack
from pydantic import ValidationError

from protocol.errors import ErrorCode, ProtocolError
from protocol.fastpath import Fallback, Reader, reader
from protocol.messages import MESSAGE_TYPES, PROTOCOL_VERSION, Message

__all__ = ["MAX_MESSAGE_BYTES", "MAX_VALUES", "Head", "decode", "encode", "peek"]

MAX_MESSAGE_BYTES = 16 * 1024 * 1024
"""Largest message :func:`decode` accepts unless told otherwise (``poise serve``'s default)."""

MAX_VALUES = 32_768
"""Most msgpack values (maps, arrays, scalars, strings) a message may hold.

Arrays of numbers travel as ``bin``, one value each, so no Poise message
needs more than a few thousand (a hello's parameters, contacts and file
names); a 14 MB message of 15 M empty arrays would take msgpack 10 s and
1 GB to build. A message over :data:`SCAN_ABOVE_BYTES` is scanned first,
and refused at the value after this many."""
MAX_DEPTH = 16
"""Deepest nesting of maps and arrays a message may have (a hello's is 4)."""
SCAN_ABOVE_BYTES = 64 * 1024
"""Messages this long or shorter hold at most this many values: decoded at once."""

_MAP_BYTES = frozenset([*range(0x80, 0x90), 0xDE, 0xDF])
_ARRAY_BYTES = frozenset([*range(0x90, 0xA0), 0xDC, 0xDD])
_STR_BYTES = frozenset([*range(0xA0, 0xC0), 0xD9, 0xDA, 0xDB])


class Head(NamedTuple):
    """What a broker routes a message by, read without validating it.

    ``type`` is ``None`` if not a string, ``seq`` -1 if not a valid one;
    ``names_files``: a ``hello`` naming files by hash; ``refusal``: a long
    message's scan found it over a cap (what :func:`decode` would raise).
    """

    type: str | None
    seq: int
    names_files: bool
    refusal: ProtocolError | None = None


def peek(data: bytes) -> Head:
    """A message's :class:`Head`, at a cost bounded whatever its shape; nothing validated.

    A short message is decoded; a long one is walked (:func:`_scan`) without
    building its values. Garbage has no type (the full :func:`decode` says what
    is wrong); a message over :data:`MAX_VALUES` or :data:`MAX_DEPTH` has the
    refusal to answer, so that it is scanned once.
    """
    if len(data) <= SCAN_ABOVE_BYTES:
        try:
            head = msgpack.unpackb(data, raw=False, strict_map_key=True)
        except Exception:
            return Head(None, -1, False)
        if not isinstance(head, dict):
            return Head(None, -1, False)
        kind = head.get("type")
        return Head(
            kind if isinstance(kind, str) else None,
            _seq_of(head),
            bool(head.get("model_asset_hashes")),
        )
    try:
        fields = _scan(data)
    except ProtocolError as exc:
        refusal = exc.with_traceback(None) if exc.code == ErrorCode.LIMIT_EXCEEDED else None
        return Head(None, -1, False, refusal)  # no traceback: it would hold the message
    kind = fields.get("type")
    return Head(kind if isinstance(kind, str) else None, _seq_of(fields), bool(fields.get("names")))


def _scan(data: bytes) -> dict[str, Any]:
    """Walk every value of ``data`` without building it; return the top map's scalars.

    One pass of msgpack's own ``skip`` and header reads, stopped at the
    :data:`MAX_VALUES`-th value or the :data:`MAX_DEPTH`-th level, so its cost
    is bounded by those caps, not by the message's shape. Returns the top
    map's ``type`` and ``seq`` (when scalars) and ``names``: whether
    ``model_asset_hashes`` is a non-empty map.

    Raises:
        ProtocolError: Not one msgpack map, or over a cap (``LIMIT_EXCEEDED``).
    """
    # read from a view of ``data`` in small pieces: no copy of a long message
    unpacker = msgpack.Unpacker(io.BytesIO(data), raw=False, max_buffer_size=len(data))
    fields: dict[str, Any] = {}
    remaining = [1]  # values still to read at each open level
    values = 0
    key: Any = None  # the top map's current key, when reading its value
    try:
        if data[0] not in _MAP_BYTES:
            raise ProtocolError(ErrorCode.MALFORMED, "", "expected a msgpack map")
        while remaining:
            if not remaining[-1]:
                remaining.pop()
                continue
            remaining[-1] -= 1
            values += 1
            if values > MAX_VALUES:
                raise ProtocolError(
                    ErrorCode.LIMIT_EXCEEDED,
                    "",
                    f"the message holds more than {MAX_VALUES} msgpack values; no Poise "
                    "message needs that many (arrays of numbers travel as bin)",
                )
            top = len(remaining) == 2  # inside the top map
            first = data[unpacker.tell()]
            if top and remaining[-1] % 2 == 1:  # a key of the top map
                if first not in _STR_BYTES:
                    raise ProtocolError(ErrorCode.MALFORMED, "", "a key that is not a string")
                key = unpacker.unpack()
                continue
            if first in _MAP_BYTES:
                count = unpacker.read_map_header()
                if top and key == "model_asset_hashes":
                    fields["names"] = count > 0
                children = 2 * count
            elif first in _ARRAY_BYTES:
                children = unpacker.read_array_header()
            elif top and key in ("type", "seq"):
                fields[key] = unpacker.unpack()
                continue
            else:
                unpacker.skip()
                continue
            if len(remaining) > MAX_DEPTH:
                raise ProtocolError(
                    ErrorCode.LIMIT_EXCEEDED,
                    "",
                    f"the message nests maps and arrays deeper than {MAX_DEPTH} levels",
                )
            remaining.append(children)
    except (msgpack.OutOfData, IndexError, ValueError, msgpack.ExtraData) as exc:
        raise ProtocolError(
            ErrorCode.MALFORMED, "", f"not a msgpack message ({type(exc).__name__}: {exc})"
        ) from None
    if unpacker.tell() != len(data):
        raise ProtocolError(ErrorCode.MALFORMED, "", "bytes after the message's map")
    return fields


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
    if len(data) > SCAN_ABOVE_BYTES:
        _scan(data)  # bounded: refuses a message whose decoding would not be
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
        except Fallback as fallback:  # pydantic says what is wrong, or converts what it may
            # One shared instance: each raise would add this request's frames (its bytes,
            # map and reply) to its traceback, for good (issue 32, finding 6).
            fallback.__traceback__ = None
    try:
        return cls.model_validate(payload)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        field = ".".join(str(part) for part in first["loc"])
        code = _ERROR_CODES.get(first["type"], ErrorCode.INVALID_FIELD)
        raise ProtocolError(code, field, f"{first['msg']} (in {kind!r})", seq) from None
