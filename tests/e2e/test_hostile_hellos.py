"""Hellos that cost a worker, read the server's files or ended untyped (issue 32, 2, 5, 7).

One real ``poise serve`` (one worker, so that a lost worker loses the victim's
session too), started in a directory holding 1 m decoy meshes under every name
a hostile mesh name could reach. A victim session ticks between the hostile
hellos: it must keep its session, and the worker must be the one it started with.
"""

from __future__ import annotations

import contextlib

import msgpack
import pytest

from clients.server_process import ServerProcess
from protocol import PROTOCOL_VERSION, ErrorCode
from protocol.messages import Command, ContactSpec, Error, Hello, SetParams, Welcome
from tests.controller_server.test_hello_limits import (
    FOOT_SIZE_M,
    assert_soles_are_the_sent_mesh,
    box_stl,
    decoys,
    deep_mjcf,
    sole,
    standing,
    urdf_with_foot_meshes,
)
from tests.e2e.test_server_safety import Peer, worker_pids

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    cwd = tmp_path_factory.mktemp("server_cwd")
    decoys(cwd)
    with contextlib.chdir(cwd):  # the server's working directory is full of decoys
        process = ServerProcess(extra_args=["--workers", "1"]).start()
    try:
        yield process
    finally:
        process.stop()


@pytest.fixture
def victim(server):
    """A session that ticks before and after each test's hostile hellos, on the same worker."""
    workers = worker_pids(server)
    with Peer(server.endpoint) as peer:
        welcome = peer.ask(Hello(model="revolute_humanoid", controller="tracking"))
        assert isinstance(welcome, Welcome), welcome
        assert isinstance(peer.ask(standing(welcome, [True, True], seq=1)), Command)
        yield
        reply = peer.ask(standing(welcome, [True, True], seq=2))
        assert isinstance(reply, Command), reply  # not NO_SESSION: its worker lives
    assert worker_pids(server) == workers


def test_a_hello_far_over_the_point_caps_is_refused_and_one_under_is_served(server, victim):
    """Finding 2: 2 × 3,000 points (5,000 no longer fit a message) vs Talos-like 2 × 8."""
    contacts = [
        {"name": f"{side}_foot", "frame": f"{side}_sole", "points_in_frame": sole(3000)}
        for side in ("left", "right")
    ]
    hostile = msgpack.packb(
        {
            "type": "hello",
            "version": PROTOCOL_VERSION,
            "seq": 7,
            "model": "revolute_humanoid",
            "contacts": contacts,
        },
        use_bin_type=True,
    )
    with Peer(server.endpoint) as peer:
        reply = peer.ask(hostile)
        assert isinstance(reply, Error) and reply.code == ErrorCode.INVALID_FIELD, reply
        assert reply.seq == 7 and reply.field == "contacts.0.points_in_frame"
        feet = [
            ContactSpec(name=f"{side}_foot", frame=f"{side}_sole", points_in_frame=sole(8))
            for side in ("left", "right")
        ]
        welcome = peer.ask(
            Hello(model="revolute_humanoid", controller="prioritized", contacts=feet)
        )
        assert isinstance(welcome, Welcome), welcome
        assert isinstance(peer.ask(standing(welcome, [True, True], seq=2)), Command)


def test_a_3000_deep_model_is_limit_exceeded(server, victim):
    """Finding 7: a RecursionError before."""
    with Peer(server.endpoint) as peer:
        reply = peer.ask(Hello(model_text=deep_mjcf(3000)))
    assert isinstance(reply, Error) and reply.code == ErrorCode.LIMIT_EXCEEDED, reply
    assert reply.field == "model" and "deep" in reply.detail


@pytest.mark.parametrize("frame", ["universe", "root"])
def test_contacts_on_frames_that_are_not_bodies_are_typed(server, victim, frame):
    """Finding 7: StopIteration (INTERNAL) before; the world is refused, a joint finds its body."""
    contacts = [
        ContactSpec(name="left", frame=frame),
        ContactSpec(name="right", frame="right_sole"),
    ]
    with Peer(server.endpoint) as peer:
        reply = peer.ask(Hello(model="revolute_humanoid", contacts=contacts))
        if frame == "universe":
            assert isinstance(reply, Error) and reply.code == ErrorCode.MODEL_INVALID, reply
            assert reply.field == "contacts" and "universe" in reply.detail
        else:
            assert isinstance(reply, Welcome), reply
            assert isinstance(peer.ask(standing(reply, [True, True], seq=2)), Command)


@pytest.mark.parametrize("controller", ["momentum", "prioritized"])
def test_quadprog_without_a_support_answers_commands(server, victim, controller):
    """Finding 7: IndexError inside quadprog on every tick before."""
    hello = Hello(
        model="revolute_humanoid", controller=controller, params={"qp_solver": "quadprog"}
    )
    with Peer(server.endpoint) as peer:
        welcome = peer.ask(hello)
        assert isinstance(welcome, Welcome), welcome
        assert isinstance(peer.ask(standing(welcome, [False, False], seq=2)), Command)
        assert peer.ask(SetParams(seq=3, params={"support_mask": [0.0, 0.0]})).type == "params"
        for seq in (4, 5):
            reply = peer.ask(standing(welcome, [True, True], seq=seq))
            assert isinstance(reply, Command), reply


@pytest.mark.parametrize(
    ("name", "served"),
    [
        ('foot.stl" smoothnormal="true', False),  # read ./mesh.stl before; no extension now
        ('it"s a foot.stl', True),
        ("../mesh.stl", True),
        ("/mesh.stl", True),
        ("f" * 3000 + ".stl", True),
    ],
    ids=["quote", "quote in a name", "parent", "absolute", "long"],
)
def test_a_sent_urdf_reads_no_file_of_the_working_directory(server, victim, name, served):
    """Finding 5: the feet were the server's ./mesh.stl (1 m) instead of the sent 0.24 m mesh.

    A name whose extension is not letters and digits reaches MuJoCo without one, and
    MuJoCo cannot tell how to load it: a typed refusal naming the mesh, not the decoy.
    """
    hello = Hello(
        model_text=urdf_with_foot_meshes(name),
        model_format="urdf",
        model_assets={name: box_stl(FOOT_SIZE_M)},
    )
    with Peer(server.endpoint) as peer:
        reply = peer.ask(hello)
    if served:
        assert isinstance(reply, Welcome), reply
        assert_soles_are_the_sent_mesh(reply.contacts)
    else:
        assert isinstance(reply, Error) and reply.code == ErrorCode.MODEL_INVALID, reply
        assert "no decoder" in reply.detail
