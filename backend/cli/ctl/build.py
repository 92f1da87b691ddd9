"""ctl's operations: the command line -> an operation of backend.core.ops.

One small builder per operation name in BUILDERS; adding an operation to ctl
is a subparser (args), a builder here and a line in render.DESCRIBE.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from backend.cli.ctl.args import CONTROL_OPS
from backend.cli.ctl.contingency import barrier_waiting
from backend.cli.ctl.contingency import given as given_contingency
from backend.cli.ctl.errors import FileInvalid, UsageError
from backend.cli.ctl.questions import build_answer
from backend.cli.ctl.team import build_reassign, build_robots
from backend.cli.ctl.values import (
    AtMarker,
    check_name,
    param_value,
    parse_area,
    parse_params,
    parse_pose,
    parse_position,
)
from backend.core import ops
from backend.core.model import AreaMarker, Policies, Pose, PoseMarker, Position, PositionMarker
from backend.core.params import KINDS


@dataclass(frozen=True)
class Known:
    """What the server told us: both None before connecting (the command line
    alone is checked then)."""

    library: Any = None
    mission: Any = None


Builder = Callable[[argparse.Namespace, Known], Any]


def _param_spec(library: Any, mission: Any, robot: str | None, skill: str | None, name: str) -> Any:
    if library is None or mission is None or robot is None or skill is None:
        return None
    spec = mission.robots.get(robot)
    if spec is None:
        return None
    sk = library.skill_for(spec.type, skill)
    return sk.params.get(name) if sk else None


def _resolve(
    parsed: dict[str, Any], library: Any, mission: Any, robot: str | None, skill: str | None
) -> tuple[dict[str, Any], dict[str, str]]:
    """Split parsed params into values and marker bindings, by parameter type."""
    params: dict[str, Any] = {}
    bindings: dict[str, str] = {}
    for name, value in parsed.items():
        pspec = _param_spec(library, mission, robot, skill, name)
        if not isinstance(value, AtMarker):
            params[name] = param_value(name, value, pspec)  # angles: degrees -> radians
            continue
        kind = KINDS.get(pspec.type) if pspec is not None else None
        if pspec is None or (kind is not None and kind.bindable_to):
            bindings[name] = value.name  # unknown: the server names the problem
        elif pspec.type == "marker":
            params[name] = value.name
        else:  # a plain string that happens to start with '@'
            params[name] = f"@{value.name}"
    return params, bindings


def _given_policies(args: argparse.Namespace) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if getattr(args, "retries", None) is not None:
        out["retries"] = args.retries
    if getattr(args, "pause_out_of_comms", None) is not None:
        out["pause_out_of_comms"] = args.pause_out_of_comms
    if hasattr(args, "recharge_below"):
        out["recharge_below"] = args.recharge_below
    return out | given_contingency(args)


def _validated(model: type, what: str, **fields: Any) -> Any:
    """Build an operation; a field the protocol refuses is a usage error."""
    from pydantic import ValidationError

    try:
        return model(**fields)
    except ValidationError as e:
        err = e.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        value = err.get("input")
        msg = err["msg"]
        if err["type"] == "string_pattern_mismatch":
            msg = "not a valid name or id (letters, digits, '_', '-', '.')"
        raise UsageError(f"{what}: {loc + ': ' if loc else ''}{value!r}: {msg}") from None


def _no_operation(args: argparse.Namespace, known: Known) -> None:
    """state, robots, pending, watch and save send no operation: only names are checked."""
    for r in getattr(args, "robots", None) or []:
        check_name(r, "ROBOT")


def _add(args: argparse.Namespace, known: Known) -> Any:
    check_name(args.robot, "ROBOT")
    check_name(args.skill, "SKILL")
    params, bindings = _resolve(
        parse_params(args.param), known.library, known.mission, args.robot, args.skill
    )
    given = _given_policies(args)
    policies = _validated(Policies, "policies", **given) if given else None
    return _validated(
        ops.AddSkill,
        "add",
        robot=args.robot,
        skill=args.skill,
        label=args.label or "",
        params=params,
        bindings=bindings,
        policies=policies,
        at=args.at,
    )


def _delete(args: argparse.Namespace, known: Known) -> Any:
    return _validated(ops.DeleteSkills, "delete", ids=args.ids)


def _move(args: argparse.Namespace, known: Known) -> Any:
    if args.index < 0:
        raise UsageError(f"move: INDEX must be 0 or more, got {args.index}")
    return _validated(ops.MoveSkill, "move", id=args.id, index=args.index)


def _unbinds(args: argparse.Namespace, parsed: dict[str, Any]) -> list[str]:
    unbind = list(dict.fromkeys(args.unbind or []))
    for u in unbind:
        check_name(u, "--unbind")
        if u in parsed:
            raise UsageError(f"--unbind {u} and --param {u}=... contradict each other")
    return unbind


def _edit(args: argparse.Namespace, known: Known) -> Any:
    parsed = parse_params(args.param)
    unbind = _unbinds(args, parsed)
    given = _given_policies(args)
    if args.label is None and not parsed and not unbind and not given:
        raise UsageError(
            "edit: nothing to change (give --label, --param, --unbind or a policy option)"
        )
    found = known.mission.find(args.id) if known.mission is not None else None
    robot, skill = (found[0], found[2].skill) if found else (None, None)
    params, bindings = _resolve(parsed, known.library, known.mission, robot, skill)
    all_bindings: dict[str, str | None] = {**bindings, **dict.fromkeys(unbind)}
    policies = None
    if given:  # the policies the command line does not name stay as they are
        base = found[2].policies.model_dump() if found else {}
        policies = _validated(Policies, "policies", **{**base, **given})
    return _validated(
        ops.EditSkill,
        "edit",
        id=args.id,
        label=args.label,
        params=params,
        bindings=all_bindings,
        policies=policies,
    )


def _after(args: argparse.Namespace, known: Known) -> Any:
    """ctl after ID SKILL: edit ID's policies.after, the rest kept."""
    found = known.mission.find(args.id) if known.mission is not None else None
    base = found[2].policies.model_dump() if found else {}
    after = None if args.after.strip().lower() in ("off", "none") else args.after.strip()
    policies = _validated(Policies, "policies", **{**base, "after": after})
    return _validated(ops.EditSkill, "after", id=args.id, policies=policies)


def _expire(args: argparse.Namespace) -> dict[str, Any]:
    """--expire D: seconds (0: never); not given: the server's default."""
    return {} if getattr(args, "expire", None) is None else {"expire_s": args.expire}


def _sync(args: argparse.Namespace, known: Known) -> Any:
    check_name(args.robot, "ROBOT")
    return _validated(ops.Sync, "sync", robot=args.robot, through=args.through, **_expire(args))


def _unsync(args: argparse.Namespace, known: Known) -> Any:
    check_name(args.robot, "ROBOT")
    return _validated(ops.Unsync, "unsync", robot=args.robot, from_id=args.from_id, **_expire(args))


def _control(args: argparse.Namespace, known: Known) -> Any:
    name = args.op
    if args.all == (args.robot is not None):
        raise UsageError(f"{name}: give a ROBOT or --all (not both)")
    if args.robot is not None:
        check_name(args.robot, "ROBOT")
    return _validated(ops.Control, name, op=name, robot=args.robot, **_expire(args))


def _retry(args: argparse.Namespace, known: Known) -> Any:
    return _validated(ops.Retry, "retry", id=args.id, **_expire(args))


def _cancel(args: argparse.Namespace, known: Known) -> Any:
    return _validated(ops.Cancel, "cancel", command=args.command)


def _barrier(args: argparse.Namespace, known: Known) -> Any:
    if len(args.ids) == 1:  # a barrier's id: its wait changes
        return _barrier_edit(args, args.ids[0], known.mission)
    return _validated(ops.AddBarrier, "barrier", ids=args.ids, **barrier_waiting(args))


def _barrier_edit(args: argparse.Namespace, bid: str, m: Any) -> Any:
    if not {"barrier_timeout", "barrier_on_timeout"} & set(vars(args)):
        raise UsageError(
            "barrier: give the ids of at least two skills of different robots, or one "
            "barrier's id with --barrier-timeout or --on-timeout"
        )
    if m is not None and bid not in m.barriers:
        raise UsageError(
            f"barrier: {bid} is no barrier (barriers: {', '.join(m.barriers) or 'none'}); "
            "give a barrier's id, or the ids of at least two skills of different robots"
        )
    current = m.barriers[bid] if m is not None else None
    return _validated(ops.EditBarrier, "barrier", barrier=bid, **barrier_waiting(args, current))


def _unbarrier(args: argparse.Namespace, known: Known) -> Any:
    return _validated(ops.RemoveBarrier, "unbarrier", barrier=args.barrier)


def _geometry_value(args: argparse.Namespace) -> tuple[str, Any]:
    if args.pose is not None:
        return "pose", parse_pose(args.pose)
    if args.position is not None:
        return "position", parse_position(args.position)
    return "area", parse_area(args.area)


# --pose / --position / --area -> a new marker (value, description)
_NEW_MARKER: dict[str, Callable[[Any, str], Any]] = {
    "pose": lambda v, d: PoseMarker(pose=Pose(**v), description=d),
    "position": lambda v, d: PositionMarker(position=Position(**v), description=d),
    "area": lambda v, d: AreaMarker(area=[Position(**p) for p in v], description=d),
}


def _marker_add(args: argparse.Namespace, known: Known) -> Any:
    kind, value = _geometry_value(args)
    marker = _NEW_MARKER[kind](value, args.description)
    return _validated(ops.MarkerAdd, "marker add", name=args.name, marker=marker)


def _marker_move(args: argparse.Namespace, known: Known) -> Any:
    kind, value = _geometry_value(args)
    current = known.mission.markers.get(args.name) if known.mission is not None else None
    new: Any
    if kind == "pose":
        new = Pose(**value)
    elif kind == "position" and current is not None and current.kind == "pose":
        o = current.pose  # a pose marker given a position keeps its orientation
        new = Pose(**value, roll=o.roll, pitch=o.pitch, yaw=o.yaw)
    elif kind == "position":
        new = Position(**value)
    else:
        new = [Position(**p) for p in value]
    return _validated(ops.MarkerMove, "marker move", name=args.name, value=new)


def _marker_rename(args: argparse.Namespace, known: Known) -> Any:
    check_name(args.new_name, "NEW_NAME")
    return _validated(ops.MarkerRename, "marker rename", name=args.name, new_name=args.new_name)


def _marker_delete(args: argparse.Namespace, known: Known) -> Any:
    return _validated(ops.MarkerDelete, "marker delete", name=args.name)


MARKER_BUILDERS: dict[str, Builder] = {
    "add": _marker_add,
    "move": _marker_move,
    "rename": _marker_rename,
    "delete": _marker_delete,
}


def _marker(args: argparse.Namespace, known: Known) -> Any:
    check_name(args.name, "NAME")
    return MARKER_BUILDERS[args.marker_op](args, known)


def _load(args: argparse.Namespace, known: Known) -> Any:
    from backend.files.diagnostics import FileProblems
    from backend.files.missions import load_mission

    loaded = getattr(args, "loaded", None)
    if loaded is None:
        try:
            loaded = load_mission(args.file)
        except FileProblems as e:
            raise FileInvalid(args.file, e.issues) from None
        args.loaded = loaded  # (mission, library): read the file once
    return ops.LoadMission(mission=loaded[0].copy_deep(), keep_state=args.keep_state)


def _new(args: argparse.Namespace, known: Known) -> Any:
    return _validated(ops.NewMission, "new", name=args.name)


def _undo(args: argparse.Namespace, known: Known) -> Any:
    return ops.Undo()


def _redo(args: argparse.Namespace, known: Known) -> Any:
    return ops.Redo()


# ctl's operation name -> its builder (None: `ctl` alone, refused before this)
BUILDERS: dict[str | None, Builder] = {
    **dict.fromkeys(("state", "pending", "watch", "save", None), _no_operation),
    "robots": build_robots,
    "reassign": build_reassign,
    **dict.fromkeys(("check", "timeline", "history", "wait", "suggest"), _no_operation),
    "questions": _no_operation,
    "answer": build_answer,
    "add": _add,
    "delete": _delete,
    "move": _move,
    "edit": _edit,
    "sync": _sync,
    "unsync": _unsync,
    **dict.fromkeys(CONTROL_OPS, _control),
    "retry": _retry,
    "cancel": _cancel,
    "barrier": _barrier,
    "after": _after,
    "unbarrier": _unbarrier,
    "marker": _marker,
    "load": _load,
    "new": _new,
    "undo": _undo,
    "redo": _redo,
    "waive": lambda args, known: _validated(
        ops.Waive, "waive", check=args.check, reason=args.reason.strip()
    ),
    "unwaive": lambda args, known: _validated(ops.Unwaive, "unwaive", check=args.check),
}


def build_op(args: argparse.Namespace, library: Any = None, mission: Any = None) -> Any:
    """The operation `args` asks for (None for state/robots/pending/watch/save).

    Without `library`/`mission` (before connecting) only the command line is
    checked; with them, `@MARKER` values are resolved by parameter type and
    edits keep the policies they do not name. Raises UsageError / FileInvalid.
    """
    builder = BUILDERS.get(args.op)
    if builder is None:
        raise UsageError(f"unknown operation {args.op!r}")
    return builder(args, Known(library, mission))
