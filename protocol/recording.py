"""Poise conversation logs: record protocol messages to MCAP and read them back.

A log is an `MCAP <https://mcap.dev>`_ file with one channel per message
type (topic = the ``type``: ``hello``, ``welcome``, ``state``, ``command``,
``set_params``, ``params``, ``stats``, ``asset``, ``asset_received``, ``bye``,
``error``). Each channel has a
JSON Schema (schema encoding ``jsonschema``) and its messages are JSON
(message encoding ``json``), so Foxglove opens the file as it is. A logged
message is the protocol message as a JSON object plus one envelope key:

- ``direction``: ``"sent"`` or ``"received"``, seen from the recorder's side.
- Numeric arrays are JSON lists of numbers. JSON has no NaN or infinity:
  every non-finite number (in an array or a scalar) is written as ``null``
  and reads back as NaN (a ``float | None`` field reads back as ``None``).

The recorders of Poise (the client's, the server's) write a ``hello`` with the
files of its model inline (``model_assets``), whether they travelled inline or
by hash (``model_asset_hashes`` and ``asset`` uploads, which are not recorded):
a log replays on a server that never saw them.

The MCAP log time (and publish time) of a message is the time of the event in
nanoseconds since the Unix epoch; the MCAP ``sequence`` counts the messages
the recorder accepted, so a gap shows what it dropped.

Crash safety: :class:`Recorder` hands messages to a writer thread that closes
a chunk and flushes the file every ``flush_interval_s`` (and at once after a
handshake, ``set_params``/``params``, ``error`` or ``bye`` message), so a
process killed mid-run loses at most the messages of the last interval.
:func:`read_log` reads such a truncated file up to its last complete chunk.
"""

from __future__ import annotations

import base64
import json
import logging
import math
import os
import queue
import struct
import threading
import time
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Literal

import numpy as np
import orjson
from mcap.exceptions import McapError
from mcap.records import Channel, Header
from mcap.records import Message as McapMessage
from mcap.stream_reader import MAGIC_SIZE, StreamReader
from mcap.writer import CompressionType, Writer
from pydantic import BaseModel, ValidationError

from protocol.errors import PoiseError
from protocol.messages import MESSAGE_TYPES, Message

__all__ = [
    "CHUNK_SIZE",
    "QUEUE_LIMIT",
    "BadLog",
    "LogReader",
    "LoggedMessage",
    "Recorder",
    "encode_logged",
    "message_json_schema",
    "read_log",
]

log = logging.getLogger("poise.record")

Direction = Literal["sent", "received"]

CHUNK_SIZE = 256 * 1024
"""A chunk closes at this size (bytes, uncompressed) even before ``flush_interval_s``."""
QUEUE_LIMIT = 10_000
"""Messages waiting for the writer thread; beyond it ``record`` drops (slow disk)."""

_MCAP_MAGIC = bytes([137, 77, 67, 65, 80, 48, 13, 10])
# Rare messages that a replay cannot do without: written to disk at once.
_FLUSH_AT_ONCE = frozenset({"hello", "welcome", "set_params", "params", "error", "bye"})
_STOP = object()


class BadLog(PoiseError, ValueError):
    """A file is not a readable Poise log (empty, not MCAP, or corrupt).

    Attributes:
        path: The file.
        detail: What is wrong with it.
    """

    def __init__(self, path: str | os.PathLike[str], detail: str):
        self.path = Path(path)
        self.detail = detail
        super().__init__(f"{str(path)!r} is not a readable Poise log: {detail}")


@dataclass(frozen=True)
class LoggedMessage:
    """One message read back from a log.

    Attributes:
        time_ns: Time of the event, ns since the Unix epoch (MCAP log time).
        direction: ``"sent"`` or ``"received"`` from the recorder's side.
        seq: The message's protocol ``seq``.
        message: The protocol message, validated again (arrays are numpy).
    """

    time_ns: int
    direction: Direction
    seq: int
    message: Message


def _fields(value: Any) -> Any:
    """Orjson's fallback: a message (or nested model) as its fields, bytes (files) as base64."""
    if isinstance(value, BaseModel):
        return {name: getattr(value, name) for name in type(value).model_fields}
    if isinstance(value, bytes):
        return base64.b64encode(value).decode("ascii")
    raise TypeError(f"cannot log a {type(value).__name__}")


def encode_logged(message: Message, direction: Direction) -> bytes:
    """The JSON bytes logged for ``message`` (see the module docstring).

    orjson writes numpy arrays and enums natively, every float in its shortest
    exact form (a replay compares against the very numbers sent) and NaN and
    infinity as ``null``: 8 µs for a thesis-humanoid command with diagnostics
    (from ``tests/fixtures/replay_momentum_push.mcap``), against 113 µs with the
    standard library's encoder, whose cost made recording slow the loop by 15 %.
    """
    data = _fields(message)
    data["direction"] = direction
    return orjson.dumps(data, default=_fields, option=orjson.OPT_SERIALIZE_NUMPY)


def _revive(annotation: Any, value: Any) -> Any:
    """Undo :func:`_to_json`'s ``null`` for NaN where the field's type expects a number."""
    origin = typing.get_origin(annotation)
    if value is None:
        if annotation is float:
            return math.nan
        return None
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        if not isinstance(value, dict):
            return value
        fields = annotation.model_fields
        return {
            key: _revive(fields[key].annotation, item) if key in fields else item
            for key, item in value.items()
        }
    if annotation is bytes and isinstance(value, str):
        return base64.b64decode(value)
    if typing.get_origin(annotation) is typing.Annotated:
        return _revive(typing.get_args(annotation)[0], value)
    if annotation is np.ndarray and isinstance(value, list):
        return [math.nan if item is None else item for item in value]
    if origin in (typing.Union, types.UnionType):
        options = [arg for arg in typing.get_args(annotation) if arg is not type(None)]
        return _revive(options[0], value) if len(options) == 1 else value
    if origin in (list, tuple) and isinstance(value, list):
        args = typing.get_args(annotation)
        if origin is tuple and args and args[-1] is not Ellipsis:
            return [_revive(arg, item) for arg, item in zip(args, value, strict=False)]
        return [_revive(args[0], item) for item in value] if args else value
    if origin is dict and isinstance(value, dict):
        item_type = typing.get_args(annotation)[1]
        return {key: _revive(item_type, item) for key, item in value.items()}
    return value


def _json_array_schemas(node: Any) -> Any:
    """Describe what the JSON holds: arrays as number lists, ``null`` for non-finite numbers."""
    if isinstance(node, list):
        return [_json_array_schemas(item) for item in node]
    if not isinstance(node, dict):
        return node
    node = {key: _json_array_schemas(item) for key, item in node.items()}
    if node.get("type") == "string" and node.get("format") == "binary":
        del node["format"]
        node["type"] = "array"
        node["items"] = {"type": ["number", "null"]}
    elif node.get("type") == "number":
        node["type"] = ["number", "null"]
    return node


def _inline_refs(node: Any, definitions: dict[str, Any]) -> Any:
    """Replace every ``$ref`` by its definition (viewers handle self-contained schemas best)."""
    if isinstance(node, list):
        return [_inline_refs(item, definitions) for item in node]
    if not isinstance(node, dict):
        return node
    if "$ref" in node:
        rest = {key: item for key, item in node.items() if key != "$ref"}
        target = definitions[node["$ref"].rsplit("/", 1)[-1]]
        return {**_inline_refs(target, definitions), **_inline_refs(rest, definitions)}
    return {key: _inline_refs(item, definitions) for key, item in node.items()}


def message_json_schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of the logged messages of type ``kind`` (self-contained, no ``$ref``).

    It is the pydantic model's schema with arrays described as lists of
    numbers (``null`` for non-finite values) and the ``direction`` envelope key.
    """
    schema = MESSAGE_TYPES[kind].model_json_schema()
    definitions = schema.pop("$defs", {})
    schema = _json_array_schemas(_inline_refs(schema, definitions))
    schema["properties"]["direction"] = {
        "description": "Sent or received, seen from the recorder's side (log envelope).",
        "enum": ["sent", "received"],
        "type": "string",
    }
    schema["required"] = [*schema.get("required", []), "direction"]
    return dict(schema)


class Recorder:
    """Write a Poise conversation to an MCAP file without ever raising into the loop.

    :meth:`record` only queues the message; a writer thread serialises it,
    closes a chunk and flushes the file at least every ``flush_interval_s``.
    A write error (disk full) or a full queue (disk slower than the loop)
    drops messages: counted in :attr:`dropped`, logged once on the
    ``poise.record`` logger.

    Args:
        path: The log file (created or overwritten).
        flush_interval_s: Longest time a recorded message stays in memory;
            a SIGKILL loses at most about this much of the log.

    Raises:
        OSError: The file cannot be created.

    Example:
        >>> with Recorder("session.mcap") as recorder:  # doctest: +SKIP
        ...     recorder.record(state, "sent")
    """

    def __init__(self, path: str | os.PathLike[str], *, flush_interval_s: float = 0.1):
        if not flush_interval_s > 0:
            raise ValueError(f"{flush_interval_s=} must be positive")
        self.path = Path(path)
        self.flush_interval_s = flush_interval_s
        self._file: BinaryIO = open(self.path, "wb")  # closed in close()
        # zstd: a log of the thesis humanoid is 1.8× smaller than with LZ4 (JSON numbers
        # compress poorly; measured on a 300-tick recording, 1.66 MB of JSON: LZ4
        # 1.14 MB, zstd 0.64 MB), at about 1.5 ms of the writer thread per 0.1 s chunk.
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="poise")
        self._channels: dict[str, int] = {}
        for kind in MESSAGE_TYPES:
            schema = json.dumps(message_json_schema(kind)).encode()
            schema_id = self._writer.register_schema(kind, "jsonschema", schema)
            self._channels[kind] = self._writer.register_channel(kind, "json", schema_id)
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=QUEUE_LIMIT)
        self._lock = threading.Lock()
        self._dropped = 0
        self._written = 0
        self._unflushed = 0
        self._failed = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="poise-recorder", daemon=True)
        self._thread.start()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def dropped(self) -> int:
        """Messages that did not reach the file (write error, full queue, after close)."""
        return self._dropped

    @property
    def written(self) -> int:
        """Messages flushed to the file so far."""
        return self._written

    def record(self, message: Message, direction: Direction, time_ns: int | None = None) -> None:
        """Queue one message for the log; never raises, never blocks.

        Args:
            message: The protocol message as sent or received.
            direction: ``"sent"`` or ``"received"``, from the recorder's side.
            time_ns: Time of the event (ns since the Unix epoch); default: now.
        """
        event_ns = time.time_ns() if time_ns is None else time_ns
        if self._closed or self._failed:
            self._drop(1, "the recorder is closed" if self._closed else "")
            return
        try:
            self._queue.put_nowait((event_ns, direction, message))
        except queue.Full:
            self._drop(1, f"{QUEUE_LIMIT} messages wait for a disk that is too slow")

    def close(self) -> None:
        """Write what is queued, the summary and the footer, and close the file."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(_STOP)
        self._thread.join()
        try:
            if not self._failed:
                self._writer.add_metadata(
                    "poise_recorder", {"written": str(self._written), "dropped": str(self._dropped)}
                )
                self._writer.finish()
            self._file.close()
        except (OSError, ValueError) as exc:
            if not self._failed:
                self._fail(exc)
            try:
                self._file.close()
            except OSError:
                pass

    def _run(self) -> None:
        next_flush = time.monotonic() + self.flush_interval_s
        while True:
            try:
                item = self._queue.get(timeout=max(0.0, next_flush - time.monotonic()))
            except queue.Empty:
                item = None
            if item is _STOP:
                self._flush()
                return
            flush_now = False
            if item is not None:
                flush_now = self._write(*item)
            if flush_now or time.monotonic() >= next_flush:
                self._flush()
                next_flush = time.monotonic() + self.flush_interval_s

    def _write(self, time_ns: int, direction: Direction, message: Message) -> bool:
        """Add one message to the open chunk; whether it must reach the disk at once."""
        if self._failed:
            self._drop(1, "")
            return False
        try:
            data = encode_logged(message, direction)
            sequence = (self._written + self._unflushed + self._dropped) & 0xFFFFFFFF
            self._writer.add_message(
                self._channels[message.type], time_ns, data, time_ns, sequence=sequence
            )
        except Exception as exc:  # never let a bad message or a full disk stop the thread
            self._fail(exc, lost=1)
            return False
        self._unflushed += 1
        return message.type in _FLUSH_AT_ONCE

    def _flush(self) -> None:
        if self._failed or not self._unflushed:
            return
        try:
            self._writer.flush()
        except Exception as exc:
            self._fail(exc)
            return
        self._written += self._unflushed
        self._unflushed = 0

    def _fail(self, exc: BaseException, lost: int = 0) -> None:
        """Stop writing for good: the file may end in a partial record."""
        self._failed = True
        lost += self._unflushed
        self._unflushed = 0
        log.error(
            "recording to %s stopped (%s: %s); dropping every further message",
            self.path,
            type(exc).__name__,
            exc,
        )
        self._drop(lost, "")

    def _drop(self, count: int, reason: str) -> None:
        with self._lock:
            first = self._dropped == 0
            self._dropped += count
        if first and reason and count:
            log.error("recording to %s dropped a message: %s", self.path, reason)


def _check_start(path: Path) -> None:
    """Raise :class:`BadLog` unless the file starts with the MCAP magic and a header."""
    try:
        with open(path, "rb") as file:
            head = file.read(MAGIC_SIZE + 1)
    except OSError as exc:
        raise BadLog(path, f"cannot read it ({exc.strerror or exc})") from None
    if not head:
        raise BadLog(path, "the file is empty")
    if head[:MAGIC_SIZE] != _MCAP_MAGIC:
        raise BadLog(path, "no MCAP magic at its start (is it a `.mcap` recording?)")
    if len(head) > MAGIC_SIZE and head[MAGIC_SIZE] != 0x01:  # the header record opcode
        raise BadLog(path, f"the MCAP magic is not followed by a header (opcode {head[8]:#x})")


class LogReader:
    """The messages of a log in file order; iterate once.

    A log cut short (the recording process was killed, so no summary or
    footer) yields every message up to its last complete chunk, then logs a
    warning on ``poise.record`` naming how many messages were read; after the
    iteration :attr:`truncated` says so and :attr:`messages_read` counts them.

    Raises (while iterating):
        BadLog: A message that is not a Poise message, or an MCAP file written
            by another program.
    """

    def __init__(self, path: Path):
        self.path = path
        self.messages_read = 0
        self.truncated = False
        self.stopped_at_byte: int | None = None
        """Where reading stopped in a truncated log."""
        self._file: BinaryIO | None = None
        self._size_bytes = 0
        self._finished = False

    @property
    def fraction_read(self) -> float:
        """How much of the file has been read (0 to 1, by bytes): for a progress bar."""
        if self._finished:
            return 1.0
        if self._file is None or self._size_bytes == 0:
            return 0.0
        return min(1.0, self._file.tell() / self._size_bytes)

    def __iter__(self) -> Iterator[LoggedMessage]:
        channels: dict[int, Channel] = {}
        with open(self.path, "rb") as file:
            self._file, self._size_bytes = file, os.fstat(file.fileno()).st_size
            records = StreamReader(file, validate_crcs=True).records
            while True:
                try:
                    record = next(records)
                except StopIteration:
                    break
                except (McapError, ValueError, EOFError, struct.error, OSError, MemoryError) as exc:
                    self._cut_short(exc, file.tell())
                    break
                if isinstance(record, Header) and record.library != "poise":
                    raise BadLog(
                        self.path, f"written by {record.library!r}, not by a Poise recorder"
                    )
                if isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, McapMessage):
                    self.messages_read += 1
                    yield _logged(self.path, channels, record)
        self._file, self._finished = None, True

    def _cut_short(self, exc: BaseException, offset: int) -> None:
        self.truncated = True
        self.stopped_at_byte = offset
        reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        log.warning(
            "%s ends early (killed mid-recording?): read %d messages, stopped at byte %d (%s)",
            self.path,
            self.messages_read,
            offset,
            reason,
        )


def read_log(path: str | os.PathLike[str]) -> LogReader:
    """The messages of a log, in file order (see :class:`LogReader`).

    Raises:
        BadLog: The file is empty, not MCAP, or does not start with an MCAP header.
    """
    file_path = Path(path)
    _check_start(file_path)
    return LogReader(file_path)


def _logged(path: Path, channels: dict[int, Channel], record: McapMessage) -> LoggedMessage:
    channel = channels.get(record.channel_id)
    where = f"message at log time {record.log_time}"
    if channel is None or channel.topic not in MESSAGE_TYPES:
        raise BadLog(path, f"{where} is on an unknown channel {record.channel_id}")
    try:
        data = orjson.loads(record.data)
        direction = data.pop("direction")
        cls = MESSAGE_TYPES[channel.topic]
        message = cls.model_validate(_revive(cls, data))
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        first = exc.errors()[0]["msg"] if isinstance(exc, ValidationError) else exc
        raise BadLog(path, f"{where} on {channel.topic!r} is invalid ({first})") from None
    if direction not in ("sent", "received"):
        raise BadLog(path, f"{where} has direction {direction!r}")
    return LoggedMessage(record.log_time, direction, message.seq, message)
