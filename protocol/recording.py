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

Bad files: :func:`read_log` refuses, with :class:`BadLog`, a file that is not
a regular file (never blocking on a FIFO), not MCAP, or corrupt anywhere (chunk
CRCs, every record parsed, message indexes, a closed log's summary CRC and
statistics), and a zstd bomb before decompressing it (:data:`MAX_CHUNK_BYTES`,
:data:`MAX_EXPANSION`).
"""

from __future__ import annotations

import base64
import json
import logging
import math
import os
import queue
import stat
import struct
import threading
import time
import types
import typing
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO, Literal

import numpy as np
import orjson
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.records import Message as McapMessage
from mcap.stream_reader import MAGIC_SIZE
from mcap.writer import CompressionType, Writer
from pydantic import BaseModel, ValidationError

from protocol.errors import PoiseError
from protocol.messages import MESSAGE_TYPES, Message

__all__ = [
    "CHUNK_SIZE",
    "MAX_CHUNK_BYTES",
    "MAX_EXPANSION",
    "QUEUE_LIMIT",
    "SMALL_LOG_BYTES",
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


_MiB = 1024 * 1024
MAX_CHUNK_BYTES = 256 * _MiB
"""Largest decompressed chunk a reader accepts (bytes).

A recorder's chunk holds :data:`CHUNK_SIZE` of messages plus at most one more,
the largest a ``hello`` with its model's files inline (a few MB at
``poise serve``'s default limits): a chunk declaring more is refused before
it is decompressed.
"""
MAX_EXPANSION = 100
"""A log's chunks decompress to at most this many times the file's size.

zstd makes a recorder's JSON 2 to 5 times smaller (2.3 for the committed
fixtures); a file whose chunks declare more is a zstd bomb, refused before the
chunk that passes the bound is decompressed.
"""
SMALL_LOG_BYTES = 64 * _MiB
"""Decompressed bytes any log may hold whatever its size (a short log of a large model)."""

_FILE_KINDS = {
    stat.S_IFDIR: "a directory",
    stat.S_IFIFO: "a FIFO (named pipe)",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
}
_HEAD_BYTES = 9  # a record's opcode (1 byte) and length (8 bytes)


def _open_log(path: Path) -> BinaryIO:
    """Open a regular file for reading without ever blocking (a FIFO would wait for a writer)."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise BadLog(path, f"cannot read it ({exc.strerror or exc})") from None
    mode = os.fstat(descriptor).st_mode
    if not stat.S_ISREG(mode):
        os.close(descriptor)
        kind = _FILE_KINDS.get(stat.S_IFMT(mode), "not a regular file")
        raise BadLog(path, f"it is {kind}, not a regular file (a `.mcap` recording)")
    return os.fdopen(descriptor, "rb")


def _check_start(path: Path) -> None:
    """Raise :class:`BadLog` unless a regular file starts with the MCAP magic and a header."""
    with _open_log(path) as file:
        try:
            head = file.read(MAGIC_SIZE + 1)
        except OSError as exc:
            raise BadLog(path, f"cannot read it ({exc.strerror or exc})") from None
    if not head:
        raise BadLog(path, "the file is empty")
    if head[:MAGIC_SIZE] != _MCAP_MAGIC:
        raise BadLog(path, "no MCAP magic at its start (is it a `.mcap` recording?)")
    if len(head) > MAGIC_SIZE and head[MAGIC_SIZE] != Opcode.HEADER:
        raise BadLog(path, f"the MCAP magic is not followed by a header (opcode {head[8]:#x})")


class _ExactStream(ReadDataStream):
    """A record's bytes for mcap's record classes; a field that runs past them raises."""

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile()
        return data


_RECORD_TYPES: dict[int, Any] = {
    Opcode.HEADER: Header,
    Opcode.FOOTER: Footer,
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.MESSAGE: McapMessage,
    Opcode.CHUNK: Chunk,
    Opcode.MESSAGE_INDEX: MessageIndex,
    Opcode.CHUNK_INDEX: ChunkIndex,
    Opcode.ATTACHMENT: Attachment,
    Opcode.ATTACHMENT_INDEX: AttachmentIndex,
    Opcode.STATISTICS: Statistics,
    Opcode.METADATA: Metadata,
    Opcode.METADATA_INDEX: MetadataIndex,
    Opcode.SUMMARY_OFFSET: SummaryOffset,
    Opcode.DATA_END: DataEnd,
}
_PARSE_ERRORS = (McapError, ValueError, struct.error, EOFError)


def _parse(opcode: int, data: bytes) -> Any:
    """One record from its bytes (``None``: an opcode MCAP does not define, skipped)."""
    record_type = _RECORD_TYPES.get(opcode)
    if record_type is None:
        return None
    stream = _ExactStream(BytesIO(data))
    if record_type is McapMessage:
        return McapMessage.read(stream, len(data))
    return record_type.read(stream)


class LogReader:
    """The messages of a log in file order; iterate once.

    Every chunk's CRC is checked, every record parsed in full, and a closed
    log's summary CRC and statistics checked against what was read: a log
    corrupt anywhere raises :class:`BadLog`, never yields a partial read as
    if it were whole. A chunk is decompressed only if it declares at most
    ``max_chunk_bytes`` and the chunks so far at most ``max_expansion`` times
    the file's size (at least :data:`SMALL_LOG_BYTES`), so memory stays
    bounded whatever the file claims.

    A log cut short (the recording process was killed, so no footer at its
    end) yields every message up to its last complete chunk, then logs a
    warning on ``poise.record`` naming how many messages were read; after the
    iteration :attr:`truncated` says so and :attr:`messages_read` counts them.
    A file that ends with the MCAP magic was closed by its recorder: a record
    in it that runs past the end is corruption, not a cut.

    Raises (while iterating):
        BadLog: A corrupt file, a message that is not a Poise message, or an
            MCAP file written by another program.
    """

    def __init__(
        self,
        path: Path,
        *,
        max_chunk_bytes: int = MAX_CHUNK_BYTES,
        max_expansion: float = MAX_EXPANSION,
    ):
        self.path = path
        self.max_chunk_bytes = max_chunk_bytes
        self.max_expansion = max_expansion
        self.messages_read = 0
        self.truncated = False
        self.stopped_at_byte: int | None = None
        """Where reading stopped in a truncated log."""
        self._file: BinaryIO | None = None
        self._size_bytes = 0
        self._finished = False
        self._decompressed_bytes = 0
        self._chunks_read = 0
        self._channels: dict[int, Channel] = {}

    @property
    def fraction_read(self) -> float:
        """How much of the file has been read (0 to 1, by bytes): for a progress bar."""
        if self._finished:
            return 1.0
        if self._file is None or self._size_bytes == 0:
            return 0.0
        return min(1.0, self._file.tell() / self._size_bytes)

    def reporting(
        self, progress: Callable[[float], None] | None, every: int = 1000
    ) -> Iterator[LoggedMessage]:
        """The messages, telling ``progress`` the fraction read after every ``every`` of them."""
        for index, logged in enumerate(self):
            if progress is not None and index % every == 0:
                progress(self.fraction_read)
            yield logged

    def __iter__(self) -> Iterator[LoggedMessage]:
        with _open_log(self.path) as file:
            self._file = file
            self._size_bytes = size = os.fstat(file.fileno()).st_size
            closed = False
            if size >= 2 * MAGIC_SIZE:
                file.seek(size - MAGIC_SIZE)
                closed = file.read(MAGIC_SIZE) == _MCAP_MAGIC
                file.seek(0)
            yield from self._read(file, size, closed)
        self._file, self._finished = None, True

    def _read(self, file: BinaryIO, size: int, closed: bool) -> Iterator[LoggedMessage]:
        if file.read(MAGIC_SIZE) != _MCAP_MAGIC:
            raise BadLog(self.path, "no MCAP magic at its start (is it a `.mcap` recording?)")
        offset = MAGIC_SIZE
        summary_crc: int | None = None  # of the bytes after the data section, once it ended
        chunk_index: dict[int, list[tuple[int, int]]] = {}  # the last chunk's, to check
        while True:
            head = file.read(_HEAD_BYTES)
            if len(head) < _HEAD_BYTES:
                self._end_early(closed, offset, f"the file ends at byte {offset} without a footer")
                return
            opcode, length = struct.unpack("<BQ", head)
            if length > size - offset - _HEAD_BYTES:
                self._end_early(
                    closed, offset, f"the record at byte {offset} runs past the end of the file"
                )
                return
            if length > 2 * self.max_chunk_bytes:  # a chunk's data is about its size, or less
                raise BadLog(
                    self.path,
                    f"the record at byte {offset} declares {length} bytes: a corrupt file",
                )
            data = file.read(length)
            if summary_crc is not None:
                summary_crc = zlib.crc32(
                    head + (data[:-4] if opcode == Opcode.FOOTER else data), summary_crc
                )
            try:
                record = _parse(opcode, data)
            except _PARSE_ERRORS as exc:
                raise self._corrupt(
                    f"its {_opcode_name(opcode)} record at byte {offset} does not parse", exc
                ) from None
            if offset == MAGIC_SIZE and not isinstance(record, Header):
                raise BadLog(self.path, "the MCAP magic is not followed by a header")
            if isinstance(record, Header) and record.library != "poise":
                raise BadLog(self.path, f"written by {record.library!r}, not by a Poise recorder")
            if isinstance(record, Chunk):
                chunk_index = {}
                yield from self._chunk_records(record, offset, chunk_index)
            elif isinstance(record, MessageIndex):
                self._check_index(record, chunk_index, offset)
            elif isinstance(record, Channel | McapMessage):
                unchunked = self._record(record, {}, 0)  # outside a chunk: no index to check
                if unchunked is not None:
                    yield unchunked
            elif isinstance(record, DataEnd):
                summary_crc = 0
            elif isinstance(record, Statistics):
                self._check_statistics(record)
            elif isinstance(record, Footer):
                if summary_crc is not None and record.summary_crc not in (0, summary_crc):
                    raise BadLog(
                        self.path, "its summary section does not match its CRC: the file is corrupt"
                    )
                tail = file.read(MAGIC_SIZE + 1)
                if tail != _MCAP_MAGIC:
                    if closed or not _MCAP_MAGIC.startswith(tail):
                        raise BadLog(
                            self.path,
                            "its footer is not followed by the MCAP magic: the file is corrupt",
                        )
                    self._end_early(closed, offset, "the file ends in its closing magic")
                return
            offset += _HEAD_BYTES + length

    def _chunk_records(
        self, chunk: Chunk, offset: int, chunk_index: dict[int, list[tuple[int, int]]]
    ) -> Iterator[LoggedMessage]:
        """The messages of one chunk, decompressed within the bounds, its CRC checked."""
        self._chunks_read += 1
        where = f"the chunk at byte {offset}"
        if chunk.uncompressed_size > self.max_chunk_bytes:
            raise BadLog(
                self.path,
                f"{where} declares {chunk.uncompressed_size / _MiB:.0f} MiB decompressed, more "
                f"than a reader takes ({self.max_chunk_bytes / _MiB:.0f} MiB): a zstd bomb?",
            )
        budget = max(self.max_expansion * self._size_bytes, SMALL_LOG_BYTES)
        self._decompressed_bytes += chunk.uncompressed_size
        if self._decompressed_bytes > budget:
            raise BadLog(
                self.path,
                f"its chunks declare {self._decompressed_bytes / _MiB:.0f} MiB decompressed, "
                f"more than a reader takes from a {self._size_bytes / _MiB:.1f} MiB file "
                f"({self.max_expansion:g} times its size, at least "
                f"{SMALL_LOG_BYTES / _MiB:.0f} MiB): a zstd bomb?",
            )
        data = self._decompress(chunk, where)
        if chunk.uncompressed_crc not in (0, zlib.crc32(data)):
            raise BadLog(self.path, f"{where} does not match its CRC: the file is corrupt")
        stream = _ExactStream(BytesIO(data))
        while stream.count < len(data):
            start = stream.count
            try:
                opcode, length = stream.read1(), stream.read8()
                record = _parse(opcode, stream.read(length))
            except _PARSE_ERRORS as exc:
                raise self._corrupt(f"a record in {where} does not parse", exc) from None
            if isinstance(record, Channel | McapMessage):
                message = self._record(record, chunk_index, start)
                if message is not None:
                    yield message

    def _decompress(self, chunk: Chunk, where: str) -> bytes:
        """The chunk's records, never more than its declared size of them."""
        if chunk.compression == "":
            data = chunk.data
        elif chunk.compression == "zstd":
            try:
                with zstandard.ZstdDecompressor().stream_reader(chunk.data) as reader:
                    data = reader.read(chunk.uncompressed_size + 1)
            except zstandard.ZstdError as exc:
                raise self._corrupt(f"{where} does not decompress", exc) from None
        else:
            raise BadLog(
                self.path, f"{where} is compressed with {chunk.compression!r}; Poise writes zstd"
            )
        if len(data) != chunk.uncompressed_size:
            more = "more" if len(data) > chunk.uncompressed_size else "fewer"
            raise BadLog(
                self.path,
                f"{where} decompresses to {more} bytes than the {chunk.uncompressed_size} it "
                "declares: the file is corrupt",
            )
        return data

    def _record(
        self, record: Channel | McapMessage, chunk_index: dict[int, list[tuple[int, int]]], at: int
    ) -> LoggedMessage | None:
        if isinstance(record, Channel):
            self._channels[record.id] = record
            return None
        chunk_index.setdefault(record.channel_id, []).append((record.log_time, at))
        self.messages_read += 1
        return _logged(self.path, self._channels, record)

    def _check_index(
        self, index: MessageIndex, chunk_index: dict[int, list[tuple[int, int]]], offset: int
    ) -> None:
        """A chunk's message index names the messages read from it (times and offsets)."""
        if sorted(index.records) != sorted(chunk_index.get(index.channel_id, [])):
            raise BadLog(
                self.path,
                f"the message index at byte {offset} does not match its chunk: the file is corrupt",
            )

    def _check_statistics(self, statistics: Statistics) -> None:
        if (statistics.message_count, statistics.chunk_count) != (
            self.messages_read,
            self._chunks_read,
        ):
            raise BadLog(
                self.path,
                f"its summary counts {statistics.message_count} messages in "
                f"{statistics.chunk_count} chunks, the file holds {self.messages_read} in "
                f"{self._chunks_read}: the file is corrupt",
            )

    def _corrupt(self, what: str, exc: BaseException) -> BadLog:
        reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        return BadLog(self.path, f"{what} ({reason}): the file is corrupt")

    def _end_early(self, closed: bool, offset: int, what: str) -> None:
        """The file ends before its footer: a recorder killed mid-run, unless it was closed."""
        if closed:
            raise BadLog(
                self.path,
                f"{what}, though its recorder closed it (it ends with the MCAP magic): "
                "the file is corrupt",
            )
        self.truncated = True
        self.stopped_at_byte = offset
        log.warning(
            "%s ends early (killed mid-recording?): read %d messages, stopped at byte %d (%s)",
            self.path,
            self.messages_read,
            offset,
            what,
        )


def _opcode_name(opcode: int) -> str:
    try:
        return Opcode(opcode).name.lower().replace("_", " ")
    except ValueError:
        return f"opcode {opcode:#x}"


def read_log(
    path: str | os.PathLike[str],
    *,
    max_chunk_bytes: int = MAX_CHUNK_BYTES,
    max_expansion: float = MAX_EXPANSION,
) -> LogReader:
    """The messages of a log, in file order (see :class:`LogReader`).

    Args:
        path: The log.
        max_chunk_bytes: Largest decompressed chunk accepted.
        max_expansion: Largest ratio of decompressed chunks to file size.

    Raises:
        BadLog: The file is not a regular file, is empty, not MCAP, or does not
            start with an MCAP header (and, while iterating, see :class:`LogReader`).
    """
    file_path = Path(path)
    _check_start(file_path)
    return LogReader(file_path, max_chunk_bytes=max_chunk_bytes, max_expansion=max_expansion)


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
