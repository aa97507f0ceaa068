"""``peek``: what the broker routes by, at a cost bounded whatever the message's shape.

Issue 32, finding 1: the broker msgpack-decoded every request in full before any
check; a 14 MB message of 15 M empty arrays took 10.8 s and 1 GB. A long message
is now walked without building its values and refused past ``MAX_VALUES`` values
or ``MAX_DEPTH`` levels; ``decode`` (the workers') applies the same caps.
"""

import tracemalloc

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import ErrorCode, ProtocolError, decode, encode
from protocol.codec import MAX_DEPTH, MAX_VALUES, SCAN_ABOVE_BYTES, peek
from tests.protocol.samples import sample_messages
from tests.protocol.strategies import malformed_maps

PADDING = {"zz_padding": b"\x00" * (SCAN_ABOVE_BYTES + 1)}
"""A key no message has, long enough to send a message down the scanning path."""


def many_empty_arrays(count: int, routing_last: bool = True) -> bytes:
    """The attack: one key holding ``count`` empty arrays (one byte each), then type and seq."""
    arrays = msgpack.packb("x") + b"\xdd" + count.to_bytes(4, "big") + b"\x90" * count
    routing = msgpack.packb("type") + msgpack.packb("state") + msgpack.packb("seq")
    routing += msgpack.packb(5)
    return b"\x83" + (arrays + routing if routing_last else routing + arrays)


def nested(depth: int) -> bytes:
    """A long message whose ``nest`` key holds arrays ``depth`` deep."""
    head = msgpack.packb({"type": "state", "seq": 1, **PADDING})
    return bytes([head[0] + 1]) + head[1:] + msgpack.packb("nest") + b"\x91" * depth + b"\xc0"


@pytest.mark.parametrize("message", sample_messages(), ids=lambda m: m.type)
def test_every_message_type_is_peeked_alike_short_and_long(message):
    data = encode(message)
    long = msgpack.packb({**msgpack.unpackb(data), **PADDING})
    assert len(data) <= SCAN_ABOVE_BYTES < len(long)
    names_files = bool(getattr(message, "model_asset_hashes", None))
    assert peek(data) == (message.type, message.seq, names_files, None)
    assert peek(long) == peek(data)


@settings(max_examples=200, deadline=None)
@given(malformed_maps)
def test_the_scan_reads_what_the_full_decode_reads(payload):
    """Whatever the map holds, the long path finds the short path's type and seq."""
    short = peek(msgpack.packb(payload))
    long = peek(msgpack.packb({**payload, **PADDING}))
    assert (long.type, long.seq, long.refusal) == (short.type, short.seq, None)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64), st.binary(max_size=64))
def test_long_garbage_is_read_as_msgpack_reads_it(start, end):
    data = start + b"\xc4\x00" * (SCAN_ABOVE_BYTES // 2 + 1) + end  # empty bins between
    try:
        whole = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except Exception:
        whole = None
    head = peek(data)
    if not isinstance(whole, dict):
        assert (head.type, head.seq) == (None, -1)
    else:  # start happened to open a map that the bins and the end complete
        assert head.type == (whole.get("type") if isinstance(whole.get("type"), str) else None)


@pytest.mark.parametrize("routing_last", [True, False], ids=["type last", "type first"])
def test_fifteen_million_empty_arrays_are_refused_without_building_them(routing_last):
    data = many_empty_arrays(15_000_000, routing_last)
    tracemalloc.start()
    try:
        head = peek(data)
        with pytest.raises(ProtocolError) as decoded:
            decode(data, max_bytes=len(data))
        peak_bytes = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert head.refusal is not None and head.refusal.code == ErrorCode.LIMIT_EXCEEDED
    assert f"more than {MAX_VALUES} msgpack values" in head.refusal.detail
    assert decoded.value.code == ErrorCode.LIMIT_EXCEEDED
    assert peak_bytes < 4_000_000  # the decode of it peaked at 1 GB; 15 MB is the message


def test_a_message_nested_too_deep_is_refused():
    assert peek(nested(MAX_DEPTH - 2)).refusal is None
    for depth in (MAX_DEPTH + 1, 3000):
        head = peek(nested(depth))
        assert head.refusal is not None and "deeper than 16 levels" in head.refusal.detail
        with pytest.raises(ProtocolError, match="deeper than 16 levels"):
            decode(nested(depth))


def test_a_hello_naming_files_by_hash_is_seen_on_both_paths():
    hello = {"type": "hello", "version": 2, "seq": 7, "model_asset_hashes": {"a.stl": "0" * 64}}
    assert peek(msgpack.packb(hello)) == ("hello", 7, True, None)
    assert peek(msgpack.packb({**hello, **PADDING})) == ("hello", 7, True, None)
    no_files = {**hello, "model_asset_hashes": {}, **PADDING}
    assert peek(msgpack.packb(no_files)).names_files is False
