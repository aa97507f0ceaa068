"""The shared client library against a real server process (and a scripted one)."""

import logging
import socket
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest
import zmq

from clients import ControllerClient, ServerError, ServerTimeout
from clients.server_process import ServerProcess
from protocol import ErrorCode
from protocol.codec import decode, encode
from protocol.messages import Error, Hello, Message, Welcome
from tests.helpers import random_state

pytestmark = pytest.mark.e2e


def free_tcp_endpoint() -> str:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{probe.getsockname()[1]}"


def fake_welcome(session_id: str = "fake") -> Welcome:
    """A valid ``welcome`` for a robot without joints or contacts."""
    return Welcome(
        session_id=session_id,
        model_name="fake",
        model_hash="0" * 64,
        total_mass=1.0,
        standing_position_base_in_world=(0.0, 0.0, 1.0),
        joints=[],
        contacts=[],
        controller="tracking",
        params={},
    )


class ScriptedServer:
    """An in-process ROUTER that answers each request with ``answer(request)``.

    ``answer`` returning ``None`` sends nothing. The socket lives in a thread
    until the ``with`` block ends; :attr:`requests` records what arrived.

    Args:
        answer: Reply for a decoded request (its ``seq`` is set here).
        context: ZeroMQ context (e.g. one with a ZAP authenticator).
        configure: Called with the socket before it binds (e.g. CURVE options).
    """

    def __init__(
        self,
        answer: Callable[[Message], Message | None],
        context: zmq.Context | None = None,
        configure: Callable[[zmq.Socket], None] | None = None,
    ):
        self.answer = answer
        self.requests: list[Message] = []
        self._own_context = context is None
        self._context = context or zmq.Context()
        self._socket = self._context.socket(zmq.ROUTER)
        self._socket.setsockopt(zmq.LINGER, 0)
        if configure is not None:
            configure(self._socket)
        self._socket.bind("tcp://127.0.0.1:*")
        self.endpoint = self._socket.getsockopt_string(zmq.LAST_ENDPOINT)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)

    def __enter__(self) -> "ScriptedServer":
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._socket.close(linger=0)
        if self._own_context:
            self._context.term()

    def _serve(self) -> None:
        while not self._stop.is_set():
            if not self._socket.poll(20, zmq.POLLIN):
                continue
            identity, payload = self._socket.recv_multipart()
            request = decode(payload)
            self.requests.append(request)
            reply = self.answer(request)
            if reply is not None:
                reply = reply.model_copy(update={"seq": request.seq})
                self._socket.send_multipart([identity, encode(reply)])


def test_no_server_raises_a_timeout_error():
    with ControllerClient(free_tcp_endpoint(), timeout_s=0.2) as client:
        with pytest.raises(ServerTimeout) as info:
            client.connect("thesis_humanoid")
    assert isinstance(info.value, TimeoutError)
    assert "poise serve" in str(info.value)
    assert "\n" not in str(info.value)


def test_reconnects_after_the_server_restarts():
    endpoint = free_tcp_endpoint()
    rng = np.random.default_rng(0)
    with ControllerClient(endpoint, timeout_s=5.0) as client:
        with ServerProcess(bind=[endpoint]):
            welcome = client.connect("revolute_humanoid", params={"stiffness": 80.0})
            first_session = welcome.session_id
            client.step(random_state(welcome, rng))
            client.set_params({"damping": 15.0})
        client.timeout_s = 0.3
        with pytest.raises(ServerTimeout):
            client.step(random_state(welcome, rng))
        with ServerProcess(bind=[endpoint]):
            client.timeout_s = 10.0
            command = client.step(random_state(welcome, rng))
            assert command.seq == client.last_seq
            assert client.welcome.session_id != first_session
            assert client.welcome.params["stiffness"] == 80.0
            assert client.welcome.params["damping"] == 15.0


def test_accepted_params_survive_a_reconnect(server):
    """The re-handshake restores what `set_params` changed, not refused or removed keys."""
    with ControllerClient(server.endpoint, timeout_s=10.0) as client:
        welcome = client.connect("thesis_humanoid", params={"stiffness": 80.0})
        frame = welcome.contacts[0].frame

        def point(x: float) -> dict:
            return {"frame": frame, "target_position_in_world": [x, 0.0, 0.1]}

        client.set_params({"damping": 15.0, "point:kept": point(0.1), "point:gone": point(0.2)})
        client.set_params({"point:gone": None, "point:kept": point(0.3)})
        with pytest.raises(ServerError):
            client.set_params({"damping": -1.0})
        restored = client.reconnect()
        assert restored.session_id != welcome.session_id
        assert restored.params["stiffness"] == 80.0
        assert restored.params["damping"] == 15.0
        assert restored.params["point:kept"]["target_position_in_world"] == [0.3, 0.0, 0.1]
        assert "point:gone" not in restored.params


@pytest.mark.slow
def test_an_expired_session_is_re_created_transparently(caplog):
    """`step`, the pipelined pair and `set_params` each re-create an expired session once."""
    rng = np.random.default_rng(2)
    caplog.set_level(logging.WARNING, logger="poise.client")
    with (
        ServerProcess(extra_args=["--session-timeout", "0.5"]) as server,
        ControllerClient(server.endpoint, timeout_s=10.0) as client,
    ):
        welcome = client.connect("revolute_humanoid", params={"stiffness": 80.0})
        client.set_params({"damping": 15.0})
        client.step(random_state(welcome, rng))
        sessions = [welcome.session_id]
        for request in ("step", "pipelined", "set_params"):
            time.sleep(2.0)  # > the session timeout + the server's expiry check period
            caplog.clear()
            if request == "step":
                assert client.step(random_state(welcome, rng)).seq == client.last_seq
            elif request == "pipelined":
                client.send_state(random_state(welcome, rng))
                assert client.receive_command().seq == client.last_seq
            else:
                in_force = client.set_params({"stiffness": 70.0})
                assert in_force["stiffness"] == 70.0
                assert in_force["damping"] == 15.0
            assert client.welcome.session_id not in sessions
            sessions.append(client.welcome.session_id)
            assert client.welcome.params["damping"] == 15.0
            assert client.welcome.params["stiffness"] == 80.0
            records = [r for r in caplog.records if r.name == "poise.client"]
            assert [r.levelno for r in records] == [logging.WARNING]
            assert "expired" in records[0].getMessage()
        assert client.reconnect().params["stiffness"] == 70.0


def test_a_session_is_re_created_only_once():
    """A server that keeps answering NO_SESSION gets one more hello per request, then an error."""

    def answer(request: Message) -> Message:
        if isinstance(request, Hello):
            return fake_welcome()
        return Error(code=ErrorCode.NO_SESSION, field="type", detail="scripted")

    with (
        ScriptedServer(answer) as server,
        ControllerClient(server.endpoint, timeout_s=2.0) as client,
    ):
        welcome = client.connect("fake", params={"stiffness": 80.0})
        state = random_state(welcome, np.random.default_rng(0))
        for request in ("step", "pipelined", "set_params"):
            server.requests.clear()
            with pytest.raises(ServerError) as info:
                if request == "step":
                    client.step(state)
                elif request == "pipelined":
                    client.send_state(state)
                    client.receive_command()
                else:
                    client.set_params({"damping": 5.0})
            assert info.value.code == ErrorCode.NO_SESSION
            sent = "set_params" if request == "set_params" else "state"
            assert [r.type for r in server.requests] == [sent, "hello", sent]
            assert server.requests[1].params == {"stiffness": 80.0}  # nothing refused kept


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
        # `tracking` keeps no state between ticks (momentum's objectives do), so the same
        # state sent twice must give the same command.
        welcome = client.connect("revolute_humanoid", controller="tracking")
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
