"""ctl for the team (issue 30): `robots add NAME`, `robots retire NAME
--reason TEXT` and `reassign ID... --to ROBOT` / `reassign --from ROBOT --to
ROBOT` (arguments, builders and their one-line outcomes)."""

from __future__ import annotations

import argparse
from typing import Any

from pydantic import ValidationError

from backend.cli.ctl.errors import UsageError
from backend.cli.ctl.values import check_name
from backend.core import ops

# ---------------------------------------------------------------- arguments


def robots_arguments(p: argparse.ArgumentParser, common: Any) -> None:
    """`robots` alone lists them; `robots add NAME`, `robots retire NAME --reason R`."""
    actions = p.add_subparsers(dest="robots_op", metavar="ACTION")
    add = actions.add_parser(
        "add",
        help="add a robot that asks to join (or --type TYPE: one to come)",
        description="add a robot to the mission: one the server announced (it registered "
        "under a new name with a type the library knows), or one to come (--type)",
    )
    common(add, top=False)
    add.add_argument("name", metavar="NAME")
    add.add_argument("--type", dest="robot_type", metavar="TYPE", help="default: its manifest's")
    retire = actions.add_parser(
        "retire",
        help="retire a robot: no new syncs, its queue taken back, its plan to reassign",
        description="retire a robot: no new syncs; its queued skills are taken back (by its "
        "uplink, or on the ground while it is out of reach); its log stays",
    )
    common(retire, top=False)
    retire.add_argument("name", metavar="NAME")
    retire.add_argument("--reason", required=True, metavar="TEXT", help="why (journaled)")


def reassign_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("ids", nargs="*", metavar="ID", help="idle skills to give")
    p.add_argument("--from", dest="from_robot", metavar="ROBOT", help="its whole plan")
    p.add_argument("--to", required=True, metavar="ROBOT", help="the robot to give them to")


def suggest_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "what", nargs="+", metavar="SKILL_OR_ID", help="skill ids, or one skill of the library"
    )


# ---------------------------------------------------------------- builders


def build_robots(args: argparse.Namespace, known: Any) -> Any:
    """None for `robots` alone (a view); else the operation."""
    action = getattr(args, "robots_op", None)
    if action is None:
        return None
    check_name(args.name, "NAME")
    if action == "retire":
        return ops.RetireRobot(name=args.name, reason=_reason(args.reason))
    robot_type = args.robot_type or getattr(args, "joining_type", None)
    if robot_type is None:
        if known.mission is None:  # before connecting: the server's fleet says
            return None
        raise UsageError(
            f"robots add: {args.name} has not asked to join (no registration under that "
            "name); give its type with --type TYPE to add a robot to come"
        )
    check_name(robot_type, "TYPE")
    return ops.AddRobot(name=args.name, type=robot_type)


def _reason(text: str) -> str:
    reason = text.strip()
    if not reason or len(reason) > 500:
        raise UsageError("robots retire: --reason must say why in 1 to 500 characters")
    return reason


def build_reassign(args: argparse.Namespace, known: Any) -> Any:
    if args.from_robot is not None:
        check_name(args.from_robot, "ROBOT")
    check_name(args.to, "ROBOT")
    if not args.ids and args.from_robot is None:
        raise UsageError("reassign: give skill ids, or --from ROBOT (its whole plan)")
    try:
        return ops.Reassign(ids=list(args.ids), from_robot=args.from_robot, to=args.to)
    except ValidationError as e:
        bad = e.errors()[0].get("input")
        raise UsageError(f"reassign: {bad!r} is not a skill id") from None


def joining_type(client: Any, name: str) -> str | None:
    """The type a robot that asks to join registered with."""
    info = client.robots.get(name)
    if info is None or info.manifest is None or not info.joining:
        return None
    return str(info.manifest.type)


# ---------------------------------------------------------------- outcomes


def added(o: Any) -> str:
    return f"added robot {o.op.name} ({o.op.type}) to the mission {o.at}"


def retired(o: Any) -> str:
    plan = o.value.get("to_reassign") or []
    rest = f"; its plan to reassign: {', '.join(plan)}" if plan else "; its plan is empty"
    return f"retired robot {o.op.name} ({o.op.reason}){rest} {o.at}"


def reassigned(o: Any) -> str:
    moved = o.value.get("moved") or []
    stays = o.value.get("refused") or {}
    kept = f"; {len(stays)} stay (see the notes)" if stays else ""
    return f"gave {', '.join(moved)} to {o.op.to}{kept} {o.at}"


DESCRIBE = {"robot_add": added, "robot_retire": retired, "reassign": reassigned}
