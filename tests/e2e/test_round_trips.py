"""End to end: a real `poise serve` process, 1,000 round trips per model."""

import contextlib
import shutil
import signal

import numpy as np
import pytest

from clients import ControllerClient
from clients.server_process import ServerProcess
from controller_server.models import BUILTIN_MODELS
from tests.helpers import IndependentDynamics, random_state

pytestmark = pytest.mark.e2e

ROUND_TRIPS = 1000


@pytest.mark.parametrize(
    "which",
    # One in the fast tier; the rest, 2 s each, in the slow one.
    [
        "thesis_humanoid",
        *(
            pytest.param(w, marks=pytest.mark.slow)
            for w in [*BUILTIN_MODELS, "by_path", "by_text", "momentum"]
            if w != "thesis_humanoid"
        ),
    ],
)
def test_thousand_round_trips_are_dynamically_consistent(server, which, tmp_path):
    controller = "tracking"
    endpoint = server.endpoint
    stack = contextlib.ExitStack()
    if which == "momentum":  # the full controller, every objective on
        path = BUILTIN_MODELS["thesis_humanoid"]
        hello = {"model": "thesis_humanoid", "params": {"angular_momentum_gain": 50.0}}
        controller = "momentum"
    elif which == "by_path":
        path = tmp_path / "my_dino.xml"
        shutil.copy(BUILTIN_MODELS["dino_biped"], path)
        hello = {"model": "my_dino.xml"}  # relative to the server's model directory
        own = ServerProcess(extra_args=["--model-dir", str(tmp_path)])
        endpoint = stack.enter_context(own).endpoint
    elif which == "by_text":
        path = BUILTIN_MODELS["revolute_humanoid"]
        hello = {"model_text": path.read_text()}
    else:
        path = BUILTIN_MODELS[which]
        hello = {"model": which}
    rng = np.random.default_rng(7)
    with stack, ControllerClient(endpoint, timeout_s=10.0) as client:
        welcome = client.connect(**hello, controller=controller)
        checker = IndependentDynamics(str(path), welcome)
        limits = np.concatenate([j.torque_limit for j in welcome.joints])
        worst = 0.0
        for _ in range(ROUND_TRIPS):
            state = random_state(welcome, rng)
            command = client.step(state)
            assert command.seq == client.last_seq
            for array in (
                command.joint_acceleration,
                command.joint_torque,
                command.contact_force_in_world,
                command.base_linear_acceleration_in_world,
                command.base_angular_acceleration_in_base,
            ):
                assert np.all(np.isfinite(array))
            assert np.all(np.abs(command.joint_torque) <= limits + 1e-9)
            worst = max(worst, checker.residual(state, command))
            assert checker.point_force_mismatch < 1e-6
        assert worst < 1e-6, f"inverse-dynamics residual {worst:.3g}"
        stats = {s.session_id: s for s in client.stats()}
        assert stats[welcome.session_id].ticks == ROUND_TRIPS


def test_clients_with_different_robots_interleave(server):
    rng = np.random.default_rng(3)
    with (
        ControllerClient(server.endpoint, timeout_s=10.0) as first,
        ControllerClient(server.endpoint, timeout_s=10.0) as second,
    ):
        welcomes = [first.connect("thesis_humanoid"), second.connect("revolute_humanoid")]
        assert welcomes[0].session_id != welcomes[1].session_id
        for _ in range(20):
            for client, welcome in zip((first, second), welcomes, strict=True):
                command = client.step(random_state(welcome, rng))
                assert command.joint_torque.size == sum(j.nv for j in welcome.joints)


def test_ipc_endpoint_and_clean_sigterm(tmp_path):
    endpoint = f"ipc://{tmp_path}/poise.sock"
    process = ServerProcess(bind=[endpoint]).start()
    try:
        with ControllerClient(endpoint, timeout_s=10.0) as client:
            welcome = client.connect("thesis_humanoid")
            client.step(random_state(welcome, np.random.default_rng(0)))
    finally:
        assert process.stop() == 0


def test_sigint_stops_cleanly():
    process = ServerProcess().start()
    process.process.send_signal(signal.SIGINT)
    assert process.process.wait(10) == 0
    process.stop()
