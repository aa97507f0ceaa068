"""The codec's fast path reads exactly what pydantic reads, and gives up on everything else."""

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol import MESSAGE_TYPES, encode
from protocol.fastpath import Fallback, reader
from protocol.messages import Bye, Command, Error, State, Stats
from tests.helpers import examples
from tests.protocol.samples import sample_messages
from tests.protocol.strategies import msgpack_values

FUZZ = settings(
    max_examples=examples(3000), deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
FAST = [m for m in sample_messages() if reader(type(m)) is not None]


def assert_same(fast, slow):
    """Same class, same fields in the same order, same values, same fields set, same arrays."""
    assert type(fast) is type(slow)
    assert list(fast.__dict__) == list(slow.__dict__)
    assert fast.model_fields_set == slow.model_fields_set
    assert fast.__pydantic_extra__ == slow.__pydantic_extra__
    assert fast.__pydantic_private__ == slow.__pydantic_private__
    for name, value in slow.__dict__.items():
        other = fast.__dict__[name]
        if isinstance(value, np.ndarray):
            assert isinstance(other, np.ndarray) and other.dtype == value.dtype
            assert other.flags.writeable == value.flags.writeable
            np.testing.assert_array_equal(other, value)
        elif hasattr(type(value), "model_fields"):
            assert_same(other, value)
        elif isinstance(value, list) and value and hasattr(type(value[0]), "model_fields"):
            assert len(other) == len(value)
            for a, b in zip(other, value, strict=True):
                assert_same(a, b)
        else:
            assert type(other) is type(value) and other == value


def check(cls, payload):
    """If the reader accepts the payload, pydantic accepts it too and builds the same message."""
    try:
        fast = reader(cls)(payload)
    except Fallback:
        return False
    assert_same(fast, cls.model_validate(payload))
    return True


def test_the_tick_messages_have_readers():
    """A model change that loses the fast path of a tick should be a decision, not an accident."""
    for cls in (State, Command, Bye, Stats, Error):
        assert reader(cls) is not None, cls
    assert {type(m) for m in FAST} == {State, Command, Stats, Bye, Error}
    assert all(cls in {type(m) for m in sample_messages()} for cls in MESSAGE_TYPES.values())


@pytest.mark.parametrize("message", FAST, ids=lambda m: m.type)
def test_reader_builds_what_pydantic_builds(message):
    assert check(type(message), msgpack.unpackb(encode(message)))


def floats_bytes(size=None):
    size = st.integers(0, 14) if size is None else size
    values = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
        [0.0, -0.0, 999.9, 1000.0, 1000.5, 1e4, 1e4 + 1, 1e6, 1e7, 1.7e308]
    )
    return size.flatmap(lambda n: st.lists(values, min_size=n, max_size=n)).map(
        lambda xs: np.array(xs, "<f8").tobytes()
    )


array_values = floats_bytes() | st.binary(max_size=40) | st.lists(st.floats(), max_size=4)


@FUZZ
@given(st.sampled_from(range(len(FAST))), st.data())
def test_fuzz_reader_accepts_only_what_pydantic_accepts(index, data):
    """Mutated valid messages: keys dropped, added, replaced by any value or any array."""
    message = FAST[index]
    payload = msgpack.unpackb(encode(message))
    keys = sorted(payload)
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from([*keys, "unknown_key"]))
        choice = data.draw(st.sampled_from(["delete", "any", "array"]))
        if choice == "delete" and key in payload:
            del payload[key]
        elif choice == "array":
            payload[key] = data.draw(array_values)
        else:
            payload[key] = data.draw(msgpack_values)
    check(type(message), payload)


@FUZZ
@given(st.data())
def test_fuzz_reader_checks_state_arrays_as_pydantic_does(data):
    """Every array of a state replaced: lengths, NaN, inf, values around each field's bound."""
    payload = msgpack.unpackb(encode(sample_messages()[2]))
    for key, value in list(payload.items()):
        if isinstance(value, bytes) and data.draw(st.booleans()):
            payload[key] = data.draw(floats_bytes(st.sampled_from([0, 2, 3, 4, 12, 5])))
    check(State, payload)


def test_reader_gives_up_on_values_pydantic_converts_or_refuses():
    payload = msgpack.unpackb(encode(sample_messages()[2]))
    for changes in [
        {"time_s": 1},  # pydantic converts the int
        {"time_s": float("nan")},
        {"time_s": 2e12},
        {"seq": -1},
        {"seq": True},
        {"joint_velocity": np.array([0.0, np.inf]).tobytes()},
        {"joint_velocity": np.array([0.0, 1001.0]).tobytes()},
        {"orientation_base_in_world_xyzw": np.zeros(3).tobytes()},
        {"joint_position": [0.1, 0.2]},
        {"contact_flags": [1, 0]},
        {"extra": 1},
    ]:
        with pytest.raises(Fallback):
            reader(State)({**payload, **changes})
    del payload["time_s"]
    with pytest.raises(Fallback):
        reader(State)(payload)


def test_arrays_within_a_larger_bound_than_the_smallest_are_read():
    """Base position up to 10⁴ m and wrenches up to 10⁶: past the joints' 10³, still fast."""
    payload = msgpack.unpackb(encode(sample_messages()[2]))
    payload["position_base_in_world"] = np.array([9999.0, 0.0, 1.0]).tobytes()
    payload["contact_wrench_in_world"] = np.full(12, 9.9e5).tobytes()
    assert check(State, payload)
