"""The shared client library against a real server process."""

import socket

import numpy as np
import pytest

from clients import ControllerClient, ServerError, ServerTimeout
from clients.server_process import ServerProcess
from protocol import ErrorCode
from tests.helpers import random_state

pytestmark = pytest.mark.e2e


def free_tcp_endpoint() -> str:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{probe.getsockname()[1]}"


def test_no_server_raises_a_timeout_error():
    with ControllerClient(free_tcp_endpoint(), timeout_s=0.2) as client:
        with pytest.raises(ServerTimeout) as info:
            client.connect("thesis_humanoid")
    assert isinstance(info.value, TimeoutError)
    assert "poise serve" in str(info.value)


def test_reconnects_after_the_server_restarts():
    endpoint = free_tcp_endpoint()
    rng = np.random.default_rng(0)
    with ControllerClient(endpoint, timeout_s=5.0) as client:
        with ServerProcess(bind=[endpoint]):
            welcome = client.connect("revolute_humanoid", params={"stiffness": 80.0})
            first_session = welcome.session_id
            client.step(random_state(welcome, rng))
        client.timeout_s = 0.3
        with pytest.raises(ServerTimeout):
            client.step(random_state(welcome, rng))
        with ServerProcess(bind=[endpoint]):
            client.timeout_s = 10.0
            command = client.step(random_state(welcome, rng))
            assert command.seq == client.last_seq
            assert client.welcome.session_id != first_session
            assert client.welcome.params["stiffness"] == 80.0


def test_server_errors_raise_typed_exceptions(server):
    with ControllerClient(server.endpoint, timeout_s=10.0) as client:
        with pytest.raises(ServerError) as info:
            client.connect("thesis_humanoid", params={"damping": -3.0})
        assert info.value.code == ErrorCode.INVALID_PARAMS
        assert info.value.field == "params.damping"
        client.connect("thesis_humanoid")
        assert client.set_params({"damping": 5.0})["damping"] == 5.0
        with pytest.raises(ServerError) as info:
            client.set_params({"damping": "soft"})
        assert info.value.code == ErrorCode.INVALID_PARAMS
        assert any(s.model_name == "thesis_humanoid" for s in client.stats())


def test_send_state_then_receive_command_matches_step(server):
    """The split request returns the same command as `step`; misuse is a typed error."""
    from protocol import PoiseError

    rng = np.random.default_rng(1)
    with ControllerClient(server.endpoint, timeout_s=10.0) as client:
        welcome = client.connect("revolute_humanoid")
        state = random_state(welcome, rng)
        stepped = client.step(state)
        client.send_state(state)
        with pytest.raises(PoiseError, match="outstanding"):
            client.send_state(state)
        with pytest.raises(PoiseError, match="outstanding"):
            client.set_params({"damping": 5.0})
        received = client.receive_command()
        assert received.seq == client.last_seq
        np.testing.assert_allclose(received.joint_torque, stepped.joint_torque, rtol=1e-9)
        with pytest.raises(PoiseError, match="send_state"):
            client.receive_command()
