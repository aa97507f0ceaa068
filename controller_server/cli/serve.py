"""``poise serve`` (the broker and its workers) and ``poise keygen`` (CurveZMQ key pairs)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from controller_server.cli.common import DEFAULT_ENDPOINT, READY_PREFIX, check_endpoint_option

if TYPE_CHECKING:
    from controller_server.config import ServeConfig

__all__ = ["add_parsers", "serve_config"]


def serve_config(args: argparse.Namespace) -> ServeConfig:
    """The :class:`~controller_server.config.ServeConfig` of ``poise serve``'s options."""
    from controller_server.config import ServeConfig

    return ServeConfig(
        endpoints=tuple(args.bind or [DEFAULT_ENDPOINT]),
        workers=args.workers,
        session_timeout_s=args.session_timeout,
        deadline_s=args.deadline,
        hello_deadline_s=args.hello_deadline,
        recycle_after_s=args.recycle_after,
        max_sessions=args.max_sessions,
        max_sessions_per_client=args.max_sessions_per_client,
        max_workers_per_client=args.max_workers_per_client,
        max_in_flight=args.max_in_flight,
        max_message_bytes=args.max_message_bytes,
        stalled_message_timeout_s=args.stalled_message_timeout,
        max_model_bytes=args.max_model_bytes,
        asset_cache_bytes=args.asset_cache_bytes,
        max_upload_bytes_per_client=args.max_upload_bytes_per_client,
        model_cache_entries=args.model_cache,
        model_dirs=tuple(str(Path(d).resolve()) for d in args.model_dir or []),
        curve_secret_key=args.curve_secret_key,
        allow_client_keys=args.allow_client_keys,
        stats_all=args.stats_all,
        record_dir=str(Path(args.record).resolve()) if args.record else None,
        log_level=args.log_level,
    )


def _serve(args: argparse.Namespace) -> int:
    from controller_server.server import ControllerServer, ServerStartError

    check_endpoint_option("--bind", args.bind)
    try:
        config = serve_config(args)
        for directory in config.model_dirs:
            if not Path(directory).is_dir():
                raise ValueError(f"--model-dir {directory!r} is not a directory")
        if config.record_dir is not None:
            _make_record_dir(Path(config.record_dir))
        server = ControllerServer(config)
    except (ValueError, ServerStartError) as exc:
        print(f"poise serve: {exc}", file=sys.stderr)
        return 2

    def request_stop(signum: int, _frame: object) -> None:
        logging.getLogger("poise.server").info("signal %d: shutting down", signum)
        server.stop_event.set()

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    try:
        server.start_workers()
    except ServerStartError as exc:
        server.close()
        print(f"poise serve: {exc}", file=sys.stderr)
        return 2
    if server.stop_event.is_set():
        server.close()
        return 0
    if not config.curve_secret_key and not all(_is_loopback(e) for e in server.bound_endpoints):
        logging.getLogger("poise.server").warning(
            "serving without CURVE on a non-loopback endpoint: anyone who reaches it can "
            "drive the robot; see docs/serving.md"
        )
    print(f"{READY_PREFIX}{', '.join(server.bound_endpoints)}", flush=True)
    server.serve_forever()
    print("poise serve: stopped", flush=True)
    return 0


def _make_record_dir(directory: Path) -> None:
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--record {str(directory)!r}: {exc.strerror or exc}") from None
    if not os.access(directory, os.W_OK):
        raise ValueError(f"--record {str(directory)!r} is not writable")


def _is_loopback(endpoint: str) -> bool:
    if endpoint.startswith(("ipc://", "inproc://")):
        return True
    host = endpoint.split("://", 1)[-1].rsplit(":", 1)[0].strip("[]")
    return host in ("localhost", "::1") or host.startswith("127.")


def _keygen(args: argparse.Namespace) -> int:
    import zmq.auth

    directory = Path(args.directory)
    directory.mkdir(parents=True, exist_ok=True)
    public, secret = directory / f"{args.name}.key", directory / f"{args.name}.key_secret"
    if public.exists() or secret.exists():
        print(f"poise keygen: {public} or {secret} exists; choose another --name", file=sys.stderr)
        return 2
    old_umask = os.umask(0o077)  # the secret is never readable by others, not for an instant
    try:
        zmq.auth.create_certificates(str(directory), args.name)
    finally:
        os.umask(old_umask)
    public.chmod(0o644)  # the public half is for sharing
    print(f"public key: {public}\nsecret key: {secret}")
    return 0


def add_parsers(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``serve`` and ``keygen``."""
    serve = commands.add_parser(
        "serve",
        help="run the controller server",
        description="Serve whole-body controllers: one session per client, state in, command out.",
    )
    serve.add_argument(
        "--bind",
        action="append",
        metavar="ENDPOINT",
        help="ZeroMQ endpoint to bind, tcp:// or ipc://; repeat for several "
        f"(default: {DEFAULT_ENDPOINT}; port * picks a free one)",
    )
    serve.add_argument(
        "--session-timeout",
        type=float,
        default=30.0,
        metavar="SECONDS",
        help="drop a session after this long without a request (default: 30)",
    )
    serve.add_argument(
        "--workers",
        type=int,
        default=max(1, os.cpu_count() or 1),
        metavar="N",
        help="worker processes serving the sessions (default: one per core)",
    )
    serve.add_argument(
        "--deadline",
        type=float,
        default=0.5,
        metavar="SECONDS",
        help="answer a state, set_params or bye within this time of receipt, else with "
        "DEADLINE_EXCEEDED (default: 0.5)",
    )
    serve.add_argument(
        "--hello-deadline",
        type=float,
        default=10.0,
        metavar="SECONDS",
        help="the same for hello: model load and controller creation (default: 10)",
    )
    serve.add_argument(
        "--recycle-after",
        type=float,
        default=5.0,
        metavar="SECONDS",
        help="a worker still busy this long past a request's deadline is killed and replaced, "
        "losing its sessions (default: 5)",
    )
    serve.add_argument(
        "--max-sessions",
        type=int,
        default=128,
        metavar="N",
        help="sessions on the server (default: 128)",
    )
    serve.add_argument(
        "--max-sessions-per-client",
        type=int,
        default=32,
        metavar="N",
        help="sessions per client: per CURVE key, or per peer address (default: 32)",
    )
    serve.add_argument(
        "--max-workers-per-client",
        type=int,
        default=None,
        metavar="N",
        help="workers one client's sessions may occupy, so a client arriving later finds one "
        "no other client floods (default: all but one)",
    )
    serve.add_argument(
        "--max-in-flight",
        type=int,
        default=2,
        metavar="N",
        help="requests of one session being served at once; more are refused (default: 2)",
    )
    serve.add_argument(
        "--max-message-bytes",
        type=int,
        default=16 * 1024 * 1024,
        metavar="BYTES",
        help="largest request answered, at least 65536 (default: 16 MiB); a model's files "
        "of any size still arrive, uploaded in chunks of this size",
    )
    serve.add_argument(
        "--stalled-message-timeout",
        type=float,
        default=30.0,
        metavar="SECONDS",
        help="drop a connection that completes no message (nor heartbeat) this long after "
        "a heartbeat, freeing the part of a message it sent (default: 30; a client "
        "uploading one message more slowly than max-message-bytes per this long is dropped)",
    )
    serve.add_argument(
        "--max-model-bytes",
        type=int,
        default=4 * 1024 * 1024,
        metavar="BYTES",
        help="largest model text or model/clip file, and file sent with a model (default: 4 MiB)",
    )
    serve.add_argument(
        "--asset-cache-bytes",
        type=int,
        default=256 * 1024 * 1024,
        metavar="BYTES",
        help="bytes of files sent with models (meshes) the server keeps, by SHA-256, so a "
        "client uploads each once; least recently used out (default: 256 MiB, in a private "
        "temporary directory removed at exit)",
    )
    serve.add_argument(
        "--max-upload-bytes-per-client",
        type=int,
        default=64 * 1024 * 1024,
        metavar="BYTES",
        help="total size of one client's unfinished file uploads (default: 64 MiB)",
    )
    serve.add_argument(
        "--model-cache",
        type=int,
        default=16,
        metavar="N",
        help="parsed models each worker keeps (default: 16)",
    )
    serve.add_argument(
        "--model-dir",
        action="append",
        metavar="DIR",
        help="directory whose model and clip files clients may name; repeatable "
        "(default: built-in models and clips only)",
    )
    serve.add_argument(
        "--curve-secret-key",
        metavar="FILE",
        help="encrypt and authenticate with CurveZMQ using this server secret key "
        "(`poise keygen`); needed on anything but loopback",
    )
    serve.add_argument(
        "--allow-client-keys",
        metavar="DIR",
        help="with CURVE: only clients whose public key file is in DIR (default: any key)",
    )
    serve.add_argument(
        "--stats-all",
        action="store_true",
        help="stats lists every session (default: only the asking client's own)",
    )
    serve.add_argument(
        "--record",
        metavar="DIR",
        help="record every session's conversation to DIR/<UTC time>-<session id>.mcap "
        "(created if missing; `poise replay` replays a file)",
    )
    serve.set_defaults(handler=_serve)

    keygen = commands.add_parser(
        "keygen",
        help="make a CurveZMQ key pair for `poise serve --curve-secret-key` or a client",
        description="Write NAME.key (public, give it to the other side) and NAME.key_secret "
        "(secret, keep it) in DIRECTORY.",
    )
    keygen.add_argument("directory", metavar="DIRECTORY")
    keygen.add_argument("--name", default="server", help="file name stem (default: server)")
    keygen.set_defaults(handler=_keygen)
