"""`missionctl` command line.

backend owns the entry point and the commands that need only backend
(validate, schema, server, ctl). `sim` and `console` plug their commands in
through the `missionctl.commands` entry-point group, so backend never imports
them.

Exit codes: 0 ok, 1 operation refused, 2 bad input/usage, 3 server unreachable.
"""

from __future__ import annotations

import argparse
import json
import sys

from backend.cli.parser import Parser
from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK


def cmd_validate(args: argparse.Namespace) -> int:
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


def cmd_schema(args: argparse.Namespace) -> int:
    from backend.files.schema import schemas

    all_schemas = schemas()
    if args.kind != "all":
        out = all_schemas[args.kind]
    else:
        out = all_schemas
    print(json.dumps(out, indent=2))
    return EXIT_OK


# commands of backend itself: running one needs no plug-in (finding and
# importing them costs ~50 ms of every `missionctl ctl` call in a script)
OWN_COMMANDS = frozenset({"validate", "schema", "server", "ctl", "certs"})


def build_parser(*, plugins: bool = True) -> argparse.ArgumentParser:
    p = Parser(
        prog="missionctl",
        description="Mission operation console for heterogeneous robot teams.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)

    v = sub.add_parser("validate", help="check mission and skill-library files")
    v.add_argument("files", nargs="+", metavar="FILE")
    v.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    v.set_defaults(func=cmd_validate)

    s = sub.add_parser("schema", help="print the JSON Schema of mission and library files")
    s.add_argument("kind", nargs="?", choices=["all", "mission", "library"], default="all")
    s.set_defaults(func=cmd_schema)

    from backend.cli import server as server_cli

    server_cli.register(sub)
    from backend.cli.ctl import session as ctl

    ctl.register(sub)
    from backend.cli import certs

    certs.register(sub)
    for _name, register in _registrations() if plugins else []:
        register(sub)
    return p


def _registrations():
    """Commands other packages plug in (sim, console)."""
    from importlib.metadata import entry_points

    plugged = []
    for ep in entry_points(group="missionctl.commands"):
        try:
            plugged.append((ep.name, ep.load()))
        except ImportError as e:  # a broken plug-in must not take the CLI down
            print(f"missionctl: command '{ep.name}' unavailable: {e}", file=sys.stderr)
    return sorted(plugged, key=lambda x: x[0])


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(plugins=command not in OWN_COMMANDS)
    from backend.cli.ctl.session import wants_json

    Parser.json_errors = wants_json(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
