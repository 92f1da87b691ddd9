"""`missionctl sim` and `missionctl sim-status` (plugged in through the
`missionctl.commands` entry point; backend never imports this module).

Exit codes: 0 ok, 1 refused/no simulator, 2 bad input, 3 server unreachable.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from backend.core.credentials import AccountsError
from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK, EXIT_REFUSED, EXIT_UNREACHABLE
from backend.transport.login import add_login_arguments, login_from_args
from sim.comms import DURATION_EXAMPLES, WINDOW_SYNTAX, parse_duration, parse_window
from sim.team import TeamEvents, parse_break, parse_join

if TYPE_CHECKING:  # imported when a command runs: `missionctl --help` stays quick
    from backend.core.library import Library
    from backend.core.model import Mission
    from backend.files.diagnostics import Issue
    from backend.protocol import mapfeed as mf
    from sim.fleet import SimFleet
    from sim.worldfile import WorldFile

    Loaded = tuple[Mission, Library, WorldFile, Path]


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _rate(text: str) -> tuple[str | None, float]:
    """`HZ` or `ROBOT=HZ` (--telemetry-rate)."""
    robot, _, hz = text.rpartition("=")
    try:
        value = float(hz)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a rate: {text!r} (e.g. 1, 0.5 or lru1=2)") from None
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"a rate is 0 or more samples a second, got {text!r}")
    return (robot or None), value


def _telemetry_rates(args: argparse.Namespace) -> tuple[float, dict[str, float]]:
    """(every robot's cap, per-robot caps)."""
    everyone = 1.0 if args.link_budget == "on" else 4.0
    per_robot: dict[str, float] = {}
    for robot, hz in args.telemetry_rate or []:
        if robot is None:
            everyone = hz
        else:
            per_robot[robot] = hz
    return everyone, per_robot


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "sim", help="run the simulated fleet of a mission's site (Mars sample return)"
    )
    p.add_argument(
        "--mission", metavar="FILE", required=True, help="mission file: which robots to simulate"
    )
    p.add_argument(
        "--connect",
        metavar="ENDPOINT",
        action="append",
        help="Zenoh endpoint of the mission server (default tcp/127.0.0.1:7447); repeatable",
    )
    p.add_argument(
        "--world",
        metavar="FILE",
        help=(
            "world file (default: worlds/mars.yaml next to the mission, "
            "else missions/worlds/mars.yaml)"
        ),
    )
    p.add_argument(
        "--speed",
        type=_positive,
        default=1.0,
        metavar="X",
        help="sim time per wall time (1 = real time)",
    )
    p.add_argument("--seed", type=int, metavar="N", help="random seed (default: the world file's)")
    p.add_argument(
        "--link-delay",
        type=parse_duration,
        default=0.0,
        metavar="D",
        help=(
            "one-way delay between ground and robots, in sim time (at --speed 60, 20m is 20 s "
            f"of wall time): {DURATION_EXAMPLES}"
        ),
    )
    p.add_argument(
        "--comms-window",
        type=parse_window,
        metavar="W",
        help=(
            f"contact with the ground only in windows, in sim time: {WINDOW_SYNTAX} (the first "
            "window at the start, or at OFFSET). Out of a window no robot reaches the ground: "
            "commands wait on the server, reports and the map feed wait aboard"
        ),
    )
    p.add_argument(
        "--telemetry-rate",
        type=_rate,
        action="append",
        metavar="[ROBOT=]HZ",
        help="the cap of each robot's telemetry, samples a second (default 1; 0: at changes "
        "and heartbeats only); ROBOT=HZ for one robot; repeatable. Telemetry goes when "
        "something changed beyond its deadband, and at least every 5 s",
    )
    p.add_argument(
        "--link-budget",
        choices=("on", "off"),
        default="on",
        help="off: telemetry at a steady --telemetry-rate (default then 4) and the full status "
        "at every publication, as before the link budget (a baseline for "
        "bench/bench_linkbudget.py)",
    )
    p.add_argument(
        "--break",
        dest="breaks",
        type=parse_break,
        action="append",
        metavar="ROBOT@T[:HOW]",
        help="ROBOT breaks at sim time T: stops responding (silent, the default) or its "
        "manipulator fails (arm); repeatable, e.g. lru1@12m",
    )
    p.add_argument(
        "--join",
        dest="joins",
        type=parse_join,
        action="append",
        metavar="ROBOT:TYPE@T",
        help="a robot of TYPE arrives at sim time T and asks to join the mission (an operator "
        "adds it); repeatable, e.g. lru3:lru_science@15m",
    )
    p.add_argument(
        "--connect-timeout",
        type=float,
        default=10.0,
        metavar="S",
        help="keep trying to reach the server's router this long",
    )
    p.add_argument(
        "--zenoh-config", metavar="FILE", help="JSON5 Zenoh config merged over ours (TLS, accounts)"
    )
    p.add_argument(
        "--check", action="store_true", help="only validate the mission and world files, then exit"
    )
    add_login_arguments(
        p.add_argument_group(
            "login and TLS (docs/security.md): a robot account listing the simulated robots"
        )
    )
    p.add_argument("-v", "--verbose", action="store_true")
    p.set_defaults(func=run)

    s = sub.add_parser(
        "sim-status",
        help="score, sim clock, regions and robots of a running simulator, as the robots "
        "reported them (--truth: the world as it is)",
    )
    s.add_argument(
        "--connect",
        metavar="ENDPOINT",
        action="append",
        help="Zenoh endpoint (default tcp/127.0.0.1:7447)",
    )
    s.add_argument("--json", action="store_true", help="print the SimStatus as JSON")
    s.add_argument(
        "--truth",
        action="store_true",
        help="also the world as it is (every region and stone, where robots really are, "
        "robot-to-robot exchanges, the referee's log): for evaluation, not for operating",
    )
    s.add_argument("--timeout", type=float, default=5.0, metavar="S")
    add_login_arguments(s.add_argument_group("login and TLS (docs/security.md)"))
    s.set_defaults(func=run_status)


# ---------------------------------------------------------------- sim


def _load(args: argparse.Namespace) -> tuple[Loaded | None, list[Issue]]:
    from backend.files.diagnostics import FileProblems
    from backend.files.missions import load_mission
    from sim.worldfile import default_world_for, load_world

    try:
        mission, library = load_mission(args.mission)
    except FileProblems as e:
        return None, e.issues
    world_file = Path(args.world) if args.world else default_world_for(args.mission)
    try:
        world = load_world(world_file)
    except FileProblems as e:
        return None, e.issues
    return (mission, library, world, world_file), []


class _BadInput(Exception):
    """What `missionctl sim` says on stderr before it exits with EXIT_BAD_INPUT."""


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    loaded, issues = _load(args)
    if loaded is None:
        for issue in issues:
            print(issue, file=sys.stderr)
        return EXIT_BAD_INPUT
    mission, library, world, world_file = loaded
    try:
        fleet = _fleet(args, mission, library, world)
    except _BadInput as e:
        print(f"missionctl sim: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    for warning in fleet.warnings:
        print(f"missionctl sim: {warning}", file=sys.stderr)
    if args.check:
        print(f"{args.mission}: ok\n{world_file}: ok")
        return EXIT_OK
    return asyncio.run(_serve(fleet, args, world_file))


def _fleet(
    args: argparse.Namespace, mission: Mission, library: Library, world: WorldFile
) -> SimFleet:
    """The simulated fleet the command line asks for (_BadInput: why not)."""
    from sim.errors import SimError
    from sim.fleet import SimFleet

    try:
        login = login_from_args(args)
    except AccountsError as e:
        raise _BadInput(str(e)) from None
    extra = _zenoh_options(args, login.zenoh_options())
    rate, rates = _telemetry_rates(args)
    unknown = sorted(set(rates) - set(mission.robots))
    if unknown:
        raise _BadInput(
            f"--telemetry-rate names {', '.join(unknown)}, not a robot of "
            f"{args.mission} ({', '.join(mission.robots)})"
        )
    try:
        return SimFleet(
            mission,
            library,
            world,
            connect=args.connect or ["tcp/127.0.0.1:7447"],
            speed=args.speed,
            seed=args.seed,
            link_delay=args.link_delay,
            comms_window=args.comms_window,
            zenoh_extra=extra,
            link_delay_hint=login.link_delay_hint,
            link_budget=args.link_budget == "on",
            telemetry_hz=rate,
            telemetry_rates=rates,
            team=TeamEvents(args.breaks or [], args.joins or [])
            if args.breaks or args.joins
            else None,
        )
    except (SimError, ValueError) as e:
        raise _BadInput(str(e)) from None


def _zenoh_options(args: argparse.Namespace, login_options: dict[str, Any]) -> dict[str, Any]:
    """--zenoh-config's options under the login's."""
    if not args.zenoh_config:
        return login_options
    from backend.transport import load_config_file

    try:
        return {**load_config_file(args.zenoh_config), **login_options}
    except (OSError, ValueError) as e:
        raise _BadInput(f"{args.zenoh_config}: {e}") from None


async def _serve(fleet: SimFleet, args: argparse.Namespace, world_file: Path) -> int:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        loop.add_signal_handler(sig, stop.set)
    refused = await _start(fleet, args.connect_timeout, stop)
    if refused is not None:
        return refused
    try:
        print(_greeting(fleet, world_file), flush=True)
        await stop.wait()
    finally:
        await fleet.stop()
    return EXIT_OK


async def _start(fleet: SimFleet, connect_timeout: float, stop: asyncio.Event) -> int | None:
    """Connect the fleet, trying again for `connect_timeout` seconds while the
    server is unreachable; None once connected, else the exit code (said)."""
    from backend.agent import AlreadyConnected
    from backend.transport.session import LoginRefused, TransportError, TransportUnreachable

    deadline = time.monotonic() + max(0.0, connect_timeout)
    while True:
        try:
            await fleet.start()
            return None
        except TransportUnreachable as e:
            if isinstance(e, LoginRefused) or time.monotonic() >= deadline or stop.is_set():
                print(f"missionctl sim: {e}", file=sys.stderr)
                return EXIT_UNREACHABLE
            try:
                await asyncio.wait_for(stop.wait(), 0.5)
            except TimeoutError:
                pass
        except TransportError as e:
            print(f"missionctl sim: {e}", file=sys.stderr)
            return EXIT_UNREACHABLE
        except AlreadyConnected as e:  # another sim (or robot) holds these robots
            print(f"missionctl sim: {e}", file=sys.stderr)
            return EXIT_REFUSED


def _greeting(fleet: SimFleet, world_file: Path) -> str:
    w = fleet.world
    delay = f", link delay {fleet.link_delay:g} s (sim time)" if fleet.link_delay else ""
    if fleet.comms_window is not None:
        delay += f", comms windows: {fleet.comms_window.describe()}"
    return (
        f"missionctl sim: world '{w.spec.name}' ({world_file}), seed {w.seed}, robots "
        f"{', '.join(fleet.agents)}; speed {fleet.speed:g}x{delay}; "
        f"connected to {', '.join(fleet.connect)}"
    )


# ---------------------------------------------------------------- sim-status


def run_status(args: argparse.Namespace) -> int:
    return asyncio.run(_status(args))


async def _status(args: argparse.Namespace) -> int:
    from backend import transport
    from backend.protocol import mapfeed as mf
    from backend.transport.session import TransportUnreachable
    from backend.transport.timeouts import query_timeout

    endpoints = args.connect or ["tcp/127.0.0.1:7447"]
    try:
        login = login_from_args(args)
    except AccountsError as e:
        print(f"missionctl sim-status: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    extra = login.zenoh_options()
    timeout = query_timeout(args.timeout, login.link_delay_hint)
    try:
        session = await asyncio.to_thread(
            transport.open_session, transport.client_config(endpoints, extra=extra)
        )
    except TransportUnreachable as e:
        print(f"missionctl sim-status: {e}", file=sys.stderr)
        return EXIT_UNREACHABLE
    try:
        try:
            payload = mf.TRUTH_QUERY if args.truth else b""
            raw = await transport.query(session, mf.KEY_STATUS, payload, timeout=timeout)
        except transport.NoResponder:
            print(
                f"missionctl sim-status: no simulator answers at {', '.join(endpoints)}",
                file=sys.stderr,
            )
            return EXIT_REFUSED
        except transport.QueryFailed as e:
            print(f"missionctl sim-status: {e}", file=sys.stderr)
            return EXIT_REFUSED
        status = mf.SimStatus.model_validate_json(raw)
    finally:
        await asyncio.to_thread(transport.close_session, session)
    if args.json:
        print(status.model_dump_json(indent=2))
        return EXIT_OK
    print(format_status(status))
    return EXIT_OK


def format_status(st: mf.SimStatus) -> str:
    """The ground view (what the robots reported), then the truth if it is there."""
    lines = [
        f"world {st.world} (seed {st.seed}), sim time {_clock(st.sim_time)} at {st.speed:g}x"
        + (f", link delay {st.link_delay_s:g} s" if st.link_delay_s else ""),
        "as reported by the robots:",
        f"score {st.score:g}: {len(st.delivered)} stone(s) delivered",
        *_deliveries(st.delivered),
        "regions found: "
        + (", ".join(_region(n, st.top_scores.get(n)) for n in st.rss_found) or "none")
        + f"; explored {st.explored:.1%} of the site",
        "robots (as last heard):",
    ]
    for r in st.robots.values():
        lines += _robot_lines(r, st.sim_time)
    if st.truth is not None:
        lines += _truth_lines(st.truth)
    return "\n".join(lines)


def _clock(seconds: float) -> str:
    return f"{seconds:.0f} s ({int(seconds // 60)}:{int(seconds % 60):02d})"


def _deliveries(delivered: list[mf.Delivery]) -> list[str]:
    return [f"  {d.stone} ({d.rss}) {d.score:g} by {d.by} at {d.sim_time:.0f} s" for d in delivered]


def _region(name: str, top: float | None) -> str:
    return f"{name} (top {top:g})" if top is not None else name


def _robot_lines(r: mf.RobotStatus, now: float) -> list[str]:
    flags = _flags(r, now)
    lines = [
        f"  {r.name:<8} {r.kind:<6} ({r.x:7.1f}, {r.y:7.1f})  "
        f"battery {r.battery:4.0%}  link {r.link:.2f}  "
        f"{r.activity or 'idle'}{'  [' + '; '.join(flags) + ']' if flags else ''}"
    ]
    if r.result:
        lines.append(f"           last: {r.result}")
    return lines


def _flags(r: mf.RobotStatus, now: float) -> list[str]:
    """What is worth knowing about a robot beyond its place, battery and activity."""
    flags = []
    if not r.in_range:
        age = f", last heard {now - r.heard_at:.0f} s ago" if r.heard_at is not None else ""
        flags.append(f"OUT OF RANGE{age}")
    if r.airborne:
        flags.append(f"airborne {r.z:.0f} m")
    if r.docked:
        flags.append("docked")
    if r.box:
        flags.append(f"carries {r.box}")
    if r.stones:
        flags.append(f"stones {', '.join(r.stones)}")
    return flags


def _truth_lines(tr: mf.SimTruth) -> list[str]:
    lines = [
        "TRUTH (for evaluation; the operator cannot know this):",
        f"score {tr.score:g}: {len(tr.delivered)} stone(s) delivered",
        *_deliveries(tr.delivered),
        f"explored {tr.explored:.1%} of the site",
        "regions:",
    ]
    for g in sorted(tr.regions, key=lambda g: -g.max_score):
        found = f"found by {', '.join(g.found_by)}" if g.found_by else "not found"
        lines.append(
            f"  {g.rss:<6} ({g.x:6.1f}, {g.y:6.1f}) r {g.radius:g}  top {g.max_score:g}  "
            f"{g.stones} stone(s) left  {found}"
        )
    lines.append("robots:")
    for r in tr.robots.values():
        lines += _robot_lines(r, r.heard_at or 0.0)
    lines.append("exchanges: " + ", ".join(f"{k} {v}" for k, v in sorted(tr.exchanges.items())))
    if tr.events:
        lines.append("recent:")
        lines += [f"  {e}" for e in tr.events[-8:]]
    return lines


def _dump(obj: Any) -> str:  # pragma: no cover - debugging aid
    return json.dumps(obj, indent=2, default=str)
