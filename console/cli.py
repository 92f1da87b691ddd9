"""`missionctl console` and `missionctl demo` (plugged into backend's CLI
through the `missionctl.commands` entry-point group)."""

from __future__ import annotations

import argparse
import sys

from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK, EXIT_UNREACHABLE
from backend.transport.login import add_login_arguments
from console.options import DEFAULT_CONNECT, THEME_HELP
from console.options import known_binding_ids as _known_binding_ids
from console.state.keys import KeyNames

YES_HELP = (
    f"quit without asking (for scripts); else {KeyNames().say('app.quit')} asks while robots "
    "execute, commands wait for a robot or the plan has edits not saved to a file"
)
OBSERVER = "observer: this console watches, it changes nothing"
DEMO_QUITS = (
    "Quitting ends the demo: its mission server and simulated robots stop, and its journal "
    "(in a temporary folder) is deleted — save the mission to keep the plan."
)


def register(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser(
        "console", help="the operator console (terminal UI) for a running mission server"
    )
    c.add_argument(
        "--connect",
        metavar="ENDPOINT",
        default=DEFAULT_CONNECT,
        help=f"Zenoh endpoint of the server (default {DEFAULT_CONNECT})",
    )
    add_login_arguments(
        c,
        user_help=(
            "account to log in as (with --password-file); "
            "without one, just the name recorded with every change"
        ),
    )
    c.add_argument("--theme", metavar="T", help=THEME_HELP)
    c.add_argument(
        "--config",
        metavar="FILE",
        help="settings file (default ~/.config/missionctl/config.toml or .yaml)",
    )
    c.add_argument("--yes", action="store_true", help=YES_HELP)
    c.add_argument(
        "--observer",
        action="store_true",
        help="watch only: this console changes nothing, whatever the account "
        "(`missionctl web` serves it so by default)",
    )
    c.set_defaults(func=run_console)

    d = sub.add_parser(
        "demo", help="server + simulated fleet + console on loopback; quitting stops everything"
    )
    d.add_argument(
        "--mission",
        metavar="FILE",
        help="mission to run (default missions/mars_sample_return.yaml)",
    )
    d.add_argument(
        "--speed", metavar="X", type=float, default=1.0, help="sim time per real time (default 1)"
    )
    d.add_argument(
        "--link-delay",
        metavar="D",
        default=None,
        help="one-way delay between ground and the simulated robots, in sim time "
        "(e.g. 20s, 20m, 1.5h; passed to `missionctl sim --link-delay`)",
    )
    d.add_argument(
        "--comms-window",
        metavar="W",
        help="contact only in windows, in sim time: OPEN/PERIOD[@OFFSET], e.g. 20m/2h "
        "(passed to `missionctl sim --comms-window`)",
    )
    d.add_argument(
        "--break",
        dest="breaks",
        metavar="ROBOT@T[:HOW]",
        action="append",
        default=[],
        help="ROBOT breaks at sim time T, e.g. lru1@12m (repeatable; passed to `missionctl sim "
        "--break`)",
    )
    d.add_argument(
        "--join",
        dest="joins",
        metavar="ROBOT:TYPE@T",
        action="append",
        default=[],
        help="a robot of TYPE asks to join at sim time T, e.g. lru3:lru_science@15m "
        "(repeatable; passed to `missionctl sim --join`)",
    )
    d.add_argument("--user", metavar="U", default="", help="operator name")
    d.add_argument("--theme", metavar="T", help=THEME_HELP)
    d.add_argument("--config", metavar="FILE")
    d.add_argument("--yes", action="store_true", help=YES_HELP)
    d.set_defaults(func=run_demo)

    from console.review.cli import register as register_review
    from console.web import register as register_web

    register_review(sub)
    register_web(sub)


def _run_app(app) -> int:
    try:
        result = app.run()
    finally:
        if app.bridge is not None:
            app.bridge.close_now()  # never leave a Zenoh session open at exit (it hangs)
    code = app.return_code
    if code is None:
        code = result if isinstance(result, int) else EXIT_OK
    return int(code)


def run_console(args: argparse.Namespace) -> int:
    from backend.core.credentials import AccountsError
    from backend.transport.login import login_from_args
    from console.app import MissionApp
    from console.config import load_config

    try:
        login = login_from_args(args)
    except AccountsError as e:
        print(f"missionctl console: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    refused = _login_refused(args.connect, login)
    if refused:  # before the terminal UI takes the screen: one line, exit 3
        print(f"missionctl console: {refused}", file=sys.stderr)
        return EXIT_UNREACHABLE
    cfg = load_config(args.config, known_ids=_known_binding_ids())
    app = MissionApp(
        connect=args.connect,
        user=args.user,
        theme=args.theme,
        config=cfg,
        login=login,
        ask_before_quit=not args.yes,
        observer=OBSERVER if args.observer else "",
    )
    code = _run_app(app)
    if app.login_refused:
        print(f"missionctl console: {app.login_refused}", file=sys.stderr)
    return code


def _login_refused(endpoint: str, login) -> str | None:
    """Open and close one session: the router's verdict on the login/TLS files.
    Anything else (server down…) is left to the app, which offers to retry."""
    from backend.transport import (
        LoginRefused,
        TransportError,
        client_config,
        close_session,
        open_session,
    )

    if not (login.logged_in or login.ca or login.cert):
        return None
    try:
        close_session(open_session(client_config([endpoint], extra=login.zenoh_options())))
    except LoginRefused as e:
        return str(e)
    except (TransportError, ValueError):
        pass
    return None


def _sim_options(args: argparse.Namespace) -> list[str]:
    """The demo's options that are the sim's, in its own words."""
    said = [("--link-delay", args.link_delay), ("--comms-window", args.comms_window)]
    said += [("--break", b) for b in args.breaks] + [("--join", j) for j in args.joins]
    return [word for name, value in said if value for word in (name, value)]


def run_demo(args: argparse.Namespace) -> int:
    from console.config import load_config
    from console.demo import DEFAULT_MISSION, DemoError, DemoProcesses

    if args.speed <= 0:
        print("missionctl demo: --speed must be positive", file=sys.stderr)
        return EXIT_BAD_INPUT
    mission = args.mission or str(DEFAULT_MISSION)
    procs = DemoProcesses(mission, speed=args.speed, sim_options=_sim_options(args))
    try:
        procs.launch()  # the server starts while the console loads (console/demo_app.py)
    except DemoError as e:
        procs.stop()
        print(f"missionctl demo: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        from console.demo_app import DemoApp

        app = DemoApp(
            procs,
            user=args.user,
            theme=args.theme,
            config=load_config(args.config, known_ids=_known_binding_ids()),
            notices=procs.notices,
            ask_before_quit=not args.yes,
            quitting_stops=DEMO_QUITS,
        )
        app.on_forced_exit.append(procs.stop)  # the children must not outlive a hung-up demo
        code = _run_app(app)
        if app.demo_error:
            print(f"missionctl demo: {app.demo_error}", file=sys.stderr)
        return code
    finally:
        procs.stop()
