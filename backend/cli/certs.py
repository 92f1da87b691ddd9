"""`missionctl certs`: a private CA, a server certificate and client certificates.

The command line only; the PKI itself is backend/server/certs.py (`make_certs`).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


def prepare_parser(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "certs",
        help="make a CA, a server certificate and client certificates for TLS endpoints",
        description="Writes DIR/ca.pem (+ ca.key), DIR/server.pem (+ server.key) and "
        "DIR/client-NAME.pem (+ .key) per --client. An existing DIR/ca.pem is reused, "
        "so clients can be added later.",
    )
    p.add_argument("dir", metavar="DIR", help="directory to write into (created)")
    p.add_argument(
        "--server-name",
        metavar="NAME",
        action="append",
        help="DNS name or IP address clients use to reach the server; repeatable "
        "(default: localhost and 127.0.0.1). Given, the server certificate is (re)made.",
    )
    p.add_argument(
        "--client",
        metavar="NAME",
        action="append",
        default=[],
        help="make a client certificate with this common name; repeatable",
    )
    p.add_argument(
        "--days",
        type=int,
        default=365,
        metavar="N",
        help="validity of new certificates (default 365)",
    )
    return p


def run(args: argparse.Namespace) -> int:
    from backend.server.certs import make_certs

    problem = _usage_problem(args)
    if problem is not None:
        print(f"missionctl certs: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        written = make_certs(
            Path(args.dir), server_names=args.server_name, clients=args.client, days=args.days
        )
    except (ImportError, OSError, ValueError) as e:
        print(f"missionctl certs: {_not_written(e, args.dir)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    for path in written:
        print(path)
    return EXIT_OK


def _usage_problem(args: argparse.Namespace) -> str | None:
    bad = [n for n in args.client if not _NAME.match(n)]
    if bad:
        return (
            f"invalid client name(s) {', '.join(map(repr, bad))}: "
            "use letters, digits, '.', '_', '-'"
        )
    if args.days < 1:
        return "--days must be at least 1"
    return None


def _not_written(e: Exception, folder: str) -> str:
    """Why no certificate was written, and what to do."""
    if isinstance(e, ImportError):
        return "needs the 'cryptography' package (pip install cryptography)"
    if isinstance(e, OSError):  # a folder that cannot be made or written: say which and why
        return (
            f"cannot write into {e.filename or folder}: {e.strerror or e}; "
            "choose a DIR you can create and write"
        )
    return str(e)
