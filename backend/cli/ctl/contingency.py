"""ctl's contingency options (add, edit): --skill-timeout, --not-after,
--on-failure, --on-timeout, read into Policies fields. (`--timeout` is
already every ctl command's wait for the server, in seconds.)"""

from __future__ import annotations

import argparse
from typing import Any

from backend.core.contingency import BRANCH_SYNTAX, read_branch, read_instant, read_seconds
from backend.core.model import Branch


def mission_seconds(text: str) -> float | None:
    """'10m', '1.5h', '90' -> seconds; 'off' -> None."""
    seconds = read_seconds(text)
    if isinstance(seconds, str):
        raise argparse.ArgumentTypeError(seconds)
    return seconds


def mission_instant(text: str) -> float | None:
    """'sim 2:00:00', '2h' (sim time), '2030-07-01 14:32' (UTC) -> mission-clock seconds."""
    at = read_instant(text)
    if isinstance(at, str):
        raise argparse.ArgumentTypeError(at)
    return at


def branch(text: str) -> Branch:
    """A branch as Policies takes it."""
    found = read_branch(text)
    if found is None:
        raise argparse.ArgumentTypeError(f"expected {BRANCH_SYNTAX}, got {text!r}")
    return found


def add_options(g: argparse._ArgumentGroup) -> None:
    g.add_argument(
        "--skill-timeout",
        dest="skill_timeout",
        type=mission_seconds,
        metavar="DURATION",
        default=argparse.SUPPRESS,
        help="mission time the skill may run, retries included (10m; 'off'); then --on-timeout",
    )
    g.add_argument(
        "--not-after",
        dest="not_after",
        type=mission_instant,
        metavar="TIME",
        default=argparse.SUPPRESS,
        help="mission-clock deadline: sim 2:00:00 (or 2h of sim time) with a simulator, "
        "a UTC time 2030-07-01 14:32 on a real mission; 'off'",
    )
    g.add_argument(
        "--after",
        type=lambda t: None if t.strip().lower() in ("off", "none") else t.strip(),
        metavar="SKILL",
        default=argparse.SUPPRESS,
        help="start only once this skill of another robot succeeded ('off')",
    )
    for trigger, when in (("failure", "after a failure"), ("timeout", "at the timeout")):
        g.add_argument(
            f"--on-{trigger}",
            dest=f"on_{trigger}",
            type=branch,
            metavar="BRANCH",
            default=argparse.SUPPRESS,
            help=f"what the robot does {when}, on board: {BRANCH_SYNTAX}",
        )


def given(args: argparse.Namespace) -> dict[str, Any]:
    """The contingency fields the command line names."""
    names = {"skill_timeout": "timeout", "not_after": "not_after"}
    names |= {"on_failure": "on_failure", "on_timeout": "on_timeout", "after": "after"}
    return {field: getattr(args, k) for k, field in names.items() if hasattr(args, k)}


def add_after_args(p: argparse.ArgumentParser) -> None:
    """ctl after ID SKILL: the same as `edit ID --after SKILL` ('off' clears it)."""
    p.add_argument("id", metavar="ID")
    p.add_argument("after", metavar="SKILL", help="the other robot's skill ('off': no more)")


def add_barrier_args(p: argparse.ArgumentParser) -> None:
    """ctl barrier ID ID... (a new barrier) or ctl barrier BARRIER_ID (change
    one), each with how long its robots wait for each other."""
    p.add_argument(
        "ids", nargs="+", metavar="ID", help="skills of different robots, or one barrier's id"
    )
    p.add_argument(
        "--barrier-timeout",
        dest="barrier_timeout",
        type=mission_seconds,
        metavar="DURATION",
        default=argparse.SUPPRESS,
        help="mission time a robot waits at the barrier for its partners (10m; 'off': for ever)",
    )
    p.add_argument(
        "--on-timeout",
        dest="barrier_on_timeout",
        choices=("continue", "halt"),
        default=argparse.SUPPRESS,
        help="then, on board: start alone (continue) or fail the skill (halt, the default)",
    )


def barrier_waiting(args: argparse.Namespace, current: Any = None) -> dict[str, Any]:
    """timeout and on_timeout as the command line names them, the rest as
    `current` (a barrier being changed) has them."""
    out = {"timeout": getattr(current, "timeout", None)}
    out["on_timeout"] = getattr(current, "on_timeout", "halt")
    if hasattr(args, "barrier_timeout"):
        out["timeout"] = args.barrier_timeout
    if hasattr(args, "barrier_on_timeout"):
        out["on_timeout"] = args.barrier_on_timeout
    return out
