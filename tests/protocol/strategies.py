"""Hypothesis strategies for malformed protocol messages (decoder and live-server fuzz)."""

from hypothesis import strategies as st

from protocol import MESSAGE_TYPES, PROTOCOL_VERSION

scalars = (
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=8)
    | st.binary(max_size=48)
)
msgpack_values = (
    scalars
    | st.lists(scalars, max_size=4)
    | st.dictionaries(st.text(max_size=6), scalars, max_size=3)
)
message_keys = st.sampled_from(
    sorted({key for cls in MESSAGE_TYPES.values() for key in cls.model_fields})
) | st.text(max_size=8)
malformed_maps = st.fixed_dictionaries(
    {},
    optional={
        "version": st.just(PROTOCOL_VERSION) | msgpack_values,
        "type": st.sampled_from(sorted(MESSAGE_TYPES)) | msgpack_values,
        "seq": st.integers(-5, 2**64 - 1) | msgpack_values,
    },
).flatmap(
    lambda head: st.dictionaries(message_keys, msgpack_values, max_size=6).map(
        lambda tail: {**tail, **head}
    )
)
