"""A client's CURVE keys (ZeroMQ's CurveZMQ): read from `poise keygen`'s files, checked.

A server run with a key accepts only clients that know its public key; a client proves
itself with a key pair of its own (docs/serving.md). :class:`CurveKeys` holds the three
keys (z85), read from their files (:meth:`CurveKeys.from_files`) with a typed, one-line
error (:class:`InvalidKeyFile`) for a file that is missing, unreadable or holds no usable
key.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import zmq
import zmq.auth
from zmq.utils import z85

from protocol.errors import PoiseError

__all__ = ["CURVE_KEY_LENGTH", "CurveKeys", "InvalidKeyFile"]

CURVE_KEY_LENGTH = 40
"""Length of a Z85-encoded CURVE key (32 bytes of key material)."""


class InvalidKeyFile(PoiseError, ValueError):
    """A CURVE key file is missing, unreadable or holds no usable key.

    Attributes:
        path: The key file.
        detail: What is wrong with it and what to do.
    """

    def __init__(self, path: str | os.PathLike[str], detail: str):
        self.path = Path(path)
        self.detail = detail
        super().__init__(f"CURVE key file {str(path)!r}: {detail}")


@dataclass(frozen=True)
class CurveKeys:
    """The keys of an encrypted, authenticated (ZeroMQ CURVE) connection.

    Keys are 40-byte Z85 strings, as made by :func:`zmq.curve_keypair` and
    stored by `poise keygen` (:func:`zmq.auth.create_certificates`).

    Attributes:
        server_public: The server's public key (the client checks it is
            talking to that server).
        client_public: This client's public key (the server's allow list
            holds it).
        client_secret: This client's secret key (never sent).

    Raises:
        ValueError: A key is not 40 Z85 characters, or the client's public
            key does not belong to its secret key.
    """

    server_public: bytes
    client_public: bytes
    client_secret: bytes = field(repr=False)

    def __post_init__(self) -> None:
        for name in ("server_public", "client_public", "client_secret"):
            problem = _key_problem(getattr(self, name))
            if problem:
                raise ValueError(f"{name}: {problem}")
        if zmq.curve_public(self.client_secret) != self.client_public:
            raise ValueError("client_public is not the public key of client_secret")

    @classmethod
    def from_files(
        cls,
        server_key: str | os.PathLike[str],
        client_key: str | os.PathLike[str] | None = None,
    ) -> CurveKeys:
        """Load keys from certificate files made by :func:`zmq.auth.create_certificates`.

        Args:
            server_key: The server's public certificate (``NAME.key``; a
                ``NAME.key_secret`` file works too, only its public key is read).
            client_key: This client's secret certificate (``NAME.key_secret``).
                ``None`` makes an ephemeral key pair: enough when the server
                accepts any client key (encryption without client
                authentication).

        Raises:
            InvalidKeyFile: A file is missing, unreadable, holds no valid
                public key, or (``client_key``) no matching secret key.
        """
        server_public, _ = _load_key_file(server_key)
        if client_key is None:
            client_public, client_secret = zmq.curve_keypair()
        else:
            client_public, secret = _load_key_file(client_key)
            if secret is None:
                raise InvalidKeyFile(
                    client_key,
                    "holds no secret key; give the client's `.key_secret` file, not `.key`",
                )
            problem = _key_problem(secret)
            if problem:
                raise InvalidKeyFile(client_key, f"secret key: {problem}")
            if zmq.curve_public(secret) != client_public:
                raise InvalidKeyFile(client_key, "the public key does not match the secret key")
            client_secret = secret
        return cls(server_public, client_public, client_secret)


def _key_problem(key: bytes) -> str:
    """Why ``key`` is not a Z85 CURVE key, or ``""`` if it is one."""
    if not isinstance(key, bytes) or len(key) != CURVE_KEY_LENGTH:
        length = len(key) if isinstance(key, bytes) else type(key).__name__
        return f"expected {CURVE_KEY_LENGTH} Z85 bytes, got {length}"
    try:
        z85.decode(key)
    except (KeyError, ValueError):
        return "not a Z85 string"
    return ""


def _load_key_file(path: str | os.PathLike[str]) -> tuple[bytes, bytes | None]:
    """Public and (if present) secret key of a certificate file."""
    if not os.path.exists(path):
        raise InvalidKeyFile(path, "no such file; make one with `poise keygen DIR`")
    if not os.path.isfile(path):
        raise InvalidKeyFile(path, "not a regular file; give the key file, not its directory")
    try:
        public, secret = zmq.auth.load_certificate(path)
    except OSError as exc:
        raise InvalidKeyFile(path, f"cannot read it ({exc.strerror or exc})") from exc
    except ValueError as exc:
        raise InvalidKeyFile(path, "no `public-key` line; is it a zmq.auth certificate?") from exc
    problem = _key_problem(public)
    if problem:
        raise InvalidKeyFile(path, f"public key: {problem}")
    return public, secret
