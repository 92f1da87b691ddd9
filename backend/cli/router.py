"""`missionctl router`: a site relay (backend/server/relay.py) until interrupted.

    missionctl router --connect tls/ground:7447 --ca pki/ca.pem \\
        --user lander --password-file secrets/lander.pw --link-delay-hint 6s

The site's robots and consoles connect to --listen; the relay connects to the
ground's server at --connect and keeps serving the site while the ground is
unreachable. docs/deployment.md walks through a deployment.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from typing import Any

from backend.cli.listening import (
    add_listen_arguments,
    config_file_options,
    log_to_stderr,
    tls_listen_options,
    until_signalled,
)
from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK, EXIT_UNREACHABLE
from backend.transport.login import add_login_arguments

DEFAULT_LISTEN = "tcp/127.0.0.1:7448"  # beside a server on one machine (7447)
DEFAULT_CONNECT = "tcp/127.0.0.1:7447"


def prepare_parser(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "router",
        help="run a site relay: the site's robots and consoles connect to it, it connects "
        "to the ground's server and keeps serving the site while the ground is unreachable",
    )
    add_listen_arguments(p, default_listen=DEFAULT_LISTEN, delay_hint=False)
    p.add_argument(
        "--connect",
        metavar="ENDPOINT",
        action="append",
        help=f"the ground's mission server (default {DEFAULT_CONNECT}); repeatable",
    )
    g = p.add_argument_group(
        "the relay's own login at the ground (an account of role relay) and the long link"
    )
    add_login_arguments(g, user_help="the relay's account at the ground (role relay)")
    g.add_argument(
        "--ground-cert-name",
        metavar="CN",
        action="append",
        help="with --accounts: the common name of the ground's TLS certificate, which tells "
        "the ground's link from the site's (default: 'missionctl server', as missionctl "
        "certs makes it); repeatable",
    )
    p.add_argument("-v", "--verbose", action="store_true")
    return p


def run(args: argparse.Namespace) -> int:
    from backend.core.credentials import AccountsError

    log_to_stderr(args.verbose)
    try:
        relay, login = _relay(args)
    except (AccountsError, ValueError) as e:
        print(f"missionctl router: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    from backend.transport import timeouts
    from backend.transport.session import TransportError

    try:
        return asyncio.run(_serve(relay, timeouts.describe(login.link_delay_hint)))
    except TransportError as e:
        print(f"missionctl router: {e}", file=sys.stderr)
        return EXIT_UNREACHABLE


def _relay(args: argparse.Namespace) -> tuple[Any, Any]:
    """The relay the options ask for, and its login at the ground (their
    errors, AccountsError or ValueError, are the caller's to say)."""
    from backend.server.accounts import load_accounts
    from backend.server.relay import SiteRelay
    from backend.transport.login import login_from_args

    listen = args.listen or [DEFAULT_LISTEN]
    connect = args.connect or [DEFAULT_CONNECT]
    file_options = config_file_options(args)
    login = login_from_args(args)
    _check_tls(args)
    accounts = load_accounts(args.accounts) if args.accounts else None
    _check_open_site(listen, login.logged_in, accounts is not None)
    extra = {**login.zenoh_options(), **tls_listen_options(args), **file_options}
    relay = SiteRelay(
        listen=listen,
        connect=connect,
        zenoh_extra=extra,
        accounts=accounts,
        ground_cert_names=args.ground_cert_name,
        on_ground=lambda up: _say_ground(up, connect),
    )
    return relay, login


def _check_tls(args: argparse.Namespace) -> None:
    """Zenoh has one set of TLS settings per process, for both sides of the relay."""
    if args.tls_ca and args.ca and _same_file(args.tls_ca, args.ca) is False:
        raise ValueError(
            "--tls-ca and --ca name different files: a relay trusts one CA for both the "
            "site's clients and the ground's server"
        )
    if bool(args.tls_ca) != bool(args.cert):
        raise ValueError(
            "mutual TLS is on both sides of a relay or on neither: give --tls-ca (the site's "
            "clients show certificates) together with --cert/--key (the relay shows one to "
            "the ground)"
        )


def _same_file(a: str, b: str) -> bool:
    from pathlib import Path

    return Path(a).resolve() == Path(b).resolve()


def _check_open_site(listen: list[str], logged_in: bool, accounts: bool) -> None:
    """A relay logged in at the ground but open to anyone at the site would hand its
    account (which may do everything) to whoever reaches its port."""
    if not logged_in or accounts:
        return
    exposed = [e for e in listen if not _loopback(e)]
    if exposed:
        raise ValueError(
            f"this relay logs in at the ground (--user) but would let anyone reaching "
            f"{', '.join(exposed)} in: give --accounts (the site's logins), or listen on "
            "loopback only"
        )


def _loopback(endpoint: str) -> bool:
    host = endpoint.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]")
    return host in ("localhost", "::1") or host.startswith("127.")


def _say_ground(up: bool, connect: list[str]) -> None:
    where = ", ".join(connect)
    if up:
        print(f"missionctl router: ground link up ({where})", flush=True)
    else:
        print(
            f"missionctl router: ground link down ({where}): the site keeps working; reconnecting",
            flush=True,
        )


async def _serve(relay: Any, timeouts_line: str) -> int:
    async with until_signalled(relay) as stop:
        logins = "site logins required" if relay.accounts is not None else "no site logins"
        print(
            f"missionctl router: relaying {', '.join(relay.listen)} (the site) to "
            f"{', '.join(relay.connect)} (the ground); {logins}; {timeouts_line}",
            flush=True,
        )
        await stop.wait()
    return EXIT_OK
