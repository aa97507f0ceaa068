"""Throw >10,000 generated malformed messages at a live server; it keeps serving."""

import msgpack
import numpy as np
import pytest
import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clients import ControllerClient
from protocol import MESSAGE_TYPES, ErrorCode, decode, encode
from protocol.messages import Error
from tests.helpers import random_state
from tests.protocol.samples import sample_messages
from tests.protocol.strategies import malformed_maps, msgpack_values

pytestmark = pytest.mark.e2e

FUZZ = settings(max_examples=3500, deadline=None, suppress_health_check=list(HealthCheck))
REQUEST_TIMEOUT_MS = 10_000


@pytest.fixture(scope="module")
def raw_socket(server):
    """A DEALER with a live session, so state/set_params reach the controller."""
    context = zmq.Context()
    socket = context.socket(zmq.DEALER)
    socket.setsockopt(zmq.LINGER, 0)
    socket.connect(server.endpoint)
    socket.send(encode(sample_messages()[0].model_copy(update={"params": {}})))
    assert socket.poll(REQUEST_TIMEOUT_MS)
    assert decode(socket.recv()).type == "welcome"
    yield socket
    socket.close()
    context.term()


def exchange(socket, data: bytes):
    socket.send(data)
    assert socket.poll(REQUEST_TIMEOUT_MS), "server stopped answering"
    reply = decode(socket.recv())
    if isinstance(reply, Error):
        assert isinstance(reply.code, ErrorCode) and reply.code != ErrorCode.INTERNAL, reply
    return reply


@FUZZ
@given(st.binary(max_size=400))
def test_live_random_bytes(raw_socket, data):
    exchange(raw_socket, data)


@FUZZ
@given(malformed_maps)
def test_live_random_maps(raw_socket, payload):
    exchange(raw_socket, msgpack.packb(payload))


@FUZZ
@given(st.sampled_from(["state", "set_params", "hello"]), st.data())
def test_live_mutated_requests(raw_socket, kind, data):
    template = next(m for m in sample_messages() if m.type == kind)
    payload = msgpack.unpackb(encode(template))
    payload["type"] = kind
    key = data.draw(st.sampled_from(sorted(MESSAGE_TYPES[kind].model_fields)))
    payload[key] = data.draw(msgpack_values)
    exchange(raw_socket, msgpack.packb(payload))


def test_server_still_serves_after_the_fuzz(server, raw_socket):
    with ControllerClient(server.endpoint, timeout_s=10.0) as client:
        welcome = client.connect("thesis_humanoid")
        command = client.step(random_state(welcome, np.random.default_rng(0)))
        assert np.all(np.isfinite(command.joint_torque))


def test_oversized_and_multiframe_messages(server, raw_socket):
    raw_socket.send_multipart([b"a", b"b"])
    assert raw_socket.poll(REQUEST_TIMEOUT_MS)
    reply = decode(raw_socket.recv())
    assert reply.code == ErrorCode.MALFORMED
