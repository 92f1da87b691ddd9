"""`missionctl server`: run the mission server until interrupted."""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
from pathlib import Path
from typing import Any

from backend.cli.ctl.values import parse_duration

EXIT_BAD_INPUT, EXIT_UNREACHABLE = 2, 3


def prepare_parser(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "server", help="run the mission server (a Zenoh router on loopback by default)"
    )
    p.add_argument(
        "--mission",
        metavar="FILE",
        help="mission to start from (ignored when --db already holds one)",
    )
    p.add_argument(
        "--listen",
        metavar="ENDPOINT",
        action="append",
        help="Zenoh endpoint to listen on (default tcp/127.0.0.1:7447); repeatable",
    )
    p.add_argument(
        "--db", metavar="PATH", help="SQLite journal (default: MISSION.db next to the mission file)"
    )
    p.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="JSON5 Zenoh config merged over ours (TLS, accounts, ACL)",
    )
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
    p.add_argument(
        "--command-expiry",
        type=parse_duration,
        default=0.0,
        metavar="D",
        help="default expiry of commands to robots, e.g. 30m or 2h (a robot never applies a "
        "command past its expiry; an operation may give its own with --expire); "
        "default: never",
    )
    p.add_argument(
        "--recover",
        action="store_true",
        help="when the journal holds a batch that cannot be replayed, start from the mission "
        "before it; that batch and the later ones move to the journal's quarantine table",
    )
    p.add_argument(
        "--archive-samples",
        type=int,
        default=None,
        metavar="N",
        help="telemetry samples kept for review in DB's .telemetry.db beside it, the oldest "
        "going first (default 2000000; 0: no archive). See docs/review.md",
    )
    p.add_argument("-v", "--verbose", action="store_true")
    return p


def run(args: argparse.Namespace) -> int:
    # imported here: every missionctl command builds this parser
    from backend.core.credentials import AccountsError
    from backend.files.diagnostics import FileProblems
    from backend.server.accounts import load_accounts
    from backend.server.journal import JournalError, NotReplayable, Unreplayable
    from backend.server.server import MissionServer
    from backend.transport import load_config_file
    from backend.transport.session import TransportError

    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(asctime)s %(levelname)s %(message)s",
    )
    if not args.mission and not args.db:
        print("missionctl server: give --mission FILE (and optionally --db PATH)", file=sys.stderr)
        return EXIT_BAD_INPUT
    db = Path(args.db) if args.db else Path(args.mission).with_suffix(".db")
    try:
        extra = load_config_file(args.zenoh_config) if args.zenoh_config else None
    except (OSError, ValueError) as e:
        print(f"missionctl server: {args.zenoh_config}: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        extra = {**(extra or {}), **_tls_options(args)}
        accounts = load_accounts(args.accounts) if args.accounts else None
    except (AccountsError, ValueError) as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    server = MissionServer(
        db=db,
        mission_file=args.mission,
        listen=args.listen,
        zenoh_extra=extra,
        command_expiry=args.command_expiry or None,
        accounts=accounts,
        recover=args.recover,
        **({} if args.archive_samples is None else {"archive_samples": args.archive_samples}),
    )
    try:
        return asyncio.run(_serve(server))
    except FileProblems as e:
        for issue in e.issues:
            print(issue, file=sys.stderr)
        return EXIT_BAD_INPUT
    except Unreplayable as e:  # written by an older version, or damaged: offer the recovery
        after = f" and the {e.later} after it" if e.later else ""
        print(
            f"missionctl server: {e}\nmissionctl server: the mission up to revision "
            f"{e.revision - 1} replays; to start from it, run again with --recover: "
            f"batch {e.revision}{after} will be kept in the journal's quarantine table "
            "(nothing is deleted)",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    except (JournalError, NotReplayable) as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except TransportError as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_UNREACHABLE


def _tls_options(args: argparse.Namespace) -> dict:
    """Zenoh options for --tls-cert/--tls-key/--tls-ca; checks they fit --listen."""
    tls_listen = any(e.startswith("tls/") for e in args.listen or [])
    if not (args.tls_cert or args.tls_key or args.tls_ca):
        if tls_listen:
            raise ValueError(
                "a tls/ endpoint needs --tls-cert FILE and --tls-key FILE (see missionctl certs)"
            )
        return {}
    if not (args.tls_cert and args.tls_key):
        raise ValueError("--tls-cert and --tls-key go together")
    if not tls_listen:
        raise ValueError(
            "--tls-cert/--tls-key/--tls-ca need a tls/ endpoint in --listen "
            "(e.g. --listen tls/0.0.0.0:7447)"
        )
    for opt, path in (
        ("--tls-cert", args.tls_cert),
        ("--tls-key", args.tls_key),
        ("--tls-ca", args.tls_ca),
    ):
        if path and not Path(path).is_file():
            raise ValueError(f"{opt} {path}: no such file")
    out: dict[str, str | bool] = {
        "transport/link/tls/listen_certificate": str(Path(args.tls_cert).resolve()),
        "transport/link/tls/listen_private_key": str(Path(args.tls_key).resolve()),
    }
    if args.tls_ca:
        out["transport/link/tls/root_ca_certificate"] = str(Path(args.tls_ca).resolve())
        out["transport/link/tls/enable_mtls"] = True
    return out


async def _serve(server) -> int:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        loop.add_signal_handler(sig, stop.set)
    await server.start()
    try:
        if server.recovered:
            print(f"missionctl server: {server.recovered}", flush=True)
        how = (
            f"resumed from {server.db} at revision {server.mission.revision}"
            if server.resumed
            else f"started from {server.mission_file}, journal {server.db}"
        )
        print(
            f"missionctl server: mission '{server.mission.name}' {how}; "
            f"listening on {', '.join(server.listen)}",
            flush=True,
        )
        if (
            server.resumed and server.mission_file is not None
        ):  # a changed or other mission file is not read
            print(
                f"missionctl server: {server.mission_file} was not read "
                "(the journal holds the mission); to start from it anew, give another --db",
                flush=True,
            )
        if server.accounts is not None:
            roles = ", ".join(
                f"{u} ({a.role})" for u, a in sorted(server.accounts.table.accounts.items())
            )
            print(
                f"missionctl server: logins required ({server.accounts.source}): {roles}",
                flush=True,
            )
        await stop.wait()
    finally:
        await server.stop()
    return 0
