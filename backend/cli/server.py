"""`missionctl server`: run the mission server until interrupted."""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path
from typing import Any

from backend.cli.ctl.values import parse_duration
from backend.cli.listening import (
    add_listen_arguments,
    config_file_options,
    log_to_stderr,
    tls_listen_options,
    until_signalled,
)

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
        "--db", metavar="PATH", help="SQLite journal (default: MISSION.db next to the mission file)"
    )
    add_listen_arguments(p, default_listen="tcp/127.0.0.1:7447")
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
    p.add_argument(
        "--contact-windows",
        metavar="FILE",
        help="each robot's contact windows (YAML, see docs/deployment.md); a robot not in it "
        "is always in contact, or in the simulator's windows when one runs",
    )
    p.add_argument("-v", "--verbose", action="store_true")
    return p


def run(args: argparse.Namespace) -> int:
    # imported here: every missionctl command builds this parser
    from backend.core.credentials import AccountsError
    from backend.files.diagnostics import FileProblems
    from backend.server.journal import JournalError, NotReplayable, Unreplayable
    from backend.transport.session import TransportError

    log_to_stderr(args.verbose)
    if not args.mission and not args.db:
        print("missionctl server: give --mission FILE (and optionally --db PATH)", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        options = _options(args)
    except (AccountsError, ValueError) as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except FileProblems as e:
        return _file_problems(e)
    server = _server(args, options)
    try:
        return asyncio.run(_serve(server))
    except FileProblems as e:
        return _file_problems(e)
    except Unreplayable as e:  # written by an older version, or damaged: offer the recovery
        print(_unreplayable_text(e), file=sys.stderr)
        return EXIT_BAD_INPUT
    except (JournalError, NotReplayable) as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except TransportError as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_UNREACHABLE


def _options(args: argparse.Namespace) -> dict[str, Any]:
    """The server's options read from files (Zenoh's configuration, TLS,
    accounts, contact windows); their errors are the caller's to say."""
    from backend.files.contact import load_contact_windows
    from backend.server.accounts import load_accounts

    return {
        "zenoh_extra": {**config_file_options(args), **tls_listen_options(args)},
        "accounts": load_accounts(args.accounts) if args.accounts else None,
        "contact_windows": (
            load_contact_windows(args.contact_windows) if args.contact_windows else None
        ),
    }


def _server(args: argparse.Namespace, options: dict[str, Any]) -> Any:
    from backend.server.server import MissionServer

    db = Path(args.db) if args.db else Path(args.mission).with_suffix(".db")
    return MissionServer(
        db=db,
        mission_file=args.mission,
        listen=args.listen,
        command_expiry=args.command_expiry or None,
        recover=args.recover,
        link_delay_hint=args.link_delay_hint,
        **options,
        **({} if args.archive_samples is None else {"archive_samples": args.archive_samples}),
    )


def _file_problems(e: Any) -> int:
    for issue in e.issues:
        print(issue, file=sys.stderr)
    return EXIT_BAD_INPUT


def _unreplayable_text(e: Any) -> str:
    """The journal holds a batch that does not replay: what --recover would do."""
    after = f" and the {e.later} after it" if e.later else ""
    return (
        f"missionctl server: {e}\nmissionctl server: the mission up to revision "
        f"{e.revision - 1} replays; to start from it, run again with --recover: "
        f"batch {e.revision}{after} will be kept in the journal's quarantine table "
        "(nothing is deleted)"
    )


async def _serve(server) -> int:
    async with until_signalled(server) as stop:
        for line in _greeting(server):
            print(f"missionctl server: {line}", flush=True)
        await stop.wait()
    return 0


def _greeting(server: Any) -> list[str]:
    """What the server says once it listens: the mission, where from, and
    what an operator must know (a recovery, an unread file, delays, logins)."""
    lines = [server.recovered] if server.recovered else []
    how = (
        f"resumed from {server.db} at revision {server.mission.revision}"
        if server.resumed
        else f"started from {server.mission_file}, journal {server.db}"
    )
    lines.append(f"mission '{server.mission.name}' {how}; listening on {', '.join(server.listen)}")
    if server.resumed and server.mission_file is not None:  # a changed file is not read
        lines.append(
            f"{server.mission_file} was not read "
            "(the journal holds the mission); to start from it anew, give another --db"
        )
    if server.link_delay_hint > 0:
        from backend.transport.timeouts import describe

        lines.append(describe(server.link_delay_hint))
    if server.accounts is not None:
        roles = ", ".join(
            f"{u} ({a.role})" for u, a in sorted(server.accounts.table.accounts.items())
        )
        lines.append(f"logins required ({server.accounts.source}): {roles}")
    return lines
