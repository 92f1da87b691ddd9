"""Opening and closing Zenoh sessions with clear errors."""

from __future__ import annotations

import json
import logging
import re
import time
from collections.abc import Iterator
from contextlib import contextmanager

import zenoh

log = logging.getLogger(__name__)

_UNREACHABLE_DETAIL = (
    "no router accepted the connection (is it running? are the address, TLS settings "
    "and credentials right?)"
)


_SILENT_DETAIL = (
    "something accepted the connection but did not answer within {s:g} s (a stopped or "
    "overloaded server? a firewall dropping the connection?)"
)


class TransportError(Exception):
    """Base of every error raised by backend.transport."""


class TransportUnreachable(TransportError, ConnectionError):
    """No router could be reached at any of the configured endpoints."""

    def __init__(self, endpoints: list[str], detail: str, *, what: str = "the mission server"):
        self.endpoints = list(endpoints)
        self.detail = detail
        where = ", ".join(self.endpoints) or "(no endpoint configured)"
        super().__init__(f"cannot reach {what} at {where}: {detail}")


class LoginRefused(TransportUnreachable):
    """The router is there but refused us: credentials or TLS (see `probe.diagnose`)."""

    def __init__(self, endpoints: list[str], message: str):
        self.endpoints = list(endpoints)
        self.detail = message
        ConnectionError.__init__(self, message)


class ListenFailed(TransportError):
    """A router could not listen on one of its endpoints (e.g. address in use)."""

    def __init__(self, endpoints: list[str], detail: str):
        self.endpoints = list(endpoints)
        self.detail = detail
        super().__init__(f"cannot listen on {', '.join(self.endpoints)}: {detail}")


def clean_zenoh_message(text: str) -> str:
    """Drop the Rust source locations (" at /root/.cargo/...rs:61.") from a ZError text."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?", "", text).strip()


def _endpoints(config: zenoh.Config, section: str) -> list[str]:
    try:
        value = json.loads(config.get_json(f"{section}/endpoints"))
    except (zenoh.ZError, ValueError):
        return []
    # a list, or the per-mode form: {"router": [...], "client": [...]}
    lists = value.values() if isinstance(value, dict) else [value]
    return [str(e) for eps in lists for e in (eps or [])]


def open_session(config: zenoh.Config, *, what: str = "the mission server") -> zenoh.Session:
    """`zenoh.open` with our exceptions; the caller must close the session.

    Raises `TransportUnreachable` (router down, wrong address, rejected
    credentials all look the same to Zenoh), `ListenFailed`, or `TransportError`.
    """
    started = time.monotonic()
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        raw = str(exc)
        if "Unable to connect" in raw:
            from backend.transport.probe import diagnose

            waited = time.monotonic() - started
            if waited >= _open_timeout_s(config) / 2:
                # a refused login or TLS handshake fails at once; a hung
                # (SIGSTOPped, overloaded) router still accepts TCP, then is silent
                detail = _SILENT_DETAIL.format(s=round(waited))
                raise TransportUnreachable(
                    _endpoints(config, "connect"), detail, what=what
                ) from exc
            refusal = diagnose(config, _endpoints(config, "connect"))
            if refusal is not None:
                raise LoginRefused(_endpoints(config, "connect"), refusal) from exc
            raise TransportUnreachable(
                _endpoints(config, "connect"), _UNREACHABLE_DETAIL, what=what
            ) from exc
        if "listener" in raw:
            raise ListenFailed(_endpoints(config, "listen"), clean_zenoh_message(raw)) from exc
        raise TransportError(f"cannot open a Zenoh session: {clean_zenoh_message(raw)}") from exc


def _open_timeout_s(config: zenoh.Config) -> float:
    try:
        return float(json.loads(config.get_json("transport/unicast/open_timeout"))) / 1000
    except (zenoh.ZError, ValueError, TypeError):
        return 10.0  # Zenoh's default


def close_session(session: zenoh.Session) -> None:
    """Close a session (idempotent). Must be called explicitly: a process whose
    session still has callback subscribers open at interpreter exit never ends.

    Never asks `session.is_closed()` first: it waits for the session's lock
    holding the GIL, while a liveliness query ending on Zenoh's thread runs its
    done callback under that lock and waits for the GIL (a deadlock seen in a
    robot refused at start). `close()` releases the GIL and may be repeated."""
    try:
        session.close()
    except zenoh.ZError:
        log.exception("error while closing the Zenoh session")


@contextmanager
def session_scope(
    config: zenoh.Config, *, what: str = "the mission server"
) -> Iterator[zenoh.Session]:
    """`with session_scope(cfg) as session:` — opened with `open_session`, always closed."""
    session = open_session(config, what=what)
    try:
        yield session
    finally:
        close_session(session)
