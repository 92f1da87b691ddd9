"""`missionctl validate`: check mission and skill-library files."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK


def prepare_parser(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser("validate", help="check mission and skill-library files")
    p.add_argument("files", nargs="+", metavar="FILE")
    p.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    return p


def run(args: argparse.Namespace) -> int:
    bad = [f for f in args.files if not _valid(f, args.quiet)]
    return EXIT_BAD_INPUT if bad else EXIT_OK


def _valid(file: str, quiet: bool) -> bool:
    """Check one file: its issues on stderr, or `FILE: ok` (unless quiet)."""
    from backend.files.missions import validate_file

    issues = validate_file(file)
    for issue in issues:
        print(issue, file=sys.stderr)
    if not issues and not quiet:
        print(f"{file}: ok")
    return not issues
