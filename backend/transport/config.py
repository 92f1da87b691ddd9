"""Builders for `zenoh.Config` objects of the mission server (router) and its clients.

Config paths are Zenoh's own, separated by "/" (``transport/link/tx/lease``);
"." is accepted as separator too when a key contains no "/".
Values are plain Python/JSON values; they are serialised with `json.dumps`
before `Config.insert_json5`, so strings need no extra quoting.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from os import PathLike
from typing import Any

import zenoh

from backend.transport.session import clean_zenoh_message

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def _key(path: str) -> str:
    return path if "/" in path else path.replace(".", "/")


def set_option(config: zenoh.Config, path: str, value: Any) -> None:
    """Set one config value; raises `ValueError` naming the path when Zenoh rejects it."""
    try:
        config.insert_json5(_key(path), json.dumps(value))
    except zenoh.ZError as exc:
        shown = "(hidden)" if "password" in path else repr(value)  # never echo a secret
        raise ValueError(
            f"invalid Zenoh config option {path!r} = {shown}: {clean_zenoh_message(str(exc))}"
        ) from exc


def apply_options(config: zenoh.Config, options: Mapping[str, Any] | None) -> zenoh.Config:
    """Merge a mapping of config path -> value into `config` (in order) and return it."""
    for path, value in (options or {}).items():
        set_option(config, path, value)
    return config


def _common(config: zenoh.Config) -> None:
    # Never discover or be discovered beyond the endpoints we were given.
    set_option(config, "scouting/multicast/enabled", False)
    set_option(config, "scouting/gossip/enabled", False)
    # Without this, opening a session waits ~500 ms for scouting replies.
    set_option(config, "scouting/delay", 0)


def router_config(
    listen: list[str],
    *,
    extra: Mapping[str, Any] | None = None,
    base: zenoh.Config | None = None,
) -> zenoh.Config:
    """Config of the mission server's router session: listens exactly on `listen`.

    `base` (e.g. from `zenoh.Config.from_file`) is modified in place when given.
    `extra` is merged last, so it can override anything set here.
    """
    if not listen:
        raise ValueError("a router needs at least one listen endpoint")
    config = base if base is not None else zenoh.Config()
    set_option(config, "mode", "router")
    set_option(config, "listen/endpoints", list(listen))
    set_option(config, "connect/endpoints", [])
    _common(config)
    # Zenoh batches messages while a link is busy and may hold one back up to
    # 1 ms for the next: an operation's reply, sent right after its event
    # batch, then reached its client ~1 ms late for 1-2 % of operations (the
    # round trip's p99 tail; `time_limit` 0 only halved it). Off, the server
    # sends each message at once, for ~20 % fewer operations per second at
    # full load. A --zenoh-config file can turn it back on.
    set_option(config, "transport/link/tx/queue/batching/enabled", False)
    # Needed by zenoh.ext AdvancedPublisher caches (late joiners).
    set_option(config, "timestamping/enabled", True)
    # Used on a link only when the other end asks for it too: a site relay's
    # (relay_config); a LAN client does not.
    set_option(config, "transport/unicast/compression/enabled", True)
    return apply_options(config, extra)


def relay_config(
    listen: list[str],
    connect: list[str],
    *,
    extra: Mapping[str, Any] | None = None,
    base: zenoh.Config | None = None,
) -> zenoh.Config:
    """Config of a site relay (`missionctl router`): a router listening exactly
    on `listen` for the site's robots and consoles, connected to the ground's
    router at `connect`.

    Zenoh's defaults for a router's connect endpoints are what a relay needs:
    opening does not wait for the ground, and a lost ground link is retried
    for ever (every 1 s, backing off to 4 s). For a narrow link: batching
    stays on (the site's small messages share frames), compression is on
    (the server's router accepts it: about a third off the JSON), and no
    timestamps are added (nobody at the ground reads them: ~25 bytes less
    per message).
    """
    if not listen:
        raise ValueError("a relay needs at least one listen endpoint (for the site)")
    if not connect:
        raise ValueError("a relay needs the ground's endpoint to connect to")
    config = base if base is not None else zenoh.Config()
    set_option(config, "mode", "router")
    set_option(config, "listen/endpoints", list(listen))
    set_option(config, "connect/endpoints", list(connect))
    _common(config)
    set_option(config, "transport/unicast/compression/enabled", True)
    set_option(config, "timestamping/enabled", False)
    return apply_options(config, extra)


def client_config(
    connect: list[str],
    *,
    lease_ms: int | None = None,
    wait_for_router: bool = False,
    extra: Mapping[str, Any] | None = None,
    base: zenoh.Config | None = None,
) -> zenoh.Config:
    """Config of a client session (console, robot, CLI) connecting to `connect`.

    By default opening fails at once when no router answers; with
    `wait_for_router` it blocks until one does. `lease_ms` bounds how long a hung
    (not killed) process stays visible to others (Zenoh default: 10 s).
    """
    if not connect:
        raise ValueError("a client needs at least one endpoint to connect to")
    config = base if base is not None else zenoh.Config()
    set_option(config, "mode", "client")
    set_option(config, "connect/endpoints", list(connect))
    set_option(config, "listen/endpoints", [])
    _common(config)
    if wait_for_router:
        set_option(config, "connect/timeout_ms", -1)
    if lease_ms is not None:
        set_option(config, "transport/link/tx/lease", int(lease_ms))
    return apply_options(config, extra)


def _flat_diff(default: Any, loaded: Any, prefix: str, out: dict[str, Any]) -> None:
    if isinstance(default, dict) and isinstance(loaded, dict):
        for key, value in loaded.items():
            _flat_diff(default.get(key), value, f"{prefix}/{key}" if prefix else key, out)
    elif default != loaded:
        out[prefix] = loaded


def load_config_file(path: str | PathLike[str]) -> dict[str, Any]:
    """Read a Zenoh JSON5 config file; return only the options it changes.

    The result maps config paths to values and can be passed as `extra=` to
    `router_config` / `client_config` (e.g. TLS or user/password settings).
    Zenoh itself parses and validates the file, so unknown keys and JSON5
    syntax errors raise `ValueError` with Zenoh's message.
    """
    try:
        loaded = zenoh.Config.from_file(str(path))
    except zenoh.ZError as exc:
        raise ValueError(
            f"cannot load Zenoh config {path}: {clean_zenoh_message(str(exc))}"
        ) from exc
    # str(Config) is the full config as JSON; diff against the defaults.
    out: dict[str, Any] = {}
    _flat_diff(json.loads(str(zenoh.Config())), json.loads(str(loaded)), "", out)
    return out
