"""`missionctl` command line.

backend owns the entry point and the commands that need only backend
(validate, schema, server, router, certs, ctl: one module each). `sim` and `console`
plug their commands in through the `missionctl.commands` entry-point group, so
backend never imports them.

Exit codes: 0 ok, 1 operation refused, 2 bad input/usage, 3 server unreachable.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from backend.cli import certs, ctl, router, schema, server, validate
from backend.cli.command import Command
from backend.cli.ctl.args import wants_json
from backend.cli.parser import Parser
from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK

# backend's own commands, in the order `missionctl --help` lists them. Running
# one needs no plug-in (finding and importing them costs ~50 ms of every
# `missionctl ctl` call in a script).
OWN_COMMANDS: dict[str, Command] = {
    "validate": validate,
    "schema": schema,
    "server": server,
    "router": router,
    "ctl": ctl,
    "certs": certs,
}


def build_parser(*, plugins: bool = True) -> argparse.ArgumentParser:
    p = Parser(
        prog="missionctl",
        description="Mission operation console for heterogeneous robot teams.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for command in OWN_COMMANDS.values():
        command.prepare_parser(sub).set_defaults(func=command.run)
    for _name, register in _registrations() if plugins else []:
        register(sub)
    return p


def _registrations() -> list[tuple[str, Callable[[Any], None]]]:
    """Commands other packages plug in (sim, console): `register(subparsers)`."""
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
    parser = build_parser(plugins=_command_word(argv) not in OWN_COMMANDS)
    Parser.json_errors = wants_json(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    return _run(args)


def _command_word(argv: list[str]) -> str | None:
    """The command named (`ctl` of `missionctl -v ctl state`), if any."""
    return next((a for a in argv if not a.startswith("-")), None)


def _run(args: argparse.Namespace) -> int:
    """The command's exit code; Ctrl-C and a reader gone away are no errors."""
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
