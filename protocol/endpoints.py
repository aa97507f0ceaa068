"""ZeroMQ endpoints as users type them: checked before ZeroMQ says "Invalid argument".

Servers bind and clients connect to ``tcp://HOST:PORT`` (``*`` for any free
port when binding) or ``ipc:///path``; ZeroMQ refuses anything else with
an ``EINVAL`` that names neither the mistake nor the fix.
"""

from __future__ import annotations

import re

from protocol.errors import PoiseError

__all__ = ["InvalidEndpoint", "check_endpoint"]

TRANSPORTS = ("tcp", "ipc", "inproc", "ws", "wss", "pgm", "epgm", "udp", "vmci")
"""Transports libzmq knows; Poise serves on ``tcp`` and ``ipc``."""

_HOST_PORT = re.compile(r"^(?P<host>\[[^\]]*\]|[^:/\s]*)(?::(?P<port>[^:/\s]*))?$")


class InvalidEndpoint(PoiseError, ValueError):
    """An endpoint ZeroMQ would refuse; the message says how to write it.

    Attributes:
        endpoint: What was given.
    """

    def __init__(self, endpoint: str, detail: str):
        self.endpoint = endpoint
        super().__init__(f"endpoint {endpoint!r}: {detail}")


def check_endpoint(endpoint: str) -> str:
    """Return ``endpoint`` if ZeroMQ can use it, else raise with the fix.

    Args:
        endpoint: E.g. ``tcp://127.0.0.1:5555``, ``tcp://*:*``, ``ipc:///tmp/poise``.

    Raises:
        InvalidEndpoint: No ``transport://`` prefix (``localhost:5555``), an
            unknown transport, or a TCP address without a port.
    """
    transport, separator, address = endpoint.partition("://")
    if not separator:
        match = _HOST_PORT.match(endpoint)
        if match and match["host"] and match["port"]:
            raise InvalidEndpoint(endpoint, f"write tcp://{endpoint} (ZeroMQ needs the transport)")
        raise InvalidEndpoint(endpoint, "write tcp://HOST:PORT, e.g. tcp://127.0.0.1:5555")
    if transport not in TRANSPORTS:
        raise InvalidEndpoint(
            endpoint, f"unknown transport {transport!r}; write tcp://HOST:PORT or ipc:///PATH"
        )
    if transport == "tcp":
        match = _HOST_PORT.match(address)
        if match is None or not match["host"] or not match["port"]:
            raise InvalidEndpoint(endpoint, "write tcp://HOST:PORT, e.g. tcp://127.0.0.1:5555")
        port = match["port"]
        if port != "*" and not (port.isdigit() and int(port) < 65536):
            raise InvalidEndpoint(endpoint, f"port {port!r} is not a number up to 65535 (or *)")
    elif not address:
        raise InvalidEndpoint(endpoint, f"give an address after {transport}://")
    return endpoint
