"""`missionctl web`: the console in a browser, served by textual-serve on loopback.

Each browser tab that opens the address gets its own console process
(`missionctl console --connect EP ...`), drawn in the page by textual-serve's
terminal. By default it is an **observer**: read-only whatever account it
logs in with, and nothing it does is ever submitted (`--observer`). With
`--operator` it is an operator's console, and only with a login (`--user`
and `--password-file`, as the console's): every tab then acts as that
user, so the address stays on loopback (reach it from elsewhere through an
SSH tunnel; docs/security.md).
"""

from __future__ import annotations

import argparse
import shlex
import sys

from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK
from backend.transport.login import add_login_arguments
from console.options import DEFAULT_CONNECT, THEME_HELP

DEFAULT_PORT = 8470
HOST = "127.0.0.1"  # loopback only: textual-serve has no login of its own


def register(sub: argparse._SubParsersAction) -> None:
    w = sub.add_parser(
        "web",
        help="serve the console to a browser on loopback (observer unless --operator)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    w.add_argument(
        "--connect",
        metavar="ENDPOINT",
        default=DEFAULT_CONNECT,
        help=f"Zenoh endpoint of the mission server (default {DEFAULT_CONNECT})",
    )
    w.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        metavar="N",
        help=f"serve on http://{HOST}:N (default {DEFAULT_PORT})",
    )
    w.add_argument(
        "--operator",
        action="store_true",
        help="an operator's console (needs --user and --password-file); default: an observer",
    )
    add_login_arguments(w, user_help="account the served consoles log in as")
    w.add_argument("--theme", metavar="T", help=THEME_HELP)
    w.set_defaults(func=run_web)


def console_command(args: argparse.Namespace) -> str:
    """The shell command textual-serve runs for each browser tab."""
    argv = [sys.executable, "-m", "backend.cli", "console", "--connect", args.connect, "--yes"]
    if not args.operator:
        argv.append("--observer")
    for option in ("user", "password_file", "ca", "cert", "key"):
        value = getattr(args, option, None)
        if value:
            argv += [f"--{option.replace('_', '-')}", str(value)]
    if args.theme:
        argv += ["--theme", args.theme]
    return shlex.join(argv)


def run_web(args: argparse.Namespace) -> int:
    if args.operator and not (args.user and getattr(args, "password_file", None)):
        print(
            "missionctl web: --operator needs a login (--user and --password-file), as the "
            "console does; without --operator the browser view is an observer",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    if not 0 < args.port < 65536:
        print(f"missionctl web: --port {args.port} is not a port (1-65535)", file=sys.stderr)
        return EXIT_BAD_INPUT
    from textual_serve.server import Server

    role = "operator" if args.operator else "observer (read-only)"
    server = Server(console_command(args), host=HOST, port=args.port, title="missionctl")
    print(
        f"missionctl web: serving the console as {role} on http://{HOST}:{args.port} "
        f"for the server at {args.connect}; ctrl+c stops",
        file=sys.stderr,
        flush=True,
    )
    server.serve()
    return EXIT_OK
