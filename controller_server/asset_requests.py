"""The broker's answers that involve its asset cache: uploads, and hellos naming files.

The broker answers an ``asset`` upload itself (:func:`receive_asset`), and refuses a
``hello`` that names files by hash (``model_asset_hashes``) the client has not
uploaded with ``ASSETS_MISSING`` (:func:`check_assets`) before any worker sees it.
The cache itself, its bytes and its directory, is :mod:`controller_server.asset_cache`.
"""

from __future__ import annotations

import logging

from controller_server.asset_cache import AssetCache
from controller_server.routing import error_of, error_reply
from controller_server.session_table import SessionTable
from protocol.codec import decode
from protocol.errors import AssetsMissing, ErrorCode, ProtocolError
from protocol.messages import Asset, Error, Hello, Message

__all__ = ["check_assets", "receive_asset"]

log = logging.getLogger("poise.server")


def receive_asset(
    assets: AssetCache,
    local: SessionTable,
    identity: bytes,
    client: str,
    payload: bytes,
    max_message_bytes: int,
) -> Message:
    """The answer to an ``asset`` request: the cache's, or an error.

    ``local`` (the broker's session-less table) answers a request whose peeked
    type was not its real one.
    """
    try:
        request = decode(payload, max_message_bytes)
        if not isinstance(request, Asset):  # a peeked type that was not the real one
            return local.handle(identity, payload)
        return assets.receive(identity, client, request)
    except ProtocolError as exc:
        return error_of(exc, max_message_bytes)
    except OSError as exc:  # the cache's disk: full, or gone
        log.error("asset cache: %s", exc)
        detail = f"the server cannot store the file now ({exc.strerror or exc}); retry later"
        return error_reply(-1, ErrorCode.LIMIT_EXCEEDED, "", detail)


def check_assets(
    assets: AssetCache, client: str, payload: bytes, max_message_bytes: int
) -> Error | None:
    """The refusal of a ``hello`` naming files by hash: invalid, or files missing.

    ``None``: every file is in the cache for this client; the worker serves it.
    """
    try:
        request = decode(payload, max_message_bytes)
    except ProtocolError as exc:
        return error_of(exc, max_message_bytes)
    if not isinstance(request, Hello) or not request.model_asset_hashes:
        return None
    missing = assets.missing(client, request.model_asset_hashes.values())
    if not missing:
        return None
    return error_of(AssetsMissing(missing, request.seq), max_message_bytes)
