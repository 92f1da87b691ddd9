"""Helper processes for the transport tests (started with subprocess, never forked).

    python zenoh_procs.py router ENDPOINT          router with test queryables
    python zenoh_procs.py token ENDPOINT KEY       client holding a liveliness token
    python zenoh_procs.py sub-and-close ENDPOINT   open, subscribe, close, exit

`router` and `token` print "ready" once set up and run until stdin closes.
`router` prints "listen-failed" and exits 3 when its port is taken.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from backend.transport import (  # noqa: E402
    ListenFailed,
    ReplyError,
    client_config,
    declare_token,
    router_config,
    serve,
    session_scope,
    subscribe,
)


def _refuse(payload: bytes) -> bytes:
    raise ReplyError(b"skill is not idle")


def _boom(payload: bytes) -> bytes:
    raise ValueError("kaboom")


def _slow(payload: bytes) -> bytes:
    time.sleep(0.5)  # deliberately slow responder
    return payload


def _ready() -> None:
    print("ready", flush=True)
    sys.stdin.read()  # until the test closes our stdin


def router(endpoint: str) -> int:
    try:
        with session_scope(router_config([endpoint])) as session:
            serve(session, "test/echo", lambda payload: b"echo:" + payload)
            serve(session, "test/refuse", _refuse)
            serve(session, "test/boom", _boom)
            serve(session, "test/slow", _slow)
            _ready()
    except ListenFailed:
        print("listen-failed", flush=True)
        return 3
    return 0


def token(endpoint: str, key: str) -> int:
    with session_scope(client_config([endpoint])) as session:
        token = declare_token(session, key)  # keep a reference: a dropped token is undeclared
        _ready()
        token.undeclare()
    return 0


def sub_and_close(endpoint: str) -> int:
    with session_scope(client_config([endpoint])) as session:
        subscribe(session, "test/**", lambda message: None)
    print("closed", flush=True)
    return 0


if __name__ == "__main__":
    command, *args = sys.argv[1:]
    sys.exit({"router": router, "token": token, "sub-and-close": sub_and_close}[command](*args))
