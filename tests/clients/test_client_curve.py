"""CURVE encryption and authentication of the client, against an in-process CURVE server.

The server here is a scripted ROUTER with ``curve_server`` set and a
ZAP authenticator (:class:`zmq.auth.thread.ThreadAuthenticator`) that allows
the client public keys in one directory, as ``poise serve`` does.
"""

import contextlib
from collections.abc import Iterator
from pathlib import Path

import pytest
import zmq
import zmq.auth
from zmq.auth.thread import ThreadAuthenticator

from clients import ControllerClient, CurveKeys, InvalidKeyFile, ServerError, ServerTimeout
from protocol import ErrorCode, PoiseError
from protocol.messages import Error, Hello, Message
from tests.clients.test_client import ScriptedServer, fake_welcome

pytestmark = pytest.mark.skipif(not zmq.has("curve"), reason="libzmq without CURVE")


@pytest.fixture
def keys(tmp_path: Path) -> dict[str, Path]:
    """Certificates of the server, an allowed client (in ``allowed/``) and an intruder."""
    for directory in ("server", "allowed", "intruder"):
        (tmp_path / directory).mkdir()
    server_public, server_secret = zmq.auth.create_certificates(tmp_path / "server", "server")
    client_public, client_secret = zmq.auth.create_certificates(tmp_path / "allowed", "client")
    _, intruder_secret = zmq.auth.create_certificates(tmp_path / "intruder", "intruder")
    return {
        "server_public": Path(server_public),
        "server_secret": Path(server_secret),
        "client_public": Path(client_public),
        "client_secret": Path(client_secret),
        "intruder_secret": Path(intruder_secret),
        "allowed": tmp_path / "allowed",
    }


def answer(request: Message) -> Message:
    """A welcome for ``hello``, a recognizable error for anything else."""
    if isinstance(request, Hello):
        return fake_welcome("curve")
    return Error(code=ErrorCode.INVALID_PARAMS, field="params.damping", detail="scripted")


@contextlib.contextmanager
def scripted_curve_server(keys: dict[str, Path], location: str) -> Iterator[ScriptedServer]:
    """A CURVE server whose authenticator allows the client keys at ``location``
    (a directory, or ``zmq.auth.CURVE_ALLOW_ANY``)."""
    public, secret = zmq.auth.load_certificate(keys["server_secret"])

    def configure(socket: zmq.Socket) -> None:
        socket.curve_secretkey = secret
        socket.curve_publickey = public
        socket.curve_server = True

    context = zmq.Context()
    authenticator = ThreadAuthenticator(context)
    authenticator.start()
    try:
        authenticator.configure_curve(domain="*", location=location)
        with ScriptedServer(answer, context=context, configure=configure) as server:
            yield server
    finally:
        authenticator.stop()
        context.term()


@pytest.fixture
def curve_server(keys: dict[str, Path]) -> Iterator[ScriptedServer]:
    """A CURVE server that lets in only the client keys in ``allowed/``."""
    with scripted_curve_server(keys, str(keys["allowed"])) as server:
        yield server


def test_an_allowed_client_talks_over_curve(keys, curve_server):
    curve = CurveKeys.from_files(keys["server_public"], keys["client_secret"])
    assert curve.client_public == zmq.auth.load_certificate(keys["client_public"])[0]
    with ControllerClient(curve_server.endpoint, timeout_s=2.0, curve=curve) as client:
        assert client.connect("fake").session_id == "curve"
        with pytest.raises(ServerError) as info:
            client.set_params({"damping": 5.0})
        assert (info.value.code, info.value.detail) == (ErrorCode.INVALID_PARAMS, "scripted")
        assert client.reconnect().session_id == "curve"  # a fresh socket gets the keys too
    assert [r.type for r in curve_server.requests] == ["hello", "set_params", "hello", "bye"]


@pytest.mark.parametrize(
    ("server_key", "client_key"),
    [
        ("server_public", "intruder_secret"),  # a key the server does not allow
        ("server_public", None),  # an ephemeral key, unknown to the server
        ("client_public", "client_secret"),  # the wrong server key
    ],
)
def test_a_refused_handshake_times_out(keys, curve_server, server_key, client_key):
    curve = CurveKeys.from_files(keys[server_key], client_key and keys[client_key])
    with ControllerClient(curve_server.endpoint, timeout_s=0.5, curve=curve) as client:
        with pytest.raises(ServerTimeout) as info:
            client.connect("fake")
    message = str(info.value)
    assert "CURVE" in message and "\n" not in message
    assert curve_server.requests == []


def test_a_plain_client_gets_no_answer_from_a_curve_server(curve_server):
    with ControllerClient(curve_server.endpoint, timeout_s=0.5) as client:
        with pytest.raises(ServerTimeout):
            client.connect("fake")
    assert curve_server.requests == []


def test_an_ephemeral_key_is_enough_when_any_client_is_allowed(keys):
    with scripted_curve_server(keys, zmq.auth.CURVE_ALLOW_ANY) as server:
        curve = CurveKeys.from_files(keys["server_public"])
        with ControllerClient(server.endpoint, timeout_s=2.0, curve=curve) as client:
            assert client.connect("fake").session_id == "curve"


def test_ephemeral_keys_are_fresh_pairs(keys):
    first = CurveKeys.from_files(keys["server_public"])
    second = CurveKeys.from_files(keys["server_public"])
    assert first.client_public != second.client_public
    assert zmq.curve_public(first.client_secret) == first.client_public
    assert first.client_secret.decode() not in repr(first)


@pytest.mark.parametrize(
    ("write", "as_client", "expected"),
    [
        (None, False, "no such file"),
        ("directory", False, "not a regular file"),
        ("#   no keys here\n", False, "no `public-key` line"),
        ('curve\n    public-key = "short"\n', False, "public key: expected 40"),
        ("public", True, "holds no secret key"),
        ("mismatched", True, "does not match"),
    ],
)
def test_bad_key_files_name_the_file(keys, tmp_path, write, as_client, expected):
    path = tmp_path / "bad.key"
    if write == "directory":
        path.mkdir()
    elif write == "public":
        path = keys["client_public"]
    elif write == "mismatched":
        text = keys["client_secret"].read_text()
        other_public, _ = zmq.auth.load_certificate(keys["server_public"])
        client_public, _ = zmq.auth.load_certificate(keys["client_secret"])
        path.write_text(text.replace(client_public.decode(), other_public.decode()))
    elif write is not None:
        path.write_text(write)
    with pytest.raises(InvalidKeyFile) as info:
        if as_client:
            CurveKeys.from_files(keys["server_public"], path)
        else:
            CurveKeys.from_files(path, keys["client_secret"])
    message = str(info.value)
    assert str(path) in message and expected in message and "\n" not in message
    assert isinstance(info.value, PoiseError) and isinstance(info.value, ValueError)
    assert info.value.path == path


def test_keys_are_validated_at_construction():
    public, secret = zmq.curve_keypair()
    other_public, _ = zmq.curve_keypair()
    CurveKeys(server_public=other_public, client_public=public, client_secret=secret)
    with pytest.raises(ValueError, match="server_public: expected 40"):
        CurveKeys(server_public=b"short", client_public=public, client_secret=secret)
    with pytest.raises(ValueError, match="not a Z85"):
        CurveKeys(server_public=b"~" * 40, client_public=public, client_secret=secret)
    with pytest.raises(ValueError, match="not the public key"):
        CurveKeys(server_public=other_public, client_public=other_public, client_secret=secret)


def test_keygen_writes_the_secret_readable_by_its_owner_only_from_the_start(
    tmp_path, monkeypatch, capsys
):
    """Issue 32 (9): the secret was written with the umask's mode, then chmod-ed."""
    import os
    import stat

    from controller_server.cli import main

    modes = {}
    create = zmq.auth.create_certificates

    def create_and_look(directory, name):  # the files as they are the instant they exist
        paths = create(directory, name)
        modes.update({Path(p).suffix: stat.S_IMODE(os.stat(p).st_mode) for p in paths})
        return paths

    monkeypatch.setattr(zmq.auth, "create_certificates", create_and_look)
    old_umask = os.umask(0o022)  # a usual one: files readable by all
    try:
        assert main(["keygen", str(tmp_path), "--name", "robot"]) == 0
    finally:
        os.umask(old_umask)
    assert modes[".key_secret"] == 0o600
    assert stat.S_IMODE((tmp_path / "robot.key_secret").stat().st_mode) == 0o600
    assert stat.S_IMODE((tmp_path / "robot.key").stat().st_mode) == 0o644
    assert "secret key:" in capsys.readouterr().out
