"""How the broker starts: its CURVE authentication and its worker processes.

Raises :class:`ServerStartError` for what a user can fix (a key file, a directory).
"""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import zmq

from controller_server.config import SINGLE_THREADED_BLAS, ServeConfig
from controller_server.routing import WorkerRecord
from controller_server.worker import Channel

__all__ = ["ServerStartError", "enable_curve", "start_worker"]

log = logging.getLogger("poise.server")


class ServerStartError(RuntimeError):
    """The server could not start (bad key file, endpoint in use, worker failed)."""


def enable_curve(context: zmq.Context, frontend: zmq.Socket, config: ServeConfig) -> Any:
    """Make ``frontend`` a CURVE server with ``config``'s key; the authenticator it starts.

    Raises:
        ServerStartError: The key file is unreadable or holds no secret key, or
            ``--allow-client-keys`` is not a directory.
    """
    from zmq.auth.thread import ThreadAuthenticator

    path = config.curve_secret_key
    try:
        public, secret = zmq.auth.load_certificate(path)
    except (OSError, ValueError) as exc:
        raise ServerStartError(f"cannot read the server key {path!r}: {exc}") from None
    if not secret:
        raise ServerStartError(
            f"{path!r} holds no secret key: pass the `.key_secret` file of `poise keygen`"
        )
    allowed = config.allow_client_keys
    if allowed is not None and not os.path.isdir(allowed):
        raise ServerStartError(f"--allow-client-keys {allowed!r} is not a directory")
    authenticator = ThreadAuthenticator(context, log=log.getChild("auth"))
    authenticator.start()
    authenticator.configure_curve(
        domain="*", location=allowed if allowed is not None else zmq.auth.CURVE_ALLOW_ANY
    )
    frontend.curve_secretkey = secret
    frontend.curve_publickey = public
    frontend.curve_server = True
    return authenticator


def start_worker(identity: bytes, config: ServeConfig, assets_directory: Path) -> WorkerRecord:
    """Start a worker process (``python -m controller_server.worker``) joined by a socket pair.

    The worker's BLAS runs on one thread (the workers are the parallelism); it reads the
    assets the broker receives from ``assets_directory``.
    """
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "controller_server.worker",
                identity.decode(),
                str(theirs.fileno()),
                config.to_json(),
                str(assets_directory),
            ],
            env={**os.environ, **SINGLE_THREADED_BLAS},
            pass_fds=(theirs.fileno(),),
        )
    except BaseException:
        ours.close()
        raise
    finally:
        theirs.close()  # the worker holds it: when the worker exits, ours reads EOF
    return WorkerRecord(identity, process, Channel(ours, blocking=False))
