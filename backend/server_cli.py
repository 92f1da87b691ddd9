"""`missionctl server`: run the mission server until interrupted."""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
from pathlib import Path

from .files import FileProblems
from .journal import JournalError
from .transport import load_config_file
from .transport.session import TransportError

EXIT_BAD_INPUT, EXIT_UNREACHABLE = 2, 3


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("server", help="run the mission server (a Zenoh router on loopback by default)")
    p.add_argument("--mission", metavar="FILE", help="mission to start from (ignored when --db already holds one)")
    p.add_argument("--listen", metavar="ENDPOINT", action="append", help="Zenoh endpoint to listen on (default tcp/127.0.0.1:7447); repeatable")
    p.add_argument("--db", metavar="PATH", help="SQLite journal (default: MISSION.db next to the mission file)")
    p.add_argument("--zenoh-config", metavar="FILE", help="JSON5 Zenoh config merged over ours (TLS, accounts, ACL)")
    p.add_argument("--command-timeout", type=float, default=10.0, metavar="S", help="how long to wait for a robot to answer a command")
    p.add_argument("-v", "--verbose", action="store_true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .server import MissionServer

    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(asctime)s %(levelname)s %(message)s")
    if not args.mission and not args.db:
        print("missionctl server: give --mission FILE (and optionally --db PATH)", file=sys.stderr)
        return EXIT_BAD_INPUT
    db = Path(args.db) if args.db else Path(args.mission).with_suffix(".db")
    try:
        extra = load_config_file(args.zenoh_config) if args.zenoh_config else None
    except (OSError, ValueError) as e:
        print(f"missionctl server: {args.zenoh_config}: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    server = MissionServer(db=db, mission_file=args.mission, listen=args.listen, zenoh_extra=extra, command_timeout=args.command_timeout)
    try:
        return asyncio.run(_serve(server))
    except FileProblems as e:
        for issue in e.issues:
            print(issue, file=sys.stderr)
        return EXIT_BAD_INPUT
    except JournalError as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except TransportError as e:
        print(f"missionctl server: {e}", file=sys.stderr)
        return EXIT_UNREACHABLE


async def _serve(server) -> int:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        loop.add_signal_handler(sig, stop.set)
    await server.start()
    try:
        how = f"resumed from {server.db} at revision {server.mission.revision}" if server.resumed else f"started from {server.mission_file}, journal {server.db}"
        print(f"missionctl server: mission '{server.mission.name}' {how}; listening on {', '.join(server.listen)}", flush=True)
        await stop.wait()
    finally:
        await server.stop()
    return 0
