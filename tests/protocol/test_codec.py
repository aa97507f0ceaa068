import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol import MESSAGE_TYPES, PROTOCOL_VERSION, ErrorCode, ProtocolError, decode, encode
from protocol.errors import PoiseError
from protocol.messages import Bye, State
from tests.protocol.samples import sample_messages
from tests.protocol.strategies import malformed_maps, msgpack_values

FUZZ = settings(max_examples=4000, deadline=None, suppress_health_check=[HealthCheck.too_slow])


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
