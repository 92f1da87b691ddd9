"""`missionctl schema`: print the JSON Schema of mission and library files."""

from __future__ import annotations

import argparse
import json
from typing import Any

from backend.exit_codes import EXIT_OK


def prepare_parser(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "schema", help="print the JSON Schema of the mission, library and contact windows files"
    )
    p.add_argument(
        "kind", nargs="?", choices=["all", "mission", "library", "contact-windows"], default="all"
    )
    return p


def run(args: argparse.Namespace) -> int:
    from backend.files.schema import schemas

    all_schemas = schemas()
    if args.kind != "all":
        out = all_schemas[args.kind]
    else:
        out = all_schemas
    print(json.dumps(out, indent=2))
    return EXIT_OK
