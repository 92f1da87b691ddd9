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
        m = _ENDPOINT.match(endpoint)
        if m is None or m["proto"] not in ("tcp", "tls"):
            continue
        host, port = m["v6"] or m["host"], int(m["port"])
        try:
            sock = socket.create_connection((host, port), timeout=PROBE_TIMEOUT)
        except OSError:
            continue  # nothing listens there
        with sock:
            if m["proto"] == "tls":
                problem = _tls_problem(config, sock, host, endpoint)
                if problem:
                    return problem
        if user:
            return (
                f"login refused for user {user} at {endpoint} (wrong password or no such account)"
            )
        return (
            f"login refused at {endpoint}: the server requires an account "
            "(give --user and --password-file)"
        )
    return None


def _tls_problem(config: zenoh.Config, sock: socket.socket, host: str, endpoint: str) -> str | None:
    ca = _get(config, "transport/link/tls/root_ca_certificate")
    cert = _get(config, "transport/link/tls/connect_certificate")
    key = _get(config, "transport/link/tls/connect_private_key")
    try:
        ctx = ssl.create_default_context(cafile=ca) if ca else ssl.create_default_context()
        if cert and key:
            ctx.load_cert_chain(cert, key)
    except (OSError, ssl.SSLError) as e:
        return f"cannot use the TLS files for {endpoint}: {e}"
    try:
        with ctx.wrap_socket(sock, server_hostname=host) as tls:
            # TLS 1.3: a refused client certificate shows only on the first read
            tls.settimeout(0.3)
            try:
                tls.recv(1)
            except TimeoutError:
                pass
    except ssl.SSLCertVerificationError as e:
        fix = (
            "give --ca FILE, the CA that signed it"
            if not ca
            else f"is {ca} the CA that signed it? does the certificate name {host}?"
        )
        return (
            f"TLS: the server certificate at {endpoint} is not trusted ({e.verify_message}); {fix}"
        )
    except ssl.SSLError as e:
        reason = (e.reason or str(e)).replace("_", " ").lower()
        if "certificate required" in reason:
            return (
                f"TLS: the server at {endpoint} requires a client certificate (mutual TLS): "
                "give --cert FILE --key FILE"
            )
        return f"TLS handshake with {endpoint} failed: {reason}"
    except OSError:
        return None
    return None
