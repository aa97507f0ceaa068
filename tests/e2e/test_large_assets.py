"""Issue 31 (3): a robot's meshes reach the server whatever their size.

Against real ``poise serve`` processes: a vendor-style robot with a mesh
larger than the server's message cap is simulated through ``poise sim
--connect``, its files uploaded once by SHA-256 and found in the server's
cache the next time; a request the server cannot read reaches the client as
the server's refusal (not as a timeout) and ``poise sim`` prints it in one
line; the message cap is the one ``poise serve`` is given; uploads that are
corrupt, too long or beyond a bound get typed errors; a log of a session
whose files went by hash replays on a server that never saw them.
"""

from __future__ import annotations

import hashlib
import re
import shutil
import stat
import struct
from pathlib import Path

import msgpack
import numpy as np
import pytest

from clients import ControllerClient
from clients.client import ServerError, ServerTimeout
from clients.physics.model_file import hello_model
from clients.server_process import ServerProcess
from controller_server.models import BUILTIN_MODELS
from protocol import PROTOCOL_VERSION, Asset, AssetReceived, ErrorCode, decode, encode
from protocol.messages import Error, Hello, Welcome
from protocol.recording import read_log
from tests.e2e.test_server_safety import Peer
from tests.helpers import run_poise

pytestmark = pytest.mark.e2e

MODELS = Path(__file__).resolve().parents[1] / "models"
MESSAGE_CAP_BYTES = 1_000_000
"""The server's ``--max-message-bytes`` in the large-robot tests: below the mesh's size."""


def sphere_stl(path: Path, rings: int = 150, segments: int = 200, radius_m: float = 0.05) -> None:
    """A closed UV sphere as a binary STL: 2 × rings × segments triangles (60,000: 3.0 MB)."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    points = (
        np.stack(
            [
                np.outer(np.sin(theta), np.cos(phi)),
                np.outer(np.sin(theta), np.sin(phi)),
                np.outer(np.cos(theta), np.ones_like(phi)),
            ],
            axis=-1,
        )
        * radius_m
    )
    a, b, c, d = points[:-1, :-1], points[1:, :-1], points[1:, 1:], points[:-1, 1:]
    triangles = np.concatenate(
        [np.stack([a, b, c], 2).reshape(-1, 3, 3), np.stack([a, c, d], 2).reshape(-1, 3, 3)]
    )
    records = np.zeros(
        len(triangles), dtype=[("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attr", "<u2")]
    )
    records["vertices"] = triangles
    path.write_bytes(b"\0" * 80 + struct.pack("<I", len(triangles)) + records.tobytes())


def large_robot(directory: Path, radius_m: float = 0.05) -> Path:
    """``tests/models/vendor_humanoid`` with a dense visual mesh on the pelvis; its scene.

    Robots of different ``radius_m`` share no file but the foot's.
    """
    shutil.copytree(MODELS / "vendor_humanoid", directory)
    sphere_stl(directory / "assets" / "pelvis_detail.stl", radius_m=radius_m)
    robot = (directory / "robot.xml").read_text()
    mesh = '<mesh name="foot" file="foot.stl"/>'
    geom = '<geom class="visual" type="box" size="0.08 0.14 0.07"/>'
    assert mesh in robot and geom in robot
    robot = robot.replace(
        mesh, f'{mesh}\n    <mesh name="pelvis_detail" file="pelvis_detail.stl"/>'
    )
    robot = robot.replace(geom, f'{geom}\n      <geom class="visual" mesh="pelvis_detail"/>', 1)
    (directory / "robot.xml").write_text(f"{robot}<!-- {radius_m} -->\n")
    return directory / "scene.xml"


@pytest.fixture(scope="module")
def large_robot_scene(tmp_path_factory) -> Path:
    return large_robot(tmp_path_factory.mktemp("large") / "vendor_humanoid")


@pytest.fixture(scope="module")
def capped_server():
    """A server whose message cap is below the size of the large robot's mesh."""
    args = ["--workers", "1", "--max-message-bytes", str(MESSAGE_CAP_BYTES)]
    with ServerProcess(extra_args=args) as process:
        yield process


def sim(scene: Path, endpoint: str, output: Path, *more: str, log_level: str = "INFO"):
    """``poise sim stand`` for 0.3 s on ``scene`` against the server at ``endpoint``."""
    return run_poise(
        [
            "--log-level",
            log_level,
            "sim",
            "stand",
            "--model",
            str(scene),
            "--duration",
            "0.3",
            "--connect",
            endpoint,
            "--output",
            str(output),
            *more,
        ],
        cwd=output.parent,
    )


@pytest.mark.slow
def test_a_robot_whose_mesh_exceeds_the_message_cap_is_simulated_and_sent_once(
    capped_server, large_robot_scene, tmp_path
):
    mesh_bytes = (large_robot_scene.parent / "assets" / "pelvis_detail.stl").stat().st_size
    assert mesh_bytes > 2 * MESSAGE_CAP_BYTES  # so it takes several chunks
    first = sim(large_robot_scene, capped_server.endpoint, tmp_path / "first")
    assert first.returncode == 0, first.stderr
    assert "stayed up" in first.stdout, first.stdout
    files = hello_model(str(large_robot_scene))["model_assets"]  # robot.xml and 2 meshes
    total_mb = sum(map(len, files.values())) / 1e6
    assert f"uploading {len(files)} files ({total_mb:.1f} MB)" in first.stderr, first.stderr
    second = sim(large_robot_scene, capped_server.endpoint, tmp_path / "second")
    assert second.returncode == 0, second.stderr
    assert "uploading" not in second.stderr, second.stderr  # the server's cache had them
    # This host's next client uploads nothing either; another host's is asked for them all.
    with ControllerClient(capped_server.endpoint, timeout_s=30.0) as client:
        welcome = client.connect(**hello_model(str(large_robot_scene)), controller="tracking")
        assert client.uploaded_asset_bytes == 0 and client.uploaded_assets == 0
    fields = hello_model(str(large_robot_scene))
    hashes = {
        path: hashlib.sha256(data).hexdigest() for path, data in fields["model_assets"].items()
    }
    by_hash = Hello(model_text=fields["model_text"], model_asset_hashes=hashes)
    with Peer(capped_server.endpoint, source="127.0.0.2") as stranger:
        refusal = stranger.ask(by_hash)
        assert isinstance(refusal, Error) and refusal.code == ErrorCode.ASSETS_MISSING, refusal
        assert refusal.missing_asset_hashes == sorted(set(hashes.values()))
        assert refusal.max_message_bytes == MESSAGE_CAP_BYTES
    with Peer(capped_server.endpoint) as neighbour:  # the same host: its files
        reply = neighbour.ask(by_hash.model_copy(update={"controller": "tracking"}))
        assert isinstance(reply, Welcome), reply
        assert reply.model_hash == welcome.model_hash


def test_a_client_uploads_only_what_the_server_lacks(capped_server, tmp_path):
    """One file changed: only it is sent. A chunk over the cap is refused at the door."""
    scene = large_robot(tmp_path / "robot", radius_m=0.051)
    foot = scene.parent / "assets" / "foot.stl"
    for header in (b"first", b"second"):  # the STL's free header: new content each time
        foot.write_bytes(header.ljust(80) + foot.read_bytes()[80:])
        fields = hello_model(str(scene))
        with ControllerClient(capped_server.endpoint, timeout_s=30.0) as client:
            client.connect(**fields, controller="tracking")
        if header == b"first":
            continue  # it may have uploaded the others too (this test may run first)
        assert client.uploaded_assets == 1  # the foot
        assert client.uploaded_asset_bytes == len(fields["model_assets"]["assets/foot.stl"])
    # A chunk larger than the cap is refused at the door, as any message would be.
    big = Asset(sha256="0" * 64, size_bytes=1_500_000, data=bytes(1_500_000))
    with Peer(capped_server.endpoint) as peer:
        reply = peer.ask(big)
        assert reply.code == ErrorCode.LIMIT_EXCEEDED and reply.seq == -1
        assert reply.max_message_bytes == MESSAGE_CAP_BYTES


def padded_model(directory: Path, size_bytes: int) -> Path:
    """The thesis humanoid with a comment that makes its text ``size_bytes`` long."""
    text = BUILTIN_MODELS["thesis_humanoid"].read_text()
    head, tail = text.split("\n", 1)
    padding = size_bytes - len(text) - len("<!--  -->\n")
    path = directory / f"padded_humanoid_{size_bytes}.xml"
    path.write_text(f"{head}\n<!-- {'x' * padding} -->\n{tail}")
    return path


def test_an_unreadable_request_is_answered_as_a_refusal_not_a_timeout(tmp_path):
    args = ["--workers", "1", "--max-message-bytes", "100000"]
    with ServerProcess(extra_args=args) as server:
        model = padded_model(tmp_path, 150_000)  # within twice the cap: answered
        with ControllerClient(server.endpoint, timeout_s=30.0) as client:
            with pytest.raises(ServerError) as info:
                client.connect(**hello_model(str(model)))
            assert not isinstance(info.value, ServerTimeout)
            assert info.value.code == ErrorCode.LIMIT_EXCEEDED
            assert "exceeds the server's limit of 100000" in info.value.detail
            assert "--max-message-bytes" in info.value.detail
            assert info.value.seq == client.last_seq  # the answer to the hello in flight
            welcome = client.connect("thesis_humanoid", controller="tracking")  # it goes on
            assert welcome.model_name == "thesis_humanoid"
        # Over twice the cap, ZeroMQ drops the message: the timeout says what may be wrong.
        with ControllerClient(server.endpoint, timeout_s=2.0) as client:
            with pytest.raises(ServerTimeout, match="drops one over twice its `poise serve"):
                client.connect(**hello_model(str(padded_model(tmp_path, 250_000))))
        result = sim(model, server.endpoint, tmp_path / "out", log_level="WARNING")
        assert result.returncode == 2, result.stderr
        assert re.fullmatch(
            r"poise sim: the server refused the request: LIMIT_EXCEEDED: message of \d+ bytes "
            r"exceeds the server's limit of 100000 \(`poise serve --max-message-bytes`\)\n",
            result.stderr,
        ), result.stderr


def test_the_message_cap_is_the_one_poise_serve_is_given():
    """A 20 MB hello (files inline) passes a server started with a 64 MB cap."""
    args = ["--workers", "1", "--max-message-bytes", "64000000"]
    files = {f"padding/{i}.bin": bytes([i]) * 4_000_000 for i in range(5)}
    hello = Hello(model_text=BUILTIN_MODELS["dino_biped"].read_text(), model_assets=files)
    payload = encode(hello)
    assert len(payload) > 20_000_000
    with ServerProcess(extra_args=args) as server, Peer(server.endpoint) as peer:
        reply = peer.ask(payload, timeout_ms=60_000)
        assert isinstance(reply, Welcome), reply


def _chunk(sha256: str, size: int, offset: int, data: bytes, seq: int = 1) -> Asset:
    return Asset(seq=seq, sha256=sha256, size_bytes=size, offset_bytes=offset, data=data)


def test_uploads_out_of_order_corrupt_too_long_or_beyond_a_bound_get_typed_errors():
    args = [
        "--workers",
        "1",
        "--max-message-bytes",
        "100000",
        "--max-model-bytes",
        "300000",
        "--max-upload-bytes-per-client",
        "500000",
        "--asset-cache-bytes",
        "1000000",
    ]
    content = bytes(range(256)) * 400  # 102,400 bytes: two chunks
    sha256 = hashlib.sha256(content).hexdigest()
    wrong = hashlib.sha256(b"something else").hexdigest()
    with ServerProcess(extra_args=args) as server, Peer(server.endpoint) as peer:

        def ask(chunk: Asset):
            reply = peer.ask(chunk)
            assert reply.seq == chunk.seq
            return reply

        def assert_error(reply, code, field, words):
            assert isinstance(reply, Error), reply
            assert (reply.code, reply.field) == (code, field), reply
            assert words in reply.detail, reply.detail

        invalid, limit = ErrorCode.INVALID_FIELD, ErrorCode.LIMIT_EXCEEDED
        size = len(content)
        # Out of order: a chunk past the start of an upload that never began, then a gap.
        assert_error(
            ask(_chunk(sha256, size, 60_000, content[60_000:])),
            invalid,
            "offset_bytes",
            "start it at offset 0",
        )
        first = ask(_chunk(sha256, size, 0, content[:60_000], seq=2))
        assert first == AssetReceived(seq=2, sha256=sha256, received_bytes=60_000, complete=False)
        assert_error(
            ask(_chunk(sha256, size, 70_000, content[70_000:], seq=3)),
            invalid,
            "offset_bytes",
            "60000 bytes have arrived",
        )
        assert_error(
            ask(_chunk(sha256, size + 1, 60_000, content[60_000:], seq=4)),
            invalid,
            "size_bytes",
            "declared 102400",
        )
        # Beyond the declared size: refused, and the upload is gone.
        assert_error(
            ask(_chunk(sha256, size, 60_000, content[60_000:] + b"!", seq=5)),
            invalid,
            "data",
            "past size_bytes=102400",
        )
        assert_error(
            ask(_chunk(sha256, size, 60_000, content[60_000:], seq=6)),
            invalid,
            "offset_bytes",
            "no upload",
        )
        # Corrupt: the bytes do not hash to the name given; the file is not kept.
        ask(_chunk(wrong, size, 0, content[:60_000], seq=7))
        assert_error(
            ask(_chunk(wrong, size, 60_000, content[60_000:], seq=8)),
            invalid,
            "sha256",
            f"hash to {sha256[:12]}",
        )
        hello = Hello(seq=9, model_text="<mujoco/>", model_asset_hashes={"a.stl": wrong})
        missing = peer.ask(hello)
        assert missing.code == ErrorCode.ASSETS_MISSING and missing.missing_asset_hashes == [wrong]
        # The right bytes, in order: complete; sending it again costs one message.
        ask(_chunk(sha256, size, 0, content[:60_000], seq=10))
        done = ask(_chunk(sha256, size, 60_000, content[60_000:], seq=11))
        assert done.complete and done.received_bytes == size
        again = ask(_chunk(sha256, size, 0, content[:10], seq=12))
        assert again.complete and again.received_bytes == size
        # Bounds: one file, one client's unfinished uploads, the cache.
        assert_error(
            ask(_chunk("1" * 64, 300_001, 0, b"x", seq=13)),
            limit,
            "size_bytes",
            "--max-model-bytes",
        )
        for index in range(2):
            assert not ask(_chunk(f"{index + 2}" * 64, 250_000, 0, b"x", seq=14)).complete
        assert_error(
            ask(_chunk("4" * 64, 250_000, 0, b"x", seq=15)),
            limit,
            "size_bytes",
            "--max-upload-bytes-per-client",
        )
        with (
            Peer(server.endpoint, source="127.0.0.2") as other,
            Peer(server.endpoint, source="127.0.0.3") as third,
        ):
            # 102,400 cached + 750,000 reserved + 250,000: the cached file makes room.
            for sha in ("5" * 64, "6" * 64):
                assert other.ask(_chunk(sha, 250_000, 0, b"x")).received_bytes == 1
            full = third.ask(_chunk("7" * 64, 10, 0, b"x"))
            assert_error(full, limit, "size_bytes", "--asset-cache-bytes")
        reply = peer.ask(hello.model_copy(update={"model_asset_hashes": {"a.stl": sha256}}))
        assert reply.code == ErrorCode.ASSETS_MISSING  # evicted for the reservations


@pytest.mark.slow
def test_a_log_of_files_sent_by_hash_replays_on_a_server_that_never_saw_them(
    large_robot_scene, tmp_path
):
    """Client and server logs hold the hello with its files inline: self-contained."""
    server_logs = tmp_path / "server_logs"
    args = [
        "--workers",
        "1",
        "--max-message-bytes",
        str(MESSAGE_CAP_BYTES),
        "--record",
        str(server_logs),
    ]
    mesh = (large_robot_scene.parent / "assets" / "pelvis_detail.stl").read_bytes()
    with ServerProcess(extra_args=args) as recording_server:
        result = sim(
            large_robot_scene,
            recording_server.endpoint,
            tmp_path / "out",
            "--record",
            str(tmp_path / "client_logs"),
        )
        assert result.returncode == 0, result.stderr
    logs = [tmp_path / "client_logs" / "stand.mcap", *sorted(server_logs.glob("*.mcap"))]
    assert len(logs) == 2
    for log in logs:
        hellos = [m.message for m in read_log(log) if isinstance(m.message, Hello)]
        assert len(hellos) == 1 and hellos[0].model_asset_hashes is None
        assert hellos[0].model_assets["assets/pelvis_detail.stl"] == mesh
        assert not [m for m in read_log(log) if m.message.type in ("asset", "asset_received")]
    with ServerProcess(
        extra_args=["--workers", "1", "--max-message-bytes", str(MESSAGE_CAP_BYTES)]
    ) as fresh:
        for log in logs:
            replay = run_poise(["replay", str(log), "--connect", fresh.endpoint], cwd=tmp_path)
            assert replay.returncode == 0, replay.stdout + replay.stderr


def test_a_hello_by_hash_is_validated_before_its_files_are_looked_up(capped_server):
    payload = {
        "type": "hello",
        "version": PROTOCOL_VERSION,
        "seq": 3,
        "model_text": "<mujoco/>",
        "model_asset_hashes": {"mesh.stl": "../../etc/passwd"},
    }
    with Peer(capped_server.endpoint) as peer:
        reply = peer.ask(msgpack.packb(payload))
        assert reply.code == ErrorCode.INVALID_FIELD and reply.seq == 3, reply
        assert reply.field == "model_asset_hashes.mesh.stl"
        assert decode(encode(reply)) == reply


def test_the_cache_is_a_private_directory_removed_when_the_server_stops(monkeypatch, tmp_path):
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # the server's temporary directories go here
    content = b"solid mesh\n" * 1000
    sha256 = hashlib.sha256(content).hexdigest()
    with ServerProcess(extra_args=["--workers", "1"]) as server, Peer(server.endpoint) as peer:
        assert peer.ask(_chunk(sha256, len(content), 0, content)).complete
        (directory,) = tmp_path.glob("poise-assets-*")
        assert stat.S_IMODE(directory.stat().st_mode) == 0o700
        assert (directory / sha256).read_bytes() == content
    assert server.process.returncode == 0
    assert not list(tmp_path.glob("poise-assets-*"))
