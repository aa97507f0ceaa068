"""Issue 32, finding 6: a live server under a mix of valid and mutated traffic from many clients.

Clients open sessions of every built-in model and controller with random parameters, send
states near standing and mutated ones, ``set_params`` with random values, ``stats``,
``bye`` and garbage. Every request gets exactly one typed reply, the server's log holds no
traceback, no worker is replaced, and once the sessions expire the broker and the workers
hold no more memory than after a warm-up of the same mix.

20,000 messages in every run of the slow tier, 200,000 under
``--hypothesis-profile nightly`` (:func:`tests.helpers.examples`).
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
import zmq

from clients.load import from_source
from clients.server_process import ServerProcess
from controller_server.controllers import CONTROLLERS
from controller_server.models import BUILTIN_MODELS
from protocol import PROTOCOL_VERSION, ErrorCode, decode, encode
from protocol.messages import (
    BASE_POSE_FIELDS,
    ContactSpec,
    Error,
    Hello,
    ImuSample,
    State,
    Welcome,
)
from tests.e2e.test_fuzz_server import _mutate, _peek_seq
from tests.helpers import examples, random_state

pytestmark = pytest.mark.e2e

MESSAGES = examples(200_000)
"""20,000 in every slow run, 200,000 nightly."""
CLIENTS = 12
WORKERS = 2
DEADLINE_S = 10.0
"""Generous, so that whether a tick is answered in time never depends on the machine's load."""
SESSION_TIMEOUT_S = 2.0
REPLY_WITHIN_MS = int((DEADLINE_S + 20.0) * 1000)
"""The server answers every request by its deadline; a loaded 2-core machine gets slack."""
IN_FLIGHT = 2
"""Requests a client keeps in flight (the server's ``--max-in-flight`` default)."""
MEMORY_SLACK = 0.20
"""Resident memory after the run may exceed the warm-up's by this fraction at most."""
CLIPS = ["squat", "leg_swing", "kicks", "stand_sway", "toe_touch", "leg_circle"]


# ------------------------------------------------------------------ the mix


def random_param(rng: np.random.Generator, controller: str, welcome: Welcome | None) -> tuple:
    """One parameter of ``controller`` and a random value for it, mostly within its range."""
    specs = CONTROLLERS[controller].PARAMETERS
    name = str(rng.choice(sorted(specs)))
    spec = specs[name]
    if rng.random() < 0.1:  # anything: a wrong type, a non-finite or huge value
        return name, [None, True, "x", -1.0, 1e308, float("nan"), [1.0], {"a": 1}][
            int(rng.integers(8))
        ]
    low = max(spec.minimum, -1e3) if np.isfinite(spec.minimum) else -1e3
    high = min(spec.maximum, 1e4) if np.isfinite(spec.maximum) else 1e4
    if spec.kind == "float":
        value = (
            float(rng.uniform(low, high))
            if rng.random() < 0.5
            else float(np.clip(rng.lognormal(0, 2) * (spec.default or 1.0), low, high))
        )
    elif spec.kind == "int":
        value = int(rng.integers(int(low), int(min(high, 20)) + 1))
    elif spec.kind == "bool":
        value = bool(rng.random() < 0.5)
    elif spec.kind == "choice":
        value = str(rng.choice(spec.choices))
    elif spec.kind == "text":
        value = str(rng.choice([*CLIPS, "", "no_such_clip"]))
    else:  # vector: the length in force, random entries in range
        current = welcome.params.get(name) if welcome is not None else None
        length = len(current) if isinstance(current, list | tuple) else int(rng.integers(1, 40))
        value = [float(x) for x in rng.uniform(max(low, -10), min(high, 10), length)]
    return name, value


def random_contacts(rng: np.random.Generator) -> list[ContactSpec]:
    """Two soles of 1 to 8 random points each (every set a new entry of the model cache)."""
    return [
        ContactSpec(
            name=f"{side}_foot",
            frame=f"{side}_sole",
            points_in_frame=[
                (float(x), float(y), 0.0)
                for x, y in rng.uniform([-0.15, -0.06], [0.15, 0.06], (int(rng.integers(1, 9)), 2))
            ],
            friction_coefficient=float(rng.uniform(0.2, 1.2)),
        )
        for side in ("left", "right")
    ]


def random_hello(rng: np.random.Generator, seq: int) -> Hello:
    """A valid hello of a built-in model (by name, or its text) and controller, with up to
    three random parameters, sometimes contacts of its own or an IMU on the pelvis."""
    controller = str(rng.choice(sorted(CONTROLLERS)))
    params = dict(random_param(rng, controller, None) for _ in range(int(rng.integers(0, 4))))
    params = {k: v for k, v in params.items() if not isinstance(v, list) or rng.random() < 0.2}
    model = str(rng.choice(sorted(BUILTIN_MODELS)))
    fields = {}
    if rng.random() < 0.2:
        fields["contacts"] = random_contacts(rng)
    if rng.random() < 0.1:  # the model's text with one digit changed somewhere: a new model
        text = BUILTIN_MODELS[model].read_text()
        fields["model_text"] = text.replace("0.", f"0.{int(rng.integers(10))}", 1)
        model = None
    if rng.random() < 0.2:
        fields["imu_frame"] = "pelvis"
        fields["imu_position_in_frame"] = tuple(float(x) for x in rng.uniform(-0.1, 0.1, 3))
    return Hello(
        seq=seq,
        model=model,
        controller=controller,
        params=params,
        diagnostics_period_ticks=int(rng.choice([1, 1, 10, 100])),
        **fields,
    )


def imu_state(state: State, rng: np.random.Generator) -> State:
    """``state`` with its base given by an IMU reading instead (near still, gravity up)."""
    return state.model_copy(
        update={
            **dict.fromkeys(BASE_POSE_FIELDS),
            "imu": ImuSample(
                angular_velocity_imu_in_imu=rng.normal(0, 0.1, 3),
                linear_acceleration_imu_in_imu=np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.3, 3),
                orientation_imu_in_world_xyzw=(
                    state.orientation_base_in_world_xyzw if rng.random() < 0.5 else None
                ),
            ),
        }
    )


def garbage(rng: np.random.Generator, seq: int) -> bytes:
    """Bytes that are not a request: random, a map of random keys, a reply sent as a request."""
    kind = int(rng.integers(4))
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 300)))
    if kind == 1:
        keys = ["type", "version", "seq", "params", "model", "joint_position", "zz"]
        values = [None, True, -1, 2**63, 1.5, "hello", "state", b"\x00" * 8, [1, 2], {"a": 1}]
        return msgpack.packb(
            {str(rng.choice(keys)): values[int(rng.integers(len(values)))] for _ in range(4)}
        )
    if kind == 2:
        return msgpack.packb(
            {
                "type": str(
                    rng.choice(["welcome", "command", "params", "error", "asset", "stats"])
                ),
                "version": PROTOCOL_VERSION,
                "seq": seq,
            }
        )
    return msgpack.packb({"type": "stats", "version": PROTOCOL_VERSION, "seq": seq})


@dataclasses.dataclass
class MixClient:
    """What one client knows: its session's welcome and controller, if it has one."""

    rng: np.random.Generator
    welcome: Welcome | None = None
    controller: str = "momentum"
    imu: bool = False
    seq: int = 0

    def next_request(self) -> tuple[bytes, str]:
        """The next request's bytes and its kind (for the counts)."""
        self.seq += 1
        rng, seq = self.rng, self.seq
        draw = rng.random()
        if self.welcome is None or draw < 0.03:
            hello = random_hello(rng, seq)
            self.controller = hello.controller
            self.imu = hello.imu_frame is not None
            return encode(hello), "hello"
        if draw < 0.55:
            state = random_state(
                self.welcome,
                rng,
                spread=float(rng.choice([0.0, 0.05, 0.1, 0.3, 0.5])),
                wrenches=bool(rng.random() < 0.2),
            )
            state = state.model_copy(update={"seq": seq})
            if self.imu and rng.random() < 0.7:
                return encode(imu_state(state, rng)), "imu state"
            return encode(state), "state"
        if draw < 0.80:
            return _mutate(rng, self.welcome, seq), "mutated"
        if draw < 0.90:
            params = dict(
                random_param(rng, self.controller, self.welcome)
                for _ in range(int(rng.integers(1, 4)))
            )
            payload = {"type": "set_params", "version": PROTOCOL_VERSION, "seq": seq}
            return msgpack.packb({**payload, "params": params}), "set_params"
        if draw < 0.92:
            return msgpack.packb({"type": "bye", "version": PROTOCOL_VERSION, "seq": seq}), "bye"
        return garbage(rng, seq), "garbage"

    def take_reply(self, reply) -> None:
        """Follow the session: a welcome opens it, a bye or ``NO_SESSION`` closes it."""
        if isinstance(reply, Welcome):
            self.welcome = reply
            self.controller = reply.controller
        elif reply.type == "bye" or (
            isinstance(reply, Error) and reply.code == ErrorCode.NO_SESSION
        ):
            self.welcome = None


# ------------------------------------------------------------------ the run


@dataclasses.dataclass
class Tally:
    """What the clients saw."""

    sent: int = 0
    replies: int = 0
    extra_replies: int = 0
    unanswered: int = 0
    wrong_seq: list = dataclasses.field(default_factory=list)
    internal: list = dataclasses.field(default_factory=list)
    non_finite_commands: int = 0
    labels: dict = dataclasses.field(default_factory=dict)
    lock: threading.Lock = dataclasses.field(default_factory=threading.Lock)

    def add(self, other: dict) -> None:
        with self.lock:
            for label, count in other.items():
                self.labels[label] = self.labels.get(label, 0) + count


def _run_client(endpoint: str, index: int, seed: int, messages: int, tally: Tally) -> None:
    """Send ``messages`` requests one at a time, each answered once before the next.

    Clients come from addresses of their own (127.0.0.2, .3, …: each one client to the
    server, which shares its workers between clients), the last two from one address.
    """
    client = MixClient(np.random.default_rng(seed))
    labels: dict[str, int] = {}
    context = zmq.Context()
    socket = context.socket(zmq.DEALER)
    socket.setsockopt(zmq.LINGER, 0)
    source = f"127.0.0.{2 + min(index, CLIENTS - 2)}"
    socket.connect(from_source(endpoint, source))
    try:
        for _ in range(messages):
            data, _kind = client.next_request()
            sent_seq = _peek_seq(data)
            socket.send(data)
            with tally.lock:
                tally.sent += 1
            if not socket.poll(REPLY_WITHIN_MS):
                with tally.lock:
                    tally.unanswered += 1
                return  # the one reply it waited for is lost: the run has failed
            reply = decode(socket.recv())  # a typed message, or this raises
            with tally.lock:
                tally.replies += 1
                if sent_seq is not None and reply.seq != sent_seq:
                    tally.wrong_seq.append((sent_seq, reply))
            if isinstance(reply, Error):
                label = reply.code.name
                if reply.code == ErrorCode.INTERNAL:
                    with tally.lock:
                        tally.internal.append(reply)
            else:
                label = reply.type
                if reply.type == "command" and not all(
                    np.isfinite(a).all()
                    for a in (
                        reply.joint_acceleration,
                        reply.joint_torque,
                        reply.contact_force_in_world,
                    )
                ):
                    with tally.lock:
                        tally.non_finite_commands += 1
            labels[label] = labels.get(label, 0) + 1
            client.take_reply(reply)
        while socket.poll(200):  # anything more is a second reply to some request
            socket.recv()
            with tally.lock:
                tally.extra_replies += 1
    finally:
        socket.close()
        context.term()
        tally.add(labels)


def run_mix(endpoint: str, messages: int, clients: int, seed: int) -> Tally:
    """``messages`` requests in all from ``clients`` threads, each its own DEALER."""
    tally = Tally()
    threads = [
        threading.Thread(
            target=_run_client,
            args=(endpoint, i, seed * 1000 + i, messages // clients, tally),
            daemon=True,
        )
        for i in range(clients)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return tally


def resident_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:")) / 1024


def worker_pids(server: ServerProcess) -> list[int]:
    assert server.process is not None
    found = subprocess.run(
        ["pgrep", "-P", str(server.process.pid)], capture_output=True, text=True, check=False
    )
    return sorted(int(pid) for pid in found.stdout.split())


def memory(server: ServerProcess) -> dict[str, float]:
    """Resident MB of the broker and of each worker (by pid)."""
    assert server.process is not None
    sizes = {"broker": resident_mb(server.process.pid)}
    sizes.update({f"worker {pid}": resident_mb(pid) for pid in worker_pids(server)})
    return sizes


def wait_until_sessions_expire() -> None:
    """The broker looks once a second for sessions idle past the timeout, then workers drop."""
    time.sleep(SESSION_TIMEOUT_S + 3.0)


class LoggedServer(ServerProcess):
    """A :class:`ServerProcess` whose log (its stderr) goes to a file."""

    def __init__(self, log_path: Path, **kwargs):
        super().__init__(**kwargs)
        self.log_path = log_path

    def start(self) -> LoggedServer:
        import clients.server_process as module

        popen = subprocess.Popen
        with open(self.log_path, "w") as log:

            def popen_logged(*args, **kwargs):
                return popen(*args, stderr=log, **kwargs)

            module.subprocess.Popen = popen_logged  # type: ignore[misc]
            try:
                super().start()
            finally:
                module.subprocess.Popen = popen  # type: ignore[misc]
        return self

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")


def fuzz_mix(messages: int, clients: int = CLIENTS, workers: int = WORKERS, seed: int = 0):
    """Warm up, run ``messages`` of the mix, let sessions expire; what was seen and measured."""
    with tempfile.TemporaryDirectory() as directory:
        server = LoggedServer(
            Path(directory) / "server.log",
            extra_args=[
                "--workers",
                str(workers),
                "--deadline",
                f"{DEADLINE_S:g}",
                "--session-timeout",
                f"{SESSION_TIMEOUT_S:g}",
            ],
        )
        with server:
            warm_up = run_mix(server.endpoint, max(messages // 10, 20 * clients), clients, seed + 1)
            wait_until_sessions_expire()
            before = memory(server)
            tally = run_mix(server.endpoint, messages, clients, seed)
            wait_until_sessions_expire()
            after = memory(server)
            log = server.log()
    return warm_up, tally, before, after, log


@pytest.mark.slow
def test_fuzz_mix_of_twelve_clients():
    """Every request answered once and typed, no traceback, no worker replaced, memory bounded."""
    warm_up, tally, before, after, log = fuzz_mix(MESSAGES)
    print(
        f"\nwarm-up {warm_up.replies} replies; run {tally.replies}: {sorted(tally.labels.items())}"
    )
    print(f"resident MB after the warm-up {before}, after the run {after}")
    for run in (warm_up, tally):
        assert run.unanswered == 0
        assert run.extra_replies == 0
        assert run.replies == run.sent
        assert not run.wrong_seq, run.wrong_seq[:3]
        assert not run.internal, run.internal[:3]
        assert run.non_finite_commands == 0
    assert tally.replies >= MESSAGES - CLIENTS
    assert log.count("Traceback") == 0, log[log.index("Traceback") - 2000 :][:6000]
    assert "replaced" not in log, log
    assert set(after) == set(before), (before, after)  # the same workers: none replaced
    for process, size_mb in after.items():
        assert size_mb <= before[process] * (1 + MEMORY_SLACK), (process, before, after)


if __name__ == "__main__":  # python -m tests.e2e.test_fuzz_mix MESSAGES [CLIENTS WORKERS]
    from controller_server.blas import default_to_single_threaded_blas

    default_to_single_threaded_blas()
    count, *rest = map(int, sys.argv[1:])
    started = time.monotonic()
    warm_up, tally, before, after, log = fuzz_mix(count, *rest)
    print(f"{time.monotonic() - started:.0f} s; pid {os.getpid()}")
    print(
        f"warm-up: sent {warm_up.sent}, replies {warm_up.replies}, {sorted(warm_up.labels.items())}"
    )
    print(
        f"run: sent {tally.sent}, replies {tally.replies}, extra {tally.extra_replies}, "
        f"unanswered {tally.unanswered}, wrong seq {len(tally.wrong_seq)}, "
        f"INTERNAL {len(tally.internal)}, non-finite {tally.non_finite_commands}"
    )
    print(sorted(tally.labels.items()))
    print("INTERNAL:", [e.detail[:100] for e in tally.internal[:10]])
    print(f"tracebacks {log.count('Traceback')}, replacements {log.count('replaced')}")
    print(f"resident MB after the warm-up {before}\nresident MB after the run    {after}")
    print(log[-4000:])
