import hashlib

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol import (
    MAX_MESSAGE_BYTES,
    MESSAGE_TYPES,
    PROTOCOL_VERSION,
    ErrorCode,
    ProtocolError,
    decode,
    encode,
)
from protocol.errors import PoiseError
from protocol.messages import Asset, AssetReceived, Bye, Hello, State
from tests.helpers import examples
from tests.protocol.samples import FILE_SHA256, sample_messages
from tests.protocol.strategies import malformed_maps, msgpack_values

FUZZ = settings(
    max_examples=examples(4000), deadline=None, suppress_health_check=[HealthCheck.too_slow]
)


def _equal(a, b):
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
    if hasattr(type(a), "model_fields"):
        return type(a) is type(b) and all(
            _equal(getattr(a, k), getattr(b, k)) for k in type(a).model_fields
        )
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@pytest.mark.parametrize("message", sample_messages(), ids=lambda m: m.type)
def test_every_message_round_trips(message):
    decoded = decode(encode(message))
    assert _equal(decoded, message)


def test_sample_covers_every_type():
    assert {m.type for m in sample_messages()} == set(MESSAGE_TYPES)


def test_golden_bytes_of_bye():
    expected = b"\x83\xa4type\xa3bye\xa7version\x02\xa3seq\x07"
    assert encode(Bye(seq=7)) == expected
    assert decode(expected) == Bye(seq=7)


def test_golden_bytes_of_an_asset_chunk_and_its_reply():
    """A file's chunk is msgpack `bin`; the digest a 64-character string (`str 8`)."""
    chunk = Asset(seq=3, sha256=FILE_SHA256, size_bytes=2, offset_bytes=0, data=b"\x00\xff")
    digest = b"\xa6sha256\xd9@" + FILE_SHA256.encode()
    expected = (
        b"\x87\xa4type\xa5asset\xa7version\x02\xa3seq\x03"
        + digest
        + b"\xaasize_bytes\x02\xacoffset_bytes\x00\xa4data\xc4\x02\x00\xff"
    )
    assert encode(chunk) == expected
    assert decode(expected) == chunk
    reply = AssetReceived(seq=3, sha256=FILE_SHA256, received_bytes=2, complete=True)
    expected = (
        b"\x86\xa4type\xaeasset_received\xa7version\x02\xa3seq\x03"
        + digest
        + b"\xaereceived_bytes\x02\xa8complete\xc3"
    )
    assert encode(reply) == expected
    assert decode(expected) == reply


@settings(max_examples=300, deadline=None)
@given(
    st.binary(max_size=4096),
    st.integers(0, 2**40),
    st.integers(0, 2**40),
    st.integers(0, 2**63 - 1),
)
def test_any_asset_chunk_round_trips_exactly(data, size, offset, seq):
    sha256 = hashlib.sha256(data).hexdigest()
    chunk = Asset(seq=seq, sha256=sha256, size_bytes=size, offset_bytes=offset, data=data)
    assert decode(encode(chunk)) == chunk
    payload = msgpack.unpackb(encode(chunk))
    assert payload["data"] == data and isinstance(payload["data"], bytes)  # msgpack bin
    reply = AssetReceived(seq=seq, sha256=sha256, received_bytes=offset, complete=bool(size % 2))
    assert decode(encode(reply)) == reply


def _hello_by_hash(**changes):
    payload = {
        "type": "hello",
        "version": PROTOCOL_VERSION,
        "seq": 4,
        "model_text": "<mujoco/>",
        "model_asset_hashes": {"mesh.stl": FILE_SHA256},
    }
    return msgpack.packb({**payload, **changes})


@pytest.mark.parametrize(
    ("changes", "field", "words"),
    [
        (
            {"model_asset_hashes": {"mesh.stl": FILE_SHA256.upper()}},
            "model_asset_hashes.mesh.stl",
            "pattern",
        ),
        (
            {"model_asset_hashes": {"mesh.stl": FILE_SHA256[:-1]}},
            "model_asset_hashes.mesh.stl",
            "pattern",
        ),
        ({"model_asset_hashes": {"mesh.stl": 7}}, "model_asset_hashes.mesh.stl", "string"),
        ({"model_assets": {"mesh.stl": b"x"}}, "", "in both"),
        ({"model_text": None, "model": "thesis_humanoid"}, "", "a `model` by name"),
        (
            {"model_asset_hashes": {f"{i}.stl": FILE_SHA256 for i in range(513)}},
            "model_asset_hashes",
            "at most 512",
        ),
        (
            {
                "model_asset_hashes": {f"{i}.stl": FILE_SHA256 for i in range(300)},
                "model_assets": {f"x{i}.stl": b"" for i in range(300)},
            },
            "",
            "together",
        ),
    ],
    ids=["upper case", "63 digits", "not a string", "both maps", "named model", "513", "600"],
)
def test_files_by_hash_are_checked_at_the_edge(changes, field, words):
    with pytest.raises(ProtocolError) as info:
        decode(_hello_by_hash(**changes))
    assert info.value.code == ErrorCode.INVALID_FIELD
    assert info.value.field == field and info.value.seq == 4
    assert words in info.value.detail
    assert isinstance(decode(_hello_by_hash()), Hello)


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"size_bytes": -1}, "size_bytes"),
        ({"size_bytes": 2.0}, "size_bytes"),
        ({"offset_bytes": -1}, "offset_bytes"),
        ({"data": "text"}, "data"),
        ({"sha256": "../../etc/passwd"}, "sha256"),
    ],
)
def test_bad_asset_chunks_get_typed_errors(changes, field):
    payload = msgpack.unpackb(encode(Asset(seq=5, sha256=FILE_SHA256, size_bytes=2, data=b"ab")))
    with pytest.raises(ProtocolError) as info:
        decode(msgpack.packb({**payload, **changes}))
    assert info.value.code == ErrorCode.INVALID_FIELD
    assert info.value.field == field and info.value.seq == 5


def test_the_size_limit_is_the_callers():
    """`decode` takes the server's `--max-message-bytes`; the module constant is the default."""
    big = encode(Asset(sha256=FILE_SHA256, size_bytes=20_000_000, data=bytes(20_000_000)))
    assert len(big) > MAX_MESSAGE_BYTES
    with pytest.raises(ProtocolError, match=f"exceeds {MAX_MESSAGE_BYTES}"):
        decode(big)
    assert decode(big, max_bytes=64_000_000).data == bytes(20_000_000)
    with pytest.raises(ProtocolError, match="exceeds 1000"):
        decode(encode(Bye()) + bytes(1000), max_bytes=1000)


def test_arrays_travel_as_little_endian_float64_bin():
    state = sample_messages()[2]
    payload = msgpack.unpackb(encode(state))
    assert (
        payload["joint_position"] == b"\x9a\x99\x99\x99\x99\x99\xb9?\x9a\x99\x99\x99\x99\x99\xc9?"
    )
    assert payload["joint_position"] == np.array([0.1, 0.2], "<f8").tobytes()


def _state_payload(**changes):
    payload = msgpack.unpackb(encode(sample_messages()[2]))
    payload.update(changes)
    return msgpack.packb(payload)


@pytest.mark.parametrize(
    ("data", "code", "field"),
    [
        (b"\xc1garbage", ErrorCode.MALFORMED, ""),
        (msgpack.packb([1, 2, 3]), ErrorCode.MALFORMED, ""),
        (encode(Bye(seq=1))[:-3], ErrorCode.MALFORMED, ""),
        (_state_payload(version=PROTOCOL_VERSION + 1), ErrorCode.UNSUPPORTED_VERSION, "version"),
        (_state_payload(version=PROTOCOL_VERSION - 1), ErrorCode.UNSUPPORTED_VERSION, "version"),
        (_state_payload(version=True), ErrorCode.UNSUPPORTED_VERSION, "version"),
        (_state_payload(type="teleport"), ErrorCode.UNKNOWN_TYPE, "type"),
        (_state_payload(time_s="now"), ErrorCode.INVALID_FIELD, "time_s"),
        (_state_payload(time_s=float("nan")), ErrorCode.NON_FINITE, "time_s"),
        (_state_payload(extra=1), ErrorCode.INVALID_FIELD, "extra"),
        (_state_payload(joint_position=b"\x00" * 7), ErrorCode.BAD_SHAPE, "joint_position"),
        (
            _state_payload(position_base_in_world=b"\x00" * 16),
            ErrorCode.BAD_SHAPE,
            "position_base_in_world",
        ),
        (
            _state_payload(joint_velocity=np.array([0.0, np.inf]).tobytes()),
            ErrorCode.NON_FINITE,
            "joint_velocity",
        ),
        (_state_payload(joint_position=["a", "b"]), ErrorCode.INVALID_FIELD, "joint_position"),
        (_state_payload(joint_position=[[1.0], [2.0]]), ErrorCode.BAD_SHAPE, "joint_position"),
        (_state_payload(seq=-5), ErrorCode.INVALID_FIELD, "seq"),
    ],
)
def test_bad_input_gets_typed_error_naming_the_field(data, code, field):
    with pytest.raises(ProtocolError) as info:
        decode(data)
    assert info.value.code == code
    assert info.value.field == field


def test_error_carries_the_request_seq_when_readable():
    with pytest.raises(ProtocolError) as info:
        decode(_state_payload(seq=41, joint_position=b"\x00"))
    assert info.value.seq == 41


def test_oversized_message_is_refused_before_parsing():
    with pytest.raises(ProtocolError) as info:
        decode(b"\x00" * (16 * 1024 * 1024 + 1))
    assert info.value.code == ErrorCode.MALFORMED


def _decode_or_protocol_error(data: bytes):
    try:
        message = decode(data)
    except ProtocolError as exc:
        assert isinstance(exc.code, ErrorCode)
        assert exc.detail
        return None
    assert message.version == PROTOCOL_VERSION
    assert message.type in MESSAGE_TYPES
    return message


@FUZZ
@given(st.binary(max_size=512))
def test_fuzz_random_bytes(data):
    _decode_or_protocol_error(data)


@FUZZ
@given(malformed_maps)
def test_fuzz_random_maps(payload):
    _decode_or_protocol_error(msgpack.packb(payload))


@FUZZ
@given(
    st.sampled_from(range(len(sample_messages()))),
    st.data(),
)
def test_fuzz_mutated_valid_messages(index, data):
    payload = msgpack.unpackb(encode(sample_messages()[index]))
    keys = sorted(payload)
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from([*keys, "unknown_key"]))
        if data.draw(st.booleans()) and key in payload:
            del payload[key]
        else:
            payload[key] = data.draw(msgpack_values)
    _decode_or_protocol_error(msgpack.packb(payload))


def test_valid_state_decodes_to_read_only_arrays():
    state = decode(encode(sample_messages()[2]))
    assert isinstance(state, State)
    assert not state.joint_position.flags.writeable


class UnknownBody(PoiseError, KeyError):
    def __init__(self, name, available):
        self.name, self.available = name, available
        super().__init__(f"no body {name!r}; bodies: {', '.join(available)}")


def test_errors_survive_pickling_as_a_worker_process_raises_them():
    """A run on a worker process raises its error in the caller as it was, type and fields."""
    import pickle

    for error in [
        ProtocolError(ErrorCode.INVALID_FIELD, "params.stiffness", "must be > 0", seq=3),
        UnknownBody("hed", ["head", "chest"]),
    ]:
        copy = pickle.loads(pickle.dumps(error))
        assert type(copy) is type(error) and str(copy) == str(error)
        assert vars(copy) == vars(error)
