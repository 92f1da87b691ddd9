"""What our routers take to listen, one reading for both: the mission server
and a site relay (`missionctl router`) — endpoints, a Zenoh config file,
TLS, accounts, and the link delay hint (docs/security.md, docs/deployment.md) —
and how both run until a signal."""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from backend.transport.login import add_delay_hint_argument


def add_listen_arguments(
    p: argparse.ArgumentParser, *, default_listen: str, delay_hint: bool = True
) -> None:
    """`delay_hint=False`: the caller adds --link-delay-hint itself (a relay, with its
    own login at the ground)."""
    p.add_argument(
        "--listen",
        metavar="ENDPOINT",
        action="append",
        help=f"Zenoh endpoint to listen on (default {default_listen}); repeatable",
    )
    p.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="JSON5 Zenoh config merged over ours (TLS, accounts, ACL)",
    )
    if delay_hint:
        add_delay_hint_argument(p)
    g = p.add_argument_group("security (docs/security.md)")
    g.add_argument(
        "--accounts",
        metavar="FILE",
        help="accounts file: require a user/password login and enforce each account's role "
        "with Zenoh access control",
    )
    g.add_argument(
        "--tls-cert", metavar="FILE", help="server certificate (PEM) for tls/ listen endpoints"
    )
    g.add_argument("--tls-key", metavar="FILE", help="private key of --tls-cert")
    g.add_argument(
        "--tls-ca",
        metavar="FILE",
        help="require client certificates signed by this CA (mutual TLS)",
    )


def config_file_options(args: argparse.Namespace) -> dict[str, Any]:
    """The options of --zenoh-config (a ValueError naming the file)."""
    from backend.transport import load_config_file

    if not args.zenoh_config:
        return {}
    try:
        return load_config_file(args.zenoh_config)
    except (OSError, ValueError) as e:
        raise ValueError(f"{args.zenoh_config}: {e}") from None


def tls_listen_options(args: argparse.Namespace) -> dict[str, Any]:
    """Zenoh options for --tls-cert/--tls-key/--tls-ca; checks they fit --listen."""
    if not _uses_tls(args):
        return {}
    for opt, path in (
        ("--tls-cert", args.tls_cert),
        ("--tls-key", args.tls_key),
        ("--tls-ca", args.tls_ca),
    ):
        if path and not Path(path).is_file():
            raise ValueError(f"{opt} {path}: no such file")
    out: dict[str, Any] = {
        "transport/link/tls/listen_certificate": str(Path(args.tls_cert).resolve()),
        "transport/link/tls/listen_private_key": str(Path(args.tls_key).resolve()),
    }
    if args.tls_ca:
        out["transport/link/tls/root_ca_certificate"] = str(Path(args.tls_ca).resolve())
        out["transport/link/tls/enable_mtls"] = True
    return out


def _uses_tls(args: argparse.Namespace) -> bool:
    """--listen and the --tls-* options ask for TLS (a ValueError when they
    do not go together)."""
    wanted = bool(args.tls_cert or args.tls_key or args.tls_ca)
    if wanted and not (args.tls_cert and args.tls_key):
        raise ValueError("--tls-cert and --tls-key go together")
    if wanted != _tls_listen(args):  # TLS options and a tls/ endpoint: both or neither
        raise ValueError(_NEEDS_TLS_ENDPOINT if wanted else _NEEDS_TLS_OPTIONS)
    return wanted


def _tls_listen(args: argparse.Namespace) -> bool:
    return any(e.startswith("tls/") for e in args.listen or [])


_NEEDS_TLS_OPTIONS = (
    "a tls/ endpoint needs --tls-cert FILE and --tls-key FILE (see missionctl certs)"
)
_NEEDS_TLS_ENDPOINT = (
    "--tls-cert/--tls-key/--tls-ca need a tls/ endpoint in --listen "
    "(e.g. --listen tls/0.0.0.0:7447)"
)


def log_to_stderr(verbose: bool) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(asctime)s %(levelname)s %(message)s",
    )


@asynccontextmanager
async def until_signalled(service: Any) -> AsyncIterator[asyncio.Event]:
    """Start `service`; the event is set by SIGINT, SIGTERM or SIGHUP; the
    service is stopped on the way out, whatever happened."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        loop.add_signal_handler(sig, stop.set)
    await service.start()
    try:
        yield stop
    finally:
        await service.stop()
