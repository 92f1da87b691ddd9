"""Loopback ports and endpoints."""

from __future__ import annotations

import socket

LOOPBACK = "127.0.0.1"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (the kernel picks it).

    Another process may still grab it before we listen on it; callers that
    start a router should retry with a new port on `ListenFailed`.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOOPBACK, 0))
        return int(sock.getsockname()[1])


def loopback_endpoint(port: int) -> str:
    """The Zenoh endpoint string for a TCP port on 127.0.0.1."""
    return f"tcp/{LOOPBACK}:{port}"
