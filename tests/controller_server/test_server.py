"""A worker's request handling, without sockets: every bad input gets a typed error."""

import hashlib
import stat
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clients.physics.model_file import hello_model
from controller_server.asset_cache import AssetCache, read_asset
from controller_server.session_table import SessionTable
from protocol import ErrorCode, ProtocolError, decode, encode
from protocol.messages import (
    Asset,
    Bye,
    Command,
    Error,
    Hello,
    Params,
    SetParams,
    Stats,
    Welcome,
)
from protocol.recording import read_log
from tests.helpers import random_state

ALICE, BOB = b"alice", b"bob"


@pytest.fixture
def server():
    return SessionTable()


def ask(server, identity, message):
    """Send through the codec both ways, as the socket loop does."""
    payload = message if isinstance(message, bytes) else encode(message)
    return decode(encode(server.handle(identity, payload)))


def hello(server, identity=ALICE, **fields):
    fields.setdefault("model", "thesis_humanoid")
    reply = ask(server, identity, Hello(seq=1, **fields))
    assert isinstance(reply, Welcome), reply
    return reply


def assert_error(reply, code, field=None, seq=None):
    assert isinstance(reply, Error), reply
    assert reply.code == code, reply
    if field is not None:
        assert reply.field == field, reply
    if seq is not None:
        assert reply.seq == seq
    assert reply.detail


def test_state_before_hello_is_no_session(server):
    welcome_like = hello(server, BOB)
    state = random_state(welcome_like, np.random.default_rng(0)).model_copy(update={"seq": 9})
    assert_error(ask(server, ALICE, state), ErrorCode.NO_SESSION, seq=9)


@pytest.mark.parametrize(
    ("fields", "code", "field"),
    [
        ({"model": "no_such_robot"}, ErrorCode.MODEL_NOT_FOUND, "model"),
        ({"model": "/etc/hostname"}, ErrorCode.MODEL_NOT_FOUND, "model"),
        ({"model": None, "model_text": "<mujoco><worldbody>"}, ErrorCode.MODEL_INVALID, "model"),
        ({"controller": "magic"}, ErrorCode.UNKNOWN_CONTROLLER, "controller"),
        ({"expected_model_hash": "0" * 64}, ErrorCode.MODEL_MISMATCH, "expected_model_hash"),
        ({"params": {"stiffness": -1.0}}, ErrorCode.INVALID_PARAMS, "params.stiffness"),
        ({"params": {"warp": 9.0}}, ErrorCode.INVALID_PARAMS, "params.warp"),
    ],
)
def test_bad_hello_is_refused_with_the_field(server, fields, code, field):
    fields = {"model": "thesis_humanoid", **fields}
    assert_error(ask(server, ALICE, Hello(seq=4, **fields)), code, field, seq=4)
    assert ALICE not in server.sessions


def test_matching_model_hash_is_accepted(server):
    first = hello(server, BOB)
    second = hello(server, ALICE, expected_model_hash=first.model_hash)
    assert second.model_hash == first.model_hash


def _payload(state, **changes):
    payload = msgpack.unpackb(encode(state))
    payload.update(changes)
    return msgpack.packb(payload)


def test_state_sizes_are_checked_against_the_robot(server):
    welcome = hello(server)
    state = random_state(welcome, np.random.default_rng(1))
    nq = state.joint_position.size
    cases = [
        (_payload(state, joint_position=np.zeros(nq - 1).tobytes()), "joint_position"),
        (_payload(state, joint_velocity=np.zeros(3).tobytes()), "joint_velocity"),
        (_payload(state, contact_flags=[True]), "contact_flags"),
    ]
    for payload, field in cases:
        assert_error(ask(server, ALICE, payload), ErrorCode.BAD_SHAPE, field)
    assert_error(
        ask(server, ALICE, _payload(state, orientation_base_in_world_xyzw=np.zeros(4).tobytes())),
        ErrorCode.INVALID_FIELD,
        "orientation_base_in_world_xyzw",
    )
    zero_ball = state.joint_position.copy()
    zero_ball[:4] = 0.0  # first joint of the thesis humanoid is a ball joint
    assert_error(
        ask(server, ALICE, _payload(state, joint_position=zero_ball.tobytes())),
        ErrorCode.INVALID_FIELD,
        "joint_position",
    )
    nan = state.joint_velocity.copy()
    nan[2] = np.nan
    assert_error(
        ask(server, ALICE, _payload(state, joint_velocity=nan.tobytes())), ErrorCode.NON_FINITE
    )
    # The session survives all of that.
    assert isinstance(ask(server, ALICE, state), Command)
    assert server.sessions[ALICE].errors == 6


def test_set_params_is_atomic_and_validated(server):
    welcome = hello(server)
    reply = ask(server, ALICE, SetParams(seq=2, params={"stiffness": 50.0, "damping": 10.0}))
    assert isinstance(reply, Params)
    assert reply.params["stiffness"] == 50.0
    bad = SetParams(seq=3, params={"stiffness": 70.0, "damping": float("nan")})
    assert_error(ask(server, ALICE, bad), ErrorCode.INVALID_PARAMS, "params.damping")
    assert server.sessions[ALICE].controller.parameters()["stiffness"] == 50.0
    wrong_length = SetParams(seq=4, params={"reference_joint_position": [0.0]})
    assert_error(ask(server, ALICE, wrong_length), ErrorCode.INVALID_PARAMS)
    assert_error(
        ask(server, ALICE, SetParams(seq=5, params={"qp_solver": "cplex"})),
        ErrorCode.INVALID_PARAMS,
    )
    assert welcome.params["qp_solver"] == "quadprog"


def test_replies_sent_as_requests_are_refused(server):
    welcome = hello(server)
    assert_error(ask(server, ALICE, welcome), ErrorCode.UNEXPECTED_MESSAGE, "type")
    assert_error(ask(server, ALICE, Stats(seq=1, sessions=[])), ErrorCode.UNEXPECTED_MESSAGE)


def test_stats_bye_and_expiry(server):
    welcome = hello(server)
    hello(server, BOB, model="dino_biped")
    ask(server, ALICE, random_state(welcome, np.random.default_rng(2)))
    stats = ask(server, ALICE, Stats(seq=3))
    ticks = {s.model_name: s.ticks for s in stats.sessions}
    assert ticks == {"thesis_humanoid": 1, "dino_biped": 0}
    assert isinstance(ask(server, BOB, Bye(seq=4)), Bye)
    assert_error(ask(server, BOB, Bye(seq=5)), ErrorCode.NO_SESSION)
    assert server.drop([BOB, ALICE]) == 1
    assert_error(
        ask(server, ALICE, random_state(welcome, np.random.default_rng(2))), ErrorCode.NO_SESSION
    )


def test_controller_failure_is_internal_error_and_session_survives(server, monkeypatch):
    welcome = hello(server)
    session = server.sessions[ALICE]
    original = session.controller.compute
    calls = []

    def failing_once(control_input):
        calls.append(1)
        if len(calls) == 1:
            raise FloatingPointError("boom")
        return original(control_input)

    monkeypatch.setattr(session.controller, "compute", failing_once)
    state = random_state(welcome, np.random.default_rng(4))
    assert_error(ask(server, ALICE, state), ErrorCode.INTERNAL)
    assert isinstance(ask(server, ALICE, state), Command)


@pytest.mark.parametrize("field", ["joint_torque", "joint_acceleration", "contact_force_in_world"])
def test_non_finite_controller_output_never_leaves_the_server(server, monkeypatch, field):
    """A NaN the controller produces is an INTERNAL error naming the field, not a command."""
    welcome = hello(server)
    controller = server.sessions[ALICE].controller
    original = controller.compute

    def poisoned(control_input):
        output = original(control_input)
        array = {
            "joint_torque": output.joint_torque,
            "joint_acceleration": output.acceleration[6:],
            "contact_force_in_world": output.contact_force_in_world.reshape(-1),
        }[field]
        array[len(array) // 2] = np.nan
        return output

    monkeypatch.setattr(controller, "compute", poisoned)
    state = random_state(welcome, np.random.default_rng(5))
    assert_error(ask(server, ALICE, state), ErrorCode.INTERNAL, field=field, seq=state.seq)


@pytest.mark.parametrize("controller", ["momentum", "prioritized"])
def test_diagnostics_come_every_nth_tick_and_change_no_command(server, controller):
    """`diagnostics_period_ticks = 3`: ticks 0, 3, 6 carry diagnostics, the rest none, and the
    commands are those of a session that sends them every tick (same states, same order)."""
    rng = np.random.default_rng(5)
    params = {"optimizer_period_ticks": 2} if controller == "momentum" else {}
    welcome = hello(server, ALICE, controller=controller, params=params, diagnostics_period_ticks=3)
    hello(server, BOB, controller=controller, params=params)
    states = [random_state(welcome, rng).model_copy(update={"seq": 2 + t}) for t in range(7)]
    for tick, state in enumerate(states):
        sparse, full = ask(server, ALICE, state), ask(server, BOB, state)
        assert isinstance(sparse, Command) and isinstance(full, Command)
        assert (sparse.diagnostics is not None) == (tick % 3 == 0), tick
        assert full.diagnostics is not None
        np.testing.assert_array_equal(sparse.joint_torque, full.joint_torque)
        np.testing.assert_array_equal(sparse.joint_acceleration, full.joint_acceleration)
        np.testing.assert_array_equal(sparse.contact_wrench_in_world, full.contact_wrench_in_world)


def test_quaternions_are_normalised_and_far_off_ones_refused(server):
    """Issue 11, defect 2: the normalised copy was discarded, so a quaternion scaled ×1.1
    changed torques by up to 51 N·m and ×2 gave INTERNAL."""
    welcome = hello(server, controller="momentum")
    hello(server, BOB, controller="momentum")
    state = random_state(welcome, np.random.default_rng(8))
    reference = ask(server, ALICE, state)
    scaled_ball = state.joint_position.copy()
    scaled_ball[:4] *= 1.05  # first joint of the thesis humanoid is a ball joint
    scaled = state.model_copy(
        update={
            "orientation_base_in_world_xyzw": state.orientation_base_in_world_xyzw * 0.95,
            "joint_position": scaled_ball,
        }
    )
    command = ask(server, BOB, scaled)  # a fresh session: same controller history
    assert isinstance(reference, Command) and isinstance(command, Command)
    np.testing.assert_allclose(command.joint_torque, reference.joint_torque, atol=1e-8)
    for factor, field in [(2.0, "orientation_base_in_world_xyzw"), (13.9, "joint_position")]:
        if field == "joint_position":
            values = state.joint_position.copy()
            values[:4] *= factor
        else:
            values = state.orientation_base_in_world_xyzw * factor
        reply = ask(server, ALICE, state.model_copy(update={field: values}))
        assert_error(reply, ErrorCode.INVALID_FIELD, field)
        assert "unit quaternion" in reply.detail


@pytest.mark.parametrize("controller", ["momentum", "prioritized"])
def test_real_ticks_read_by_the_fast_path_as_pydantic_reads_them(server, controller):
    """The codec's fast path (protocol.fastpath) on real ticks: same messages as pydantic's."""
    from protocol.fastpath import reader
    from tests.protocol.test_fastpath import assert_same

    welcome = hello(server, ALICE, controller=controller)
    state = random_state(welcome, np.random.default_rng(6)).model_copy(update={"seq": 3})
    state_payload = msgpack.unpackb(encode(state))
    assert_same(reader(type(state))(state_payload), type(state).model_validate(state_payload))
    command = server.handle(ALICE, encode(state))
    assert isinstance(command, Command) and command.diagnostics is not None
    payload = msgpack.unpackb(encode(command))
    assert_same(reader(Command)(payload), Command.model_validate(payload))


# ----------------------------------------------------------------- files by hash (issue 31)


def _upload(cache, data, client="10.0.0.1", identity=b"peer"):
    """One whole file in one chunk; the cache's reply."""
    sha256 = hashlib.sha256(data).hexdigest()
    return cache.receive(identity, client, Asset(sha256=sha256, size_bytes=len(data), data=data))


def _bytes_on_disk(directory: Path) -> int:
    return sum(path.stat().st_size for path in directory.rglob("*") if path.is_file())


def test_the_asset_cache_stays_within_its_bytes_least_recently_used_out():
    cache = AssetCache(
        10_000, max_file_bytes=4000, max_upload_bytes_per_client=8000, idle_timeout_s=30.0
    )
    directory = cache.directory
    try:
        assert stat.S_IMODE(directory.stat().st_mode) == 0o700
        files = [bytes([index]) * 3000 for index in range(10)]
        hashes = [hashlib.sha256(data).hexdigest() for data in files]
        for index, data in enumerate(files):
            assert _upload(cache, data).complete
            if index == 2:  # f0 used again: f1 is now the least recently used
                assert cache.missing("10.0.0.1", [hashes[0]]) == []
            assert cache.used_bytes <= 10_000
            assert _bytes_on_disk(directory) <= 10_000
        assert cache.missing("10.0.0.1", hashes) == sorted(hashes[:7])
        assert read_asset(directory, hashes[9]) == files[9]
        # An upload in progress holds its declared size; idle, it is dropped.
        sha256 = hashlib.sha256(b"y" * 4000).hexdigest()
        reply = cache.receive(b"peer", "10.0.0.1", Asset(sha256=sha256, size_bytes=4000, data=b"y"))
        assert reply.received_bytes == 1 and not reply.complete
        assert cache.used_bytes <= 10_000 and cache.missing("10.0.0.1", hashes[7:]) == [hashes[7]]
        assert cache.expire(time.monotonic() + 31.0) == 1
        assert not list((directory / "partial").iterdir())
        # Another client has uploaded nothing: it sees nothing, and its upload is stored once.
        assert cache.missing("10.0.0.2", [hashes[9]]) == [hashes[9]]
        assert _upload(cache, files[9], client="10.0.0.2").complete
        assert cache.missing("10.0.0.2", [hashes[9]]) == []
        assert _bytes_on_disk(directory) == 2 * 3000
    finally:
        cache.close()
    assert not directory.exists()


def test_a_hello_by_hash_reads_the_cache_and_is_recorded_with_its_files_inline(tmp_path):
    fields = hello_model(
        str(Path(__file__).parents[1] / "models" / "vendor_humanoid" / "scene.xml")
    )
    files = fields.pop("model_assets")
    hashes = {path: hashlib.sha256(data).hexdigest() for path, data in files.items()}
    hello = Hello(seq=3, controller="tracking", model_asset_hashes=hashes, **fields)
    cache = AssetCache(
        10**6, max_file_bytes=10**6, max_upload_bytes_per_client=10**6, idle_timeout_s=30.0
    )
    try:
        for table in (SessionTable(), SessionTable(asset_dir=cache.directory)):
            reply = ask(table, ALICE, hello)
            assert_error(reply, ErrorCode.ASSETS_MISSING, "model_asset_hashes", seq=3)
            assert reply.missing_asset_hashes == sorted(set(hashes.values()))
            assert reply.max_message_bytes == table.max_message_bytes
        for data in files.values():
            assert _upload(cache, data).complete
        table = SessionTable(asset_dir=cache.directory, record_dir=tmp_path)
        assert isinstance(ask(table, ALICE, hello), Welcome)
        table.close()
        (log,) = tmp_path.glob("*.mcap")
        (logged,) = [m.message for m in read_log(log) if isinstance(m.message, Hello)]
        assert logged.model_assets == files and logged.model_asset_hashes is None
        # A file damaged on disk is missing, not wrong.
        mesh = cache.directory / hashes["assets/foot.stl"]
        mesh.write_bytes(b"\0" + mesh.read_bytes()[1:])
        reply = ask(table, BOB, hello)
        assert_error(reply, ErrorCode.ASSETS_MISSING, "model_asset_hashes")
        assert reply.missing_asset_hashes == [hashes["assets/foot.stl"]]
    finally:
        cache.close()


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["10.0.0.1", "10.0.0.2"]),
            st.binary(max_size=5000),
            st.integers(1, 3),
            st.booleans(),
        ),
        max_size=12,
    )
)
def test_the_asset_cache_keeps_its_bounds_whatever_is_uploaded(uploads):
    """Uploads in 1–3 chunks, some left unfinished, from two clients: within the bounds,
    every file a client may name is there with its content, every refusal a typed error."""
    cache = AssetCache(
        8000, max_file_bytes=4000, max_upload_bytes_per_client=6000, idle_timeout_s=30.0
    )
    stored: dict[str, bytes] = {}
    try:
        for index, (client, data, chunks, finish) in enumerate(uploads):
            sha256 = hashlib.sha256(data).hexdigest()
            step = max(1, -(-len(data) // chunks))
            offsets = list(range(0, len(data), step)) or [0]
            for offset in offsets if finish else offsets[:1]:
                chunk = Asset(
                    sha256=sha256,
                    size_bytes=len(data),
                    offset_bytes=offset,
                    data=data[offset : offset + step],
                )
                try:
                    reply = cache.receive(bytes([index]), client, chunk)
                except ProtocolError as exc:
                    assert exc.code == ErrorCode.LIMIT_EXCEEDED and exc.field == "size_bytes"
                    assert (
                        len(data) > 4000
                        or "--asset-cache-bytes" in exc.detail
                        or ("--max-upload-bytes-per-client" in exc.detail)
                    )
                    break
                if reply.complete:
                    stored[sha256] = data
                    break
            assert cache.used_bytes <= 8000
            assert _bytes_on_disk(cache.directory) <= 8000
        for client in ("10.0.0.1", "10.0.0.2"):
            for sha256 in set(stored) - set(cache.missing(client, stored)):
                assert read_asset(cache.directory, sha256) == stored[sha256]
    finally:
        cache.close()
