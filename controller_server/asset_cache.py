"""The server's asset cache: files of sent models, by SHA-256, uploaded once, in chunks.

A ``hello`` may name the files of its ``model_text`` by content
(``model_asset_hashes``) instead of sending them inline, so its size does not
grow with the meshes. The broker (:mod:`controller_server.server`, through
:mod:`controller_server.asset_requests`) answers ``asset`` uploads with this
cache, and a ``hello`` naming a file the client has not uploaded with
``ASSETS_MISSING``. The workers read the files by name from
:attr:`AssetCache.directory` (:func:`read_asset`), so a file uploaded through
the broker serves every worker.

The directory is private to the server's user (``0700``, made by
:func:`tempfile.mkdtemp`) and removed by :meth:`AssetCache.close`. Complete
files are named by their SHA-256 (checked before a file gets its name);
uploads in progress live under ``partial/``. Bounds:

- the bytes of complete files plus the declared size of every upload in
  progress stay within ``capacity_bytes``: the least recently used files are
  deleted to make room, and an upload that cannot be made room for is refused;
- a file is at most ``max_file_bytes`` (``--max-model-bytes``);
- a client's uploads in progress declare at most ``max_upload_bytes_per_client``,
  and one idle longer than the session timeout is dropped (:meth:`AssetCache.expire`).

A client sees only the files it uploaded itself: a ``hello`` naming a file
another client uploaded gets ``ASSETS_MISSING`` until this one uploads it too
(the bytes are stored once). So no client learns which files another sent.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import logging
import os
import shutil
import tempfile
import time
from collections import OrderedDict
from collections.abc import Iterable
from pathlib import Path

from protocol.errors import ErrorCode, ProtocolError
from protocol.messages import Asset, AssetReceived

__all__ = ["AssetCache", "read_asset"]

log = logging.getLogger("poise.server")


@dataclasses.dataclass
class _File:
    size_bytes: int
    clients: set[str]
    """Clients that uploaded it (only they may name it)."""


@dataclasses.dataclass
class _Upload:
    client: str
    size_bytes: int
    path: Path
    digest: hashlib._Hash
    last_seen_s: float
    received_bytes: int = 0


def read_asset(directory: str | os.PathLike[str] | None, sha256: str) -> bytes | None:
    """The bytes of a complete file of the cache in ``directory``; ``None`` if absent.

    The content is hashed again, so a file damaged on disk is absent, not wrong.

    Args:
        directory: The cache's directory (``None``: no cache, nothing is found).
        sha256: The file's SHA-256, 64 lowercase hex characters (validated by the
            caller: it is a file name).
    """
    if directory is None:
        return None
    try:
        data = (Path(directory) / sha256).read_bytes()
    except OSError:  # evicted meanwhile
        return None
    return data if hashlib.sha256(data).hexdigest() == sha256 else None


class AssetCache:
    """Content-addressed files of sent models, in a private directory (see the module).

    Args:
        capacity_bytes: Bytes of complete files and uploads in progress together.
        max_file_bytes: Largest file.
        max_upload_bytes_per_client: Declared sizes of one client's uploads in progress.
        idle_timeout_s: An upload without a chunk for this long is dropped.
    """

    def __init__(
        self,
        capacity_bytes: int,
        max_file_bytes: int,
        max_upload_bytes_per_client: int,
        idle_timeout_s: float,
    ):
        self.capacity_bytes = capacity_bytes
        self.max_file_bytes = max_file_bytes
        self.max_upload_bytes_per_client = max_upload_bytes_per_client
        self.idle_timeout_s = idle_timeout_s
        self.directory = Path(tempfile.mkdtemp(prefix="poise-assets-"))
        self._partial = self.directory / "partial"
        self._partial.mkdir(mode=0o700)
        self._files: OrderedDict[str, _File] = OrderedDict()
        """Complete files, least recently used first."""
        self._uploads: dict[tuple[bytes, str], _Upload] = {}
        """Uploads in progress by (routing id, SHA-256)."""
        self._names = itertools.count()
        self.uploads_completed = 0
        """Files whose upload completed (a counter for logs and tests)."""

    @property
    def used_bytes(self) -> int:
        """Bytes of complete files plus the declared sizes of uploads in progress."""
        return sum(f.size_bytes for f in self._files.values()) + sum(
            u.size_bytes for u in self._uploads.values()
        )

    def missing(self, client: str, hashes: Iterable[str]) -> list[str]:
        """Which of ``hashes`` this client has not uploaded (sorted); the others count as used."""
        missing = set()
        for sha256 in hashes:
            entry = self._files.get(sha256)
            if entry is None or client not in entry.clients:
                missing.add(sha256)
            else:
                self._files.move_to_end(sha256)
        return sorted(missing)

    def receive(self, identity: bytes, client: str, chunk: Asset) -> AssetReceived:
        """Take one chunk of an upload.

        Args:
            identity: The client's routing id (an upload belongs to one connection).
            client: Who the client is (CURVE key or peer address): whose files these are.
            chunk: The request.

        Raises:
            ProtocolError: ``INVALID_FIELD`` (an offset out of order, a size that changed,
                a chunk past the declared size, content whose SHA-256 differs: the upload
                is dropped) or ``LIMIT_EXCEEDED`` (file, per-client or cache bound).
        """
        sha256, seq = chunk.sha256, chunk.seq
        key = (identity, sha256)
        entry = self._files.get(sha256)
        if entry is not None and client in entry.clients:
            self._drop(key)
            self._files.move_to_end(sha256)
            return AssetReceived(
                seq=seq, sha256=sha256, received_bytes=entry.size_bytes, complete=True
            )
        upload = self._uploads.get(key)
        if upload is not None and chunk.offset_bytes == 0:
            self._drop(key)  # a restart
            upload = None
        if upload is None:
            if chunk.offset_bytes != 0:
                raise ProtocolError(
                    ErrorCode.INVALID_FIELD,
                    "offset_bytes",
                    f"offset_bytes={chunk.offset_bytes}, but no upload of {sha256[:12]}… is in "
                    "progress on this connection: start it at offset 0",
                    seq,
                )
            upload = self._start(key, client, chunk)
        elif chunk.size_bytes != upload.size_bytes:
            raise ProtocolError(
                ErrorCode.INVALID_FIELD,
                "size_bytes",
                f"size_bytes={chunk.size_bytes}, but the upload in progress declared "
                f"{upload.size_bytes}: restart it at offset 0",
                seq,
            )
        elif chunk.offset_bytes != upload.received_bytes:
            raise ProtocolError(
                ErrorCode.INVALID_FIELD,
                "offset_bytes",
                f"offset_bytes={chunk.offset_bytes}, but {upload.received_bytes} bytes have "
                "arrived: send the chunk that starts there",
                seq,
            )
        end = chunk.offset_bytes + len(chunk.data)
        if end > upload.size_bytes:
            self._drop(key)
            raise ProtocolError(
                ErrorCode.INVALID_FIELD,
                "data",
                f"the chunk ends at byte {end}, past size_bytes={upload.size_bytes}; the upload "
                "is dropped: start it again at offset 0",
                seq,
            )
        with open(upload.path, "ab") as file:
            file.write(chunk.data)
        upload.digest.update(chunk.data)
        upload.received_bytes = end
        upload.last_seen_s = time.monotonic()
        if end < upload.size_bytes:
            return AssetReceived(seq=seq, sha256=sha256, received_bytes=end, complete=False)
        return self._finish(key, upload, seq)

    def _start(self, key: tuple[bytes, str], client: str, chunk: Asset) -> _Upload:
        size = chunk.size_bytes
        if size > self.max_file_bytes:
            raise ProtocolError(
                ErrorCode.LIMIT_EXCEEDED,
                "size_bytes",
                f"a file of {size} bytes exceeds the server's limit of {self.max_file_bytes} "
                "bytes per file (`poise serve --max-model-bytes`)",
                chunk.seq,
            )
        if size > self.capacity_bytes:
            raise ProtocolError(
                ErrorCode.LIMIT_EXCEEDED,
                "size_bytes",
                f"a file of {size} bytes does not fit the server's asset cache of "
                f"{self.capacity_bytes} bytes (`poise serve --asset-cache-bytes`)",
                chunk.seq,
            )
        own = sum(u.size_bytes for u in self._uploads.values() if u.client == client)
        if own + size > self.max_upload_bytes_per_client:
            raise ProtocolError(
                ErrorCode.LIMIT_EXCEEDED,
                "size_bytes",
                f"this client's unfinished uploads hold {own} bytes; {size} more exceed the "
                f"limit of {self.max_upload_bytes_per_client} per client (`poise serve "
                "--max-upload-bytes-per-client`): finish them first",
                chunk.seq,
            )
        if not self._make_room(size):
            raise ProtocolError(
                ErrorCode.LIMIT_EXCEEDED,
                "size_bytes",
                f"no room for {size} bytes in the server's asset cache of "
                f"{self.capacity_bytes} bytes (`poise serve --asset-cache-bytes`): uploads "
                "in progress hold it; retry later",
                chunk.seq,
            )
        path = self._partial / f"{next(self._names)}.part"
        path.touch(mode=0o600)
        upload = _Upload(client, size, path, hashlib.sha256(), time.monotonic())
        self._uploads[key] = upload
        return upload

    def _make_room(self, size_bytes: int) -> bool:
        """Evict least recently used files until ``size_bytes`` more fit; whether they do."""
        used = self.used_bytes
        while used + size_bytes > self.capacity_bytes and self._files:
            sha256, entry = self._files.popitem(last=False)
            (self.directory / sha256).unlink(missing_ok=True)
            used -= entry.size_bytes
            log.info("asset %s… (%d bytes) evicted from the cache", sha256[:12], entry.size_bytes)
        return used + size_bytes <= self.capacity_bytes

    def _finish(self, key: tuple[bytes, str], upload: _Upload, seq: int) -> AssetReceived:
        sha256 = key[1]
        del self._uploads[key]
        actual = upload.digest.hexdigest()
        if actual != sha256:
            upload.path.unlink(missing_ok=True)
            raise ProtocolError(
                ErrorCode.INVALID_FIELD,
                "sha256",
                f"the {upload.size_bytes} bytes received hash to {actual[:12]}…, not "
                f"{sha256[:12]}…; the upload is dropped: send the file again from offset 0",
                seq,
            )
        entry = self._files.get(sha256)
        if entry is None:
            os.replace(upload.path, self.directory / sha256)
            self._files[sha256] = _File(upload.size_bytes, {upload.client})
        else:  # another client's copy: the same bytes, stored once
            upload.path.unlink(missing_ok=True)
            entry.clients.add(upload.client)
            self._files.move_to_end(sha256)
        self.uploads_completed += 1
        log.info("asset %s… (%d bytes) uploaded", sha256[:12], upload.size_bytes)
        return AssetReceived(
            seq=seq, sha256=sha256, received_bytes=upload.size_bytes, complete=True
        )

    def _drop(self, key: tuple[bytes, str]) -> None:
        upload = self._uploads.pop(key, None)
        if upload is not None:
            upload.path.unlink(missing_ok=True)

    def expire(self, now_s: float) -> int:
        """Drop uploads idle longer than the timeout; how many."""
        idle = [
            key
            for key, upload in self._uploads.items()
            if now_s - upload.last_seen_s > self.idle_timeout_s
        ]
        for key in idle:
            self._drop(key)
        return len(idle)

    def close(self) -> None:
        """Delete the directory and everything in it."""
        self._files.clear()
        self._uploads.clear()
        shutil.rmtree(self.directory, ignore_errors=True)
