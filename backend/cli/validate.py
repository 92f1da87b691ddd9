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
    from backend.files.missions import validate_file

    bad = 0
    for f in args.files:
        issues = validate_file(f)
        for issue in issues:
            print(issue, file=sys.stderr)
        if issues:
            bad += 1
        elif not args.quiet:
            print(f"{f}: ok")
    return EXIT_BAD_INPUT if bad else EXIT_OK
