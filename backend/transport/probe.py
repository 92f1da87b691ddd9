"""Why did a router refuse us? Zenoh says only "Unable to connect" whether the
router is down, the TLS handshake failed or the login was refused. A plain
TCP connection (and, for tls/ endpoints, a TLS handshake with the same CA and
client certificate) tells them apart: a port that accepts and a handshake that
succeeds leave the login as the cause.
"""

from __future__ import annotations

import json
import re
import socket
import ssl
from typing import Any

import zenoh

_ENDPOINT = re.compile(r"^(?P<proto>[a-z]+)/(?:\[(?P<v6>[^\]]+)\]|(?P<host>[^:/]+)):(?P<port>\d+)")
PROBE_TIMEOUT = 1.0


def _get(config: zenoh.Config, path: str) -> Any:
    try:
        return json.loads(config.get_json(path))
    except (zenoh.ZError, ValueError):
        return None


def diagnose(config: zenoh.Config, endpoints: list[str]) -> str | None:
    """A sentence when a router answered at one of `endpoints` but refused us
    (TLS or login); None when nothing answers (the router is unreachable)."""
    user = _get(config, "transport/auth/usrpwd/user")
    for endpoint in endpoints:
        refusal = _refusal(config, endpoint, user)
        if refusal is not None:
            return refusal
    return None


def _refusal(config: zenoh.Config, endpoint: str, user: Any) -> str | None:
    """Why the router at `endpoint` refused us (None: nothing listens there)."""
    address = _address(endpoint)
    if address is None:
        return None
    proto, host, port = address
    try:
        sock = socket.create_connection((host, port), timeout=PROBE_TIMEOUT)
    except OSError:
        return None  # nothing listens there
    with sock:
        problem = _tls_problem(config, sock, host, endpoint) if proto == "tls" else None
    return problem or _login_refused(endpoint, user)


def _address(endpoint: str) -> tuple[str, str, int] | None:
    """(protocol, host, port) of a tcp/ or tls/ endpoint (None: another kind)."""
    m = _ENDPOINT.match(endpoint)
    if m is None or m["proto"] not in ("tcp", "tls"):
        return None
    return m["proto"], m["v6"] or m["host"], int(m["port"])


def _login_refused(endpoint: str, user: Any) -> str:
    if user:
        return f"login refused for user {user} at {endpoint} (wrong password or no such account)"
    return (
        f"login refused at {endpoint}: the server requires an account "
        "(give --user and --password-file)"
    )


def _tls_problem(config: zenoh.Config, sock: socket.socket, host: str, endpoint: str) -> str | None:
    ca = _get(config, "transport/link/tls/root_ca_certificate")
    try:
        ctx = _tls_context(config, ca)
    except (OSError, ssl.SSLError) as e:
        return f"cannot use the TLS files for {endpoint}: {e}"
    try:
        _handshake(ctx, sock, host)
    except ssl.SSLCertVerificationError as e:
        return _untrusted(e, ca, host, endpoint)
    except ssl.SSLError as e:
        return _handshake_failed(e, endpoint)
    except OSError:
        return None
    return None


def _tls_context(config: zenoh.Config, ca: Any) -> ssl.SSLContext:
    """A client's TLS context with the session's CA and client certificate."""
    cert = _get(config, "transport/link/tls/connect_certificate")
    key = _get(config, "transport/link/tls/connect_private_key")
    ctx = ssl.create_default_context(cafile=ca) if ca else ssl.create_default_context()
    if cert and key:
        ctx.load_cert_chain(cert, key)
    return ctx


def _handshake(ctx: ssl.SSLContext, sock: socket.socket, host: str) -> None:
    with ctx.wrap_socket(sock, server_hostname=host) as tls:
        # TLS 1.3: a refused client certificate shows only on the first read
        tls.settimeout(0.3)
        try:
            tls.recv(1)
        except TimeoutError:
            pass


def _untrusted(e: ssl.SSLCertVerificationError, ca: Any, host: str, endpoint: str) -> str:
    """The server's certificate is not trusted: which CA to give, or to check."""
    fix = (
        "give --ca FILE, the CA that signed it"
        if not ca
        else f"is {ca} the CA that signed it? does the certificate name {host}?"
    )
    return f"TLS: the server certificate at {endpoint} is not trusted ({e.verify_message}); {fix}"


def _handshake_failed(e: ssl.SSLError, endpoint: str) -> str:
    """The handshake failed: for want of a client certificate, or why."""
    reason = (e.reason or str(e)).replace("_", " ").lower()
    if "certificate required" in reason:
        return (
            f"TLS: the server at {endpoint} requires a client certificate (mutual TLS): "
            "give --cert FILE --key FILE"
        )
    return f"TLS handshake with {endpoint} failed: {reason}"
