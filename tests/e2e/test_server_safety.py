"""A server in front of a robot: no hangs, no starvation, no leaks, no file reads, no inheritance.

Each test reproduces a defect of issue 11 against a real ``poise serve``
process on loopback, and checks what the server now does instead.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time

import msgpack
import numpy as np
import pytest
import zmq

from clients import ControllerClient, CurveKeys
from clients.load import from_source
from clients.server_process import ServerProcess
from protocol import PROTOCOL_VERSION, ErrorCode, decode, encode
from protocol.messages import Command, Error, Hello, SetParams, State, Stats, Welcome
from tests.helpers import random_state

pytestmark = pytest.mark.e2e

REPLY_TIMEOUT_MS = 10_000


class Peer:
    """A raw DEALER: chosen routing id, source address and CURVE keys."""

    def __init__(self, endpoint, routing_id=None, source=None, curve=None, context=None):
        self.own_context = context is None  # a shared one: its I/O thread orders all replies
        self.context = zmq.Context() if context is None else context
        self.socket = self.context.socket(zmq.DEALER)
        self.socket.setsockopt(zmq.LINGER, 0)
        if routing_id is not None:
            self.socket.setsockopt(zmq.ROUTING_ID, routing_id)
        if curve is not None:
            self.socket.curve_serverkey = curve.server_public
            self.socket.curve_publickey = curve.client_public
            self.socket.curve_secretkey = curve.client_secret
        if source is not None:
            endpoint = from_source(endpoint, source)
        self.socket.connect(endpoint)

    def ask(self, message, timeout_ms=REPLY_TIMEOUT_MS):
        self.socket.send(message if isinstance(message, bytes) else encode(message))
        assert self.socket.poll(timeout_ms), "no reply"
        return decode(self.socket.recv())

    def close(self):
        self.socket.close(linger=0)
        if self.own_context:
            self.context.term()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def worker_pids(server: ServerProcess) -> list[int]:
    out = subprocess.run(
        ["pgrep", "-P", str(server.process.pid)], capture_output=True, text=True
    ).stdout
    return [int(pid) for pid in out.split()]


def resume(pids: list[int]) -> None:
    """SIGCONT to each process that still exists."""
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)


def resident_mb(server: ServerProcess) -> float:
    total_kb = 0
    for pid in [server.process.pid, *worker_pids(server)]:
        with open(f"/proc/{pid}/status") as status:
            total_kb += next(int(line.split()[1]) for line in status if line.startswith("VmRSS"))
    return total_kb / 1024


def standing(welcome: Welcome, **changes) -> State:
    state = random_state(welcome, np.random.default_rng(0), spread=0.0)
    return state.model_copy(update={"contact_flags": [True] * len(welcome.contacts), **changes})


@pytest.fixture(scope="module")
def tight_server():
    """Two workers and a short deadline."""
    with ServerProcess(extra_args=["--deadline", "0.3"]) as process:
        yield process


@pytest.mark.parametrize(
    "changes",
    [
        {"joint_velocity": 1e150},
        {"joint_velocity": 1e20},
        {"joint_velocity": 1e8},
        {"angular_velocity_base_in_base": 1e150},
    ],
    ids=["qdot 1e150", "qdot 1e20", "qdot 1e8", "omega 1e150"],
)
def test_absurd_finite_state_is_refused_at_the_edge_and_blocks_nobody(tight_server, changes):
    """Defect 1: these states hung the prioritized controller (and every client) for 60 s."""
    with (
        ControllerClient(tight_server.endpoint, timeout_s=10.0) as victim,
        Peer(tight_server.endpoint) as attacker,
    ):
        welcome = victim.connect("thesis_humanoid", controller="tracking")
        assert attacker.ask(Hello(model="thesis_humanoid", controller="prioritized")).type == (
            "welcome"
        )
        ((field, value),) = changes.items()
        base = standing(welcome)
        bad = base.model_construct(
            **{**dict(base), field: np.full(getattr(base, field).size, value)}
        )
        reply = attacker.ask(encode(bad))
        assert isinstance(reply, Error) and reply.code == ErrorCode.INVALID_FIELD, reply
        assert reply.field == field
        assert isinstance(victim.step(standing(welcome)), Command)


def test_a_tick_past_the_deadline_is_a_typed_error_and_a_stuck_worker_is_replaced():
    """A worker that stops answering: its clients get DEADLINE_EXCEEDED within the deadline,
    the worker is killed and replaced, the clients' sessions are re-created by the library."""
    args = ["--workers", "1", "--deadline", "0.2", "--recycle-after", "1"]
    with (
        ServerProcess(extra_args=args) as server,
        ControllerClient(server.endpoint, timeout_s=5.0) as client,
    ):
        welcome = client.connect("thesis_humanoid")
        first_session = welcome.session_id
        assert isinstance(client.step(standing(welcome)), Command)
        (stuck,) = worker_pids(server)
        os.kill(stuck, signal.SIGSTOP)  # a tick that never returns
        with pytest.raises(Exception) as raised:
            client.step(standing(welcome))
        assert getattr(raised.value, "code", None) == ErrorCode.DEADLINE_EXCEEDED
        for _ in range(200):  # until the broker has replaced the worker
            if worker_pids(server) not in ([stuck], []):
                break
            time.sleep(0.1)
        assert stuck not in worker_pids(server)
        command = client.step(standing(welcome))  # NO_SESSION → re-created once
        assert isinstance(command, Command)
        assert client.welcome.session_id != first_session


def test_deadline_applies_to_every_tick():
    """With a deadline shorter than any prioritized tick, no command is ever sent."""
    with (
        ServerProcess(extra_args=["--deadline", "0.0005"]) as server,
        Peer(server.endpoint) as peer,
    ):
        welcome = peer.ask(Hello(model="thesis_humanoid", controller="prioritized"))
        for seq in range(1, 6):
            reply = peer.ask(standing(welcome, seq=seq))
            assert isinstance(reply, Error) and reply.code == ErrorCode.DEADLINE_EXCEEDED, reply
            assert reply.seq == seq


def test_a_reply_back_after_the_deadline_is_not_forwarded():
    """A worker's reply that reaches a broker past the deadline is answered DEADLINE_EXCEEDED.

    The broker is stopped (SIGSTOP) while the worker computes, so that the reply and
    the deadline are both due when it wakes, however busy the machine: the late
    command must not reach the client (a CI run once got one at a 0.5 ms deadline).
    """
    deadline_s = 1.5
    with (
        ServerProcess(extra_args=["--workers", "1", "--deadline", f"{deadline_s}"]) as server,
        Peer(server.endpoint) as peer,
        contextlib.ExitStack() as stack,
    ):
        welcome = peer.ask(Hello(model="thesis_humanoid", controller="momentum"))
        assert isinstance(peer.ask(standing(welcome, seq=1)), Command)
        (worker,) = worker_pids(server)
        broker = server.process.pid
        stack.callback(resume, [worker, broker])  # whatever happens below
        os.kill(worker, signal.SIGSTOP)
        peer.socket.send(encode(standing(welcome, seq=2)))
        time.sleep(deadline_s / 2)  # the broker forwards it to the stopped worker
        os.kill(broker, signal.SIGSTOP)
        resume([worker])  # it starts within the deadline and replies to a sleeping broker
        time.sleep(deadline_s)
        resume([broker])
        assert peer.socket.poll(REPLY_TIMEOUT_MS), "no reply"
        reply = decode(peer.socket.recv())
        assert isinstance(reply, Error) and reply.code == ErrorCode.DEADLINE_EXCEEDED, reply
        assert reply.seq == 2
        assert isinstance(peer.ask(standing(welcome, seq=3)), Command)  # the session lives on


def test_session_caps_message_and_model_size():
    """Defect 3: caps with typed errors, and an oversized message is answered, not dropped."""
    args = ["--max-sessions", "6", "--max-message-bytes", "200000", "--max-model-bytes", "50000"]
    with ServerProcess(extra_args=args) as server:
        _check_caps(server.endpoint)


def _check_caps(endpoint):
    peers = [Peer(endpoint) for _ in range(7)]
    try:
        replies = [p.ask(Hello(model="dino_biped", seq=1)) for p in peers]
        assert [r.type for r in replies[:6]] == ["welcome"] * 6
        assert replies[6].code == ErrorCode.LIMIT_EXCEEDED and "--max-sessions" in replies[6].detail
        big = peers[0].ask(b"\x00" * 300_000)
        assert big.code == ErrorCode.LIMIT_EXCEEDED and "--max-message-bytes" in big.detail
    finally:
        for peer in peers:
            peer.ask(msgpack.packb({"type": "bye", "version": PROTOCOL_VERSION, "seq": 9}))
            peer.close()
    with Peer(endpoint) as peer:
        padded = "<mujoco>" + " " * 60_000 + "</mujoco>"
        reply = peer.ask(Hello(model=None, model_text=padded))
        assert reply.code == ErrorCode.LIMIT_EXCEEDED and reply.field == "model_text"
        # A file sent with a model (issue 18) has the same cap, and the session table lives on.
        mesh = {"assets/foot.stl": b"\x00" * 60_000}
        reply = peer.ask(Hello(model=None, model_text="<mujoco/>", model_assets=mesh))
        assert reply.code == ErrorCode.LIMIT_EXCEEDED and reply.field == "model_assets"
        assert "'assets/foot.stl' of 60000 bytes" in reply.detail
        assert peer.ask(Hello(model="dino_biped", seq=2)).type == "welcome"


def test_sessions_per_client_are_capped():
    args = ["--max-sessions-per-client", "2"]
    with ServerProcess(extra_args=args) as server:
        peers = [Peer(server.endpoint) for _ in range(3)]
        try:
            codes = [p.ask(Hello(model="dino_biped")).type for p in peers]
            assert codes == ["welcome", "welcome", "error"]
            other = Peer(server.endpoint, source="127.0.0.2")  # another client address
            assert other.ask(Hello(model="dino_biped")).type == "welcome"
            other.close()
        finally:
            for peer in peers:
                peer.close()


def test_a_flooding_session_is_refused_beyond_its_in_flight_cap(tight_server):
    """Defect 5: a client that sends without waiting gets LIMIT_EXCEEDED beyond 2 in flight;
    every message is answered, and a paced client beside it gets every tick."""
    with (
        Peer(tight_server.endpoint) as flood,
        ControllerClient(tight_server.endpoint, timeout_s=10.0) as paced,
    ):
        welcome = flood.ask(Hello(model="thesis_humanoid", controller="prioritized"))
        paced_welcome = paced.connect("thesis_humanoid", controller="tracking")
        for seq in range(1, 51):
            flood.socket.send(encode(standing(welcome, seq=seq)))
        for _ in range(20):
            assert isinstance(paced.step(standing(paced_welcome)), Command)
        replies = []
        while len(replies) < 50 and flood.socket.poll(REPLY_TIMEOUT_MS):
            replies.append(decode(flood.socket.recv()))
        assert sorted(r.seq for r in replies) == list(range(1, 51))
        refused = [r for r in replies if isinstance(r, Error)]
        assert refused and all(
            r.code in (ErrorCode.LIMIT_EXCEEDED, ErrorCode.DEADLINE_EXCEEDED) for r in refused
        )
        flood.ask(msgpack.packb({"type": "bye", "version": PROTOCOL_VERSION, "seq": 99}))


@pytest.mark.slow
def test_memory_of_500_expired_sessions_is_returned():
    """Defect 3: 2,000 abandoned sessions took 5.3 GB that never came back."""
    args = ["--session-timeout", "1", "--max-sessions", "600", "--max-sessions-per-client", "600"]
    with ServerProcess(extra_args=args) as server:
        start_mb = resident_mb(server)
        for index in range(500):
            with Peer(server.endpoint) as peer:  # opened, then abandoned
                controller = "prioritized" if index % 2 else "momentum"
                assert peer.ask(Hello(model="thesis_humanoid", controller=controller)).type == (
                    "welcome"
                )
        peak_mb = resident_mb(server)
        with Peer(server.endpoint) as peer:
            for _ in range(100):  # expiry is checked every second
                time.sleep(0.2)
                if peer.ask(Stats()).sessions == []:
                    break
            time.sleep(1.0)  # the workers' drop (and memory release) follows the broker's
        end_mb = resident_mb(server)
        print(f"resident: start {start_mb:.0f} MB, 500 sessions {peak_mb:.0f}, after expiry "
              f"{end_mb:.0f}")  # fmt: skip
        assert peak_mb > start_mb + 100  # the sessions did cost memory
        assert end_mb <= 1.2 * start_mb


@pytest.mark.parametrize(
    "model", ["/etc/shadow", "/etc/passwd", "/proc/1/environ", "x" * 300, "/no/such/file.xml"]
)
def test_the_server_reads_no_file_outside_its_model_directories(tight_server, model):
    """Defect 4 and 6: any path was opened, the error told whether it exists, some were INTERNAL."""
    with Peer(tight_server.endpoint) as peer:
        reply = peer.ask(Hello(model=model))
        assert reply.code == ErrorCode.MODEL_NOT_FOUND
        assert "nor a file in the server's model directories" in reply.detail
        assert "controller_server" not in reply.detail
        clip = peer.ask(Hello(model="thesis_humanoid", controller="momentum",
                              params={"clip": model}))  # fmt: skip
        assert clip.code == ErrorCode.INVALID_PARAMS and clip.field == "params.clip"


def test_another_peer_reusing_a_routing_id_does_not_inherit_the_session(tight_server):
    """Defect 4: a client reusing a disconnected client's routing id got its session."""
    victim = Peer(tight_server.endpoint, routing_id=b"robot-1")
    assert victim.ask(Hello(model="dino_biped")).type == "welcome"
    victim.close()
    time.sleep(0.2)
    with Peer(tight_server.endpoint, routing_id=b"robot-1", source="127.0.0.2") as thief:
        reply = thief.ask(SetParams(params={"stiffness": 1.0}))
        assert reply.code == ErrorCode.NO_SESSION
        assert thief.ask(Stats()).sessions == []  # and it sees nobody else's sessions


@pytest.fixture(scope="module")
def curve_server(tmp_path_factory):
    import zmq.auth

    keys = tmp_path_factory.mktemp("keys")
    allowed = keys / "allowed"
    allowed.mkdir()
    for name in ("server", "alice", "bob", "mallory"):
        zmq.auth.create_certificates(str(keys), name)
    for name in ("alice", "bob"):
        (allowed / f"{name}.key").write_bytes((keys / f"{name}.key").read_bytes())
    args = ["--curve-secret-key", str(keys / "server.key_secret"),
            "--allow-client-keys", str(allowed)]  # fmt: skip
    with ServerProcess(extra_args=args) as process:
        yield (
            process,
            {
                name: CurveKeys.from_files(keys / "server.key", keys / f"{name}.key_secret")
                for name in ("alice", "bob", "mallory")
            },
        )


def test_curve_sessions_are_bound_to_the_key(curve_server):
    server, keys = curve_server
    with ControllerClient(server.endpoint, timeout_s=10.0, curve=keys["alice"]) as alice:
        welcome = alice.connect("thesis_humanoid")
        assert isinstance(alice.step(standing(welcome)), Command)
        with ControllerClient(server.endpoint, timeout_s=10.0, curve=keys["bob"]) as bob:
            bob.connect("dino_biped")
            assert [s.model_name for s in bob.stats()] == ["dino_biped"]
        assert [s.model_name for s in alice.stats()] == ["thesis_humanoid"]
    owner = Peer(server.endpoint, routing_id=b"arm-7", curve=keys["alice"])
    assert owner.ask(Hello(model="dino_biped")).type == "welcome"
    owner.close()
    time.sleep(0.2)
    with Peer(server.endpoint, routing_id=b"arm-7", curve=keys["bob"]) as other:
        assert other.ask(SetParams(params={"stiffness": 1.0})).code == ErrorCode.NO_SESSION


def test_curve_refuses_unknown_keys_and_plain_clients(curve_server):
    server, keys = curve_server
    for peer in (Peer(server.endpoint, curve=keys["mallory"]), Peer(server.endpoint)):
        peer.socket.setsockopt(zmq.SNDTIMEO, 1000)
        try:  # while the refused connection is down, a DEALER has no peer to send to
            peer.socket.send(encode(Hello(model="dino_biped")))
        except zmq.Again:
            pass
        else:
            assert not peer.socket.poll(1000)  # the handshake never completes: no reply at all
        peer.close()


def test_sigterm_answers_requests_already_sent():
    """Defect 8: SIGTERM dropped queued requests unanswered.

    The workers are stopped (SIGSTOP) while the states go out, so that they are still in
    flight when SIGTERM arrives, however busy the machine: the broker has a second to read
    them, and none can be answered before SIGTERM (the deadline is longer than that).
    """
    with (
        ServerProcess(extra_args=["--deadline", "10"]) as server,
        contextlib.ExitStack() as stack,
    ):
        peers = [stack.enter_context(Peer(server.endpoint)) for _ in range(3)]
        welcomes = [p.ask(Hello(model="thesis_humanoid", controller="momentum")) for p in peers]
        workers = worker_pids(server)
        for pid in workers:
            os.kill(pid, signal.SIGSTOP)
        stack.callback(resume, workers)  # whatever happens below
        for peer, welcome in zip(peers, welcomes, strict=True):
            peer.socket.send(encode(standing(welcome, seq=5)))
        time.sleep(1.0)
        assert not any(peer.socket.poll(0) for peer in peers)  # in flight, all of them
        server.process.send_signal(signal.SIGTERM)
        resume(workers)
        for peer in peers:
            assert peer.socket.poll(REPLY_TIMEOUT_MS)
            reply = decode(peer.socket.recv())
            assert reply.seq == 5 and isinstance(reply, Command | Error)
        assert server.process.wait(10) == 0


def test_first_request_is_answered_at_once_after_the_ready_line():
    """Defect 8: the first request took about 4 s (imports and model load after 'listening')."""
    with ServerProcess() as server, ControllerClient(server.endpoint, timeout_s=2.0) as client:
        welcome = client.connect("thesis_humanoid", controller="momentum")
        assert isinstance(client.step(standing(welcome)), Command)


@pytest.mark.parametrize("seq", [True, 1.0, "1", -1, 2**63])
def test_seq_must_be_an_integer(tight_server, seq):
    with Peer(tight_server.endpoint) as peer:
        reply = peer.ask(msgpack.packb({"type": "stats", "version": PROTOCOL_VERSION, "seq": seq}))
        assert reply.code == ErrorCode.INVALID_FIELD and reply.field == "seq"
        assert reply.seq == -1


def test_workers_run_linear_algebra_on_one_thread(tight_server):
    """numpy's threaded BLAS made one SVD 375× slower on a busy 2-core machine."""
    pids = worker_pids(tight_server)
    assert len(pids) == 2  # one per core by default
    for pid in pids:
        with open(f"/proc/{pid}/environ", "rb") as environ:
            variables = dict(
                item.split(b"=", 1) for item in environ.read().split(b"\0") if b"=" in item
            )
        assert variables[b"OPENBLAS_NUM_THREADS"] == b"1"
        assert variables[b"OMP_NUM_THREADS"] == b"1"


def test_a_refused_hello_in_flight_with_a_good_one_leaves_the_good_session(tight_server):
    """Two hellos sent back to back, the first refused: the session the second opened is
    the client's (its route is not removed by the first reply, so it can also expire)."""
    with Peer(tight_server.endpoint) as peer:
        peer.socket.send(encode(Hello(model="no_such_robot", seq=1)))
        peer.socket.send(encode(Hello(model="thesis_humanoid", seq=2)))
        replies = []
        while len(replies) < 2 and peer.socket.poll(REPLY_TIMEOUT_MS):
            replies.append(decode(peer.socket.recv()))
        assert [r.type for r in replies] == ["error", "welcome"]
        reply = peer.ask(standing(replies[1], seq=3))
        assert isinstance(reply, Command), reply
        sessions = {s.session_id: s for s in peer.ask(Stats(seq=4)).sessions}
        assert sessions[replies[1].session_id].ticks == 1
        peer.ask(msgpack.packb({"type": "bye", "version": PROTOCOL_VERSION, "seq": 5}))
