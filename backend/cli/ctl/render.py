"""ctl's output: state, robots, watch lines and what an operation did, as text and JSON.

Tables, not ladders: DESCRIBE (operation -> its one-line outcome), WATCH_TEXT
and WATCH_JSON (client message kind -> a line), EVENT_TEXT (event -> a phrase).
"""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from backend.cli.ctl.args import CONTROL_OPS
from backend.cli.ctl.clock import WALL, CtlClock
from backend.cli.ctl.clock import wall_time as _time
from backend.cli.ctl.questions import DESCRIBE as QUESTION_DESCRIBE
from backend.cli.ctl.questions import EVENT_TEXT as QUESTION_EVENT_TEXT
from backend.cli.ctl.team import DESCRIBE as TEAM_DESCRIBE
from backend.core.contact import sim_time_text
from backend.core.contingency import after_tags, awaited_by, marks, span_text, taken_text
from backend.core.model import on_board_text
from backend.core.params import POSE_FIELDS, POSITION_FIELDS, is_angle, pose_text, value_text
from backend.protocol.messages import RobotInfo

_GLYPHS = {
    "idle": ("○", "."),
    "idle_synchronized": ("●", "o"),
    "synchwaiting": ("⧗", "w"),
    "running": ("▶", ">"),
    "paused": ("‖", "|"),
    "success": ("✓", "+"),
    "failure": ("✗", "x"),
}


def unicode_ok() -> bool:
    enc = getattr(sys.stdout, "encoding", None) or "ascii"
    try:
        ("".join(g for g, _ in _GLYPHS.values()) + "—").encode(enc)
        return True
    except (UnicodeEncodeError, LookupError):
        return False


def glyph(status: str, unicode: bool = True) -> str:
    u, a = _GLYPHS.get(status, ("?", "?"))
    return u if unicode else a


def _num(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _is_pose(v: Any) -> bool:
    return (
        isinstance(v, dict)
        and bool(v)
        and set(v) <= set(POSE_FIELDS)
        and all(isinstance(x, int | float) for x in v.values())
    )


def _is_area(v: Any) -> bool:
    return (
        isinstance(v, list)
        and bool(v)
        and all(isinstance(p, dict) and set(p) <= set(POSITION_FIELDS) for p in v)
    )


def _pose_text(v: dict[str, Any]) -> str:
    """(x,y) and the other fields that are not 0, angles in degrees: `(3,4 yaw=90°)`."""
    return pose_text(v)


def _str_text(v: str) -> str:
    return v if v and re.fullmatch(r"[\w.\-@/]+", v) else json.dumps(v, ensure_ascii=False)


def short_value(v: Any, limit: int = 40, spec: Any = None) -> str:
    """A compact rendering of a parameter value for one line of `state`
    (with its spec: as a person reads it, angles in degrees)."""
    text = _value_text(v, spec)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _value_text(v: Any, spec: Any) -> str:
    if _is_angle_value(v, spec):
        return value_text(spec, v)
    if _is_pose(v):
        return _pose_text(v)
    if _is_area(v):
        return f"[{len(v)} points]"
    if isinstance(v, str):
        return _str_text(v)
    return json.dumps(v, separators=(",", ":"), ensure_ascii=False)


def _is_angle_value(v: Any, spec: Any) -> bool:
    return spec is not None and is_angle(spec) and isinstance(v, int | float)


def _differs_from_default(library: Any, skill: str, name: str, value: Any) -> bool:
    if library is None:
        return True
    spec = library.skills.get(skill)
    pspec = spec.params.get(name) if spec else None
    if pspec is None or pspec.default is None:
        return True
    from backend.core.params import normalize_value

    try:
        return normalize_value(pspec, pspec.default) != value
    except Exception:
        return True


def _spec_of(library: Any, skill: str, name: str) -> Any:
    spec = library.skills.get(skill) if library is not None else None
    return spec.params.get(name) if spec is not None else None


def short_params(s: Any, library: Any) -> str:
    parts = []
    for name, value in s.params.items():
        if name in s.bindings:
            parts.append(f"{name}=@{s.bindings[name]}")
        elif _differs_from_default(library, s.skill, name, value):
            parts.append(f"{name}={short_value(value, spec=_spec_of(library, s.skill, name))}")
    for name, marker in s.bindings.items():
        if name not in s.params:
            parts.append(f"{name}=@{marker}")
    return " ".join(parts)


def mission_time_text(clock: str, t: float) -> str:
    """A time on the mission clock: `sim 2:00:00` (sim time), or the wall's (local):
    `16:51:46` today, `2026-11-28 00:00:00` another day."""
    if clock == "sim":
        return f"sim {sim_time_text(t)}"
    at = datetime.fromtimestamp(t, UTC)
    day = at.astimezone().date()
    return _time(at) if day == datetime.now().astimezone().date() else f"{day} {_time(at)}"


def _contact(c: Any) -> str:
    """`in contact until sim 0:20:00`, `out of contact: window closed, next contact sim 2:00:00`."""
    if c.state == "out_of_contact":
        if c.next_contact is None:
            return "out of contact: window closed, no window ahead"
        nxt = mission_time_text(c.clock, c.next_contact)
        return f"out of contact: window closed, next contact {nxt}"
    until = f" until {mission_time_text(c.clock, c.closes)}" if c.closes is not None else ""
    return f"in contact{until}"


def _presence(info: Any, clock: CtlClock = WALL) -> str:
    """Whether the server knows a robot, hears it, and its contact."""
    if info is None:
        return "not registered"
    if info.joining:  # it is heard: not "offline", but not in the mission
        asked = f" since {clock.stamp(info.since)}" if info.since else ""
        return f"waiting to be added{asked}"
    if not info.online:
        return _offline(info, clock)
    if info.contact is not None and info.contact.state == "out_of_contact":
        return _out_of_contact(info, clock)  # never "online" then
    return _online(info, clock)


def _offline(info: Any, clock: CtlClock) -> str:
    if info.since:
        return f"offline since {clock.stamp(info.since)}"
    return "offline (not seen since the server started)"


def _out_of_contact(info: Any, clock: CtlClock) -> str:
    """`out of contact: ... (present since 12:00:01)`."""
    present = f" (present since {clock.stamp(info.since)})" if info.since else ""
    return _contact(info.contact) + present


def _online(info: Any, clock: CtlClock) -> str:
    """`online since 12:00:01, in contact until sim 0:20:00`."""
    online = f"online since {clock.stamp(info.since)}" if info.since else "online"
    c = info.contact
    return online + (f", {_contact(c)}" if c is not None and c.state != "offline" else "")


def _marker_text(mk: Any) -> str:
    if mk.kind == "pose":
        text = "pose " + short_value(mk.pose.model_dump())
    elif mk.kind == "position":
        text = "position " + short_value(mk.position.model_dump())
    else:
        pts = " ".join(
            f"{_num(p.x)},{_num(p.y)}" + (f",{_num(p.z)}" if p.z else "") for p in mk.area
        )
        text = f"area {pts}"
    origin = on_board_text(mk)  # a place chosen on board says so, never silently
    return (
        text
        + (f"  {mk.description}" if mk.description else "")
        + (f"  [{origin}]" if origin else "")
    )


def _shown(robot: str, only: list[str] | None) -> bool:
    return not only or robot in only


def _iso(t: datetime | None) -> str | None:
    return t.isoformat() if t else None


def _since(t: datetime | None, now: datetime) -> float | None:
    return (now - t).total_seconds() if t is not None else None


def command_line(c: Any, now: datetime, client: Any = None, clock: CtlClock = WALL) -> str:
    """One pending (or settled) command: `17 lru1 sync lru1-1, lru1-2: sent 12 s ago ...`."""
    what = f"{c.op} {', '.join(c.skills)}" if c.skills else c.op
    if c.state.value == "queued":
        when = f"queued {clock.age(c.created, now)} ago, not sent yet"
    elif c.state.value == "sent":
        when = f"sent {clock.age(c.sent, now)} ago, no answer yet"
    else:
        when = f"{c.state.value} {clock.stamp(c.settled)}" + (f": {c.reason}" if c.reason else "")
    extra = _command_notes(c, now, clock) + _stage_note(client, c, now, clock)
    tail = f" [{'; '.join(extra)}]" if extra else ""
    return f"command {c.id} to {c.robot} (seq {c.seq}): {what}: {when}{tail}"


def _command_notes(c: Any, now: datetime, clock: CtlClock) -> list[str]:
    extra = []
    if c.expires is not None and c.pending:
        passed = " (passed)" if c.expires <= now else ""
        extra.append(f"expires {clock.stamp(c.expires)}{passed}")
    if c.cancel_requested and c.pending:
        extra.append("cancel requested")
    return extra


def _stage_note(client: Any, c: Any, now: datetime, clock: CtlClock) -> list[str]:
    """The stage it waits for, with its due (the server's verification)."""
    from backend.cli.ctl.verify import stage_text

    text = stage_text(client, c, now, clock) if client is not None else ""
    return [text] if text else []


def command_json(c: Any, now: datetime, client: Any = None) -> dict[str, Any]:
    from backend.cli.ctl.verify import stages_json

    return {
        **c.model_dump(mode="json", exclude={"command"}),
        "age_s": _since(c.created, now),
        "sent_age_s": _since(c.sent, now),
        "stages": stages_json(client, c) if client is not None else None,
    }


def link_json(client: Any, name: str, now: datetime) -> dict[str, Any]:
    ls = client.link(name, now)
    return {
        "delay_s": ls.delay_s,
        "heard": _iso(ls.heard),
        "heard_age_s": ls.heard_age_s,
        "stale": ls.stale,
        "pending": [c.id for c in ls.pending],
    }


def link_text(client: Any, name: str, now: datetime, clock: CtlClock = WALL) -> str:
    """`delay 2.0 s, heard 3 s ago, 2 pending` (+ `stale: last known state`)."""
    ls = client.link(name, now)
    parts = []
    if ls.delay_s is not None:
        parts.append(f"delay {clock.fine(ls.delay_s)}")
    if ls.heard_age_s is not None:
        parts.append(f"heard {clock.duration(ls.heard_age_s)} ago")
    if ls.pending:
        parts.append(f"{len(ls.pending)} pending")
    if ls.stale and ls.online:
        parts.append("stale: last known state")
    return ", ".join(parts)


# ---------------------------------------------------------------- state --json


def _robot_json(client: Any, name: str, now: datetime | None = None) -> dict[str, Any]:
    spec = client.mission.robots.get(name)
    # a robot the server never heard of: offline, no manifest, no contact
    info = client.robots.get(name) or RobotInfo.model_construct(name=name)
    manifest = info.manifest
    rtype, kind = _robot_type(client, spec, manifest)
    return {
        "type": rtype,
        "kind": kind,
        "in_mission": spec is not None,
        "joining": info.joining,
        "retired": spec.retired if spec else "",
        "online": info.online,
        "since": _iso(info.since),
        "contact": info.contact.model_dump(mode="json") if info.contact else None,
        "manifest": manifest.model_dump(mode="json") if manifest else None,
        "link": link_json(client, name, now or datetime.now(UTC)),
    }


def _robot_type(client: Any, spec: Any, manifest: Any) -> tuple[str | None, str | None]:
    """(type, its kind): the mission's, else what the robot registered with."""
    rtype = spec.type if spec else (manifest.type if manifest else None)
    rt = client.library.robot_types.get(rtype) if rtype else None
    return rtype, (rt.kind if rt else None)


def _skill_json(
    m: Any,
    s: Any,
    locks: dict[str, Any] | None = None,
    waits: dict[str, list[str]] | None = None,
) -> dict[str, Any]:
    c = (locks or {}).get(s.id)
    return {
        "uplink": {"command": c.id, "op": c.op, "state": c.state.value} if c else None,
        "id": s.id,
        "skill": s.skill,
        "label": s.label,
        "status": s.status.value,
        "status_info": s.status_info,
        "attempt": s.attempt,
        "params": s.params,
        "bindings": s.bindings,
        "policies": s.policies.model_dump(mode="json"),
        "barrier": m.barrier_of(s.id),
        "awaited_by": (waits or {}).get(s.id, []),  # skills that start after it
        "started_at": _iso(s.started_at),
        "finished_at": _iso(s.finished_at),
    }


def state_json(client: Any, only: list[str] | None = None) -> dict[str, Any]:
    m = client.mission
    now = datetime.now(UTC)
    return {
        "revision": m.revision,
        "name": m.name,
        "library": m.library,
        "server_id": client.server_id,
        "robots": _robots_json(client, now, only),
        "tasks": _tasks_json(m, only),
        "uplink": _uplink_json(m, now, only),
        **_barriers_json(m),
        "markers": {n: mk.model_dump(mode="json") for n, mk in m.markers.items()},
        "waivers": {c: w.model_dump(mode="json") for c, w in m.waivers.items()},
    }


def _robots_json(client: Any, now: datetime, only: list[str] | None) -> dict[str, Any]:
    """The mission's robots, then those only the server knows of."""
    m = client.mission
    names = list(m.robots) + [r for r in client.robots if r not in m.robots]
    return {n: _robot_json(client, n, now) for n in names if _shown(n, only)}


def _tasks_json(m: Any, only: list[str] | None) -> dict[str, list[dict[str, Any]]]:
    locks = m.command_locks()
    waits = awaited_by(m)
    return {
        r: [_skill_json(m, s, locks, waits) for s in task]
        for r, task in m.tasks.items()
        if _shown(r, only)
    }


def _uplink_json(m: Any, now: datetime, only: list[str] | None) -> dict[str, list[Any]]:
    return {
        r: [command_json(c, now) for c in cmds] for r, cmds in m.uplink.items() if _shown(r, only)
    }


def _barriers_json(m: Any) -> dict[str, Any]:
    return {
        "barriers": {bid: list(b.skills) for bid, b in m.barriers.items()},
        # how long each barrier's robots wait for each other (mission seconds; null: for ever)
        "barrier_waits": {
            bid: {"timeout": b.timeout, "on_timeout": b.on_timeout} for bid, b in m.barriers.items()
        },
    }


# ---------------------------------------------------------------- state (text)


def _policy_words(p: Any, unicode: bool = True) -> list[str]:
    words = []
    if p.retries:
        words.append(f"retries={p.retries}")
    if p.pause_out_of_comms:
        words.append("pause-out-of-comms")
    if p.recharge_below is not None:
        words.append(f"recharge<{p.recharge_below:g}")
    return words + marks(p, unicode)


def _skill_line(s: Any, columns: str, lib: Any, dash: str, pending: Any = None) -> str:
    """`columns`: glyph, id, label and skill already padded to the task's widths;
    `pending`: (command, now, clock) when a pending command concerns it."""
    parts = [columns]
    if pending is not None:
        parts.append(_pending_note(*pending))
    extra = short_params(s, lib)
    if extra:
        parts.append(extra)
    if s.attempt > 1:
        parts.append(f"(attempt {s.attempt})")
    if not s.policies.is_default():
        parts.append("{" + " ".join(_policy_words(s.policies, dash != "-")) + "}")
    if s.branch is not None:
        parts.append(f"[{taken_text(s.branch)}]")
    if s.status_info:
        parts.append(f"{dash} {s.status_info}")
    return "  ".join(parts).rstrip()


def _pending_note(c: Any, now: datetime, clock: CtlClock) -> str:
    """`(uplinking: command 3, sent 12 s ago)`: the command a skill waits for."""
    doing = {"sync": "uplinking", "retry": "retrying", "unsync": "unsynchronizing"}[c.op]
    since = c.sent if c.sent is not None else c.created
    verb = "sent" if c.sent is not None else "queued"
    return f"({doing}: command {c.id}, {verb} {clock.age(since, now)} ago)"


def _task_lines(m: Any, task: list[Any], lib: Any, unicode: bool, clock: CtlClock) -> list[str]:
    if not task:
        return ["  (no skills)"]
    locks = m.command_locks()
    now = datetime.now(UTC)
    dash = "—" if unicode else "-"
    return [
        _skill_line(s, columns, lib, dash, (locks[s.id], now, clock) if s.id in locks else None)
        for s, columns in zip(task, _task_columns(m, task, unicode), strict=True)
    ]


def _task_columns(m: Any, task: list[Any], unicode: bool) -> list[str]:
    """Each skill's glyph, id (with its barrier and after tags), label and skill, padded to
    the task's widths."""
    waits = awaited_by(m)
    ids = [_id_tags(m, s, waits.get(s.id, []), unicode) for s in task]
    wid = max(len(i) for i in ids)
    wlabel = max(len(s.label) for s in task)
    wskill = max(len(s.skill) for s in task)
    return [
        f"  {glyph(s.status.value, unicode)} {ident:<{wid}}  {s.label:<{wlabel}}  "
        f"{s.skill:<{wskill}}"
        for s, ident in zip(task, ids, strict=True)
    ]


def _id_tags(m: Any, s: Any, waiting: list[str], unicode: bool) -> str:
    """'lru2-4 [b1] [⇠lander-1]': the id, its barrier, both ends of an after."""
    bid = m.barrier_of(s.id)
    tags = ([bid] if bid else []) + after_tags(s.policies, waiting, unicode)
    return " ".join([s.id, *(f"[{t}]" for t in tags)])


def _robot_lines(client: Any, robot: str, unicode: bool, clock: CtlClock) -> list[str]:
    m, lib = client.mission, client.library
    dash = "—" if unicode else "-"
    now = datetime.now(UTC)
    link = link_text(client, robot, now, clock)
    presence = _presence(client.robots.get(robot), clock)
    head = f"{robot} ({_type_text(m, lib, robot)}) {dash} {presence}"
    pending = [f"  pending: {command_line(c, now, clock=clock)}" for c in m.pending_commands(robot)]
    return [
        head + (f"; {link}" if link else ""),
        *_task_lines(m, m.tasks.get(robot, []), lib, unicode, clock),
        *pending,
    ]


def _type_text(m: Any, lib: Any, robot: str) -> str:
    """A robot's type in the mission (`?`: not in it), `, static` for a static one."""
    spec = m.robots.get(robot)
    rtype = spec.type if spec else "?"
    kind = lib.robot_types[rtype].kind if rtype in lib.robot_types else ""
    return rtype + (", " + kind if kind == "static" else "")


def _barrier_line(m: Any) -> str:
    if not m.barriers:
        return "barriers: none"
    return "barriers: " + "; ".join(
        f"{bid} = {' + '.join(b.skills)}"
        + (f" (waits {_barrier_wait(b)})" if b.timeout is not None else "")
        for bid, b in m.barriers.items()
    )


def _marker_lines(m: Any) -> list[str]:
    if not m.markers:
        return ["markers: none"]
    w = max(len(n) for n in m.markers)
    return ["markers:", *(f"  {n:<{w}}  {_marker_text(mk)}" for n, mk in m.markers.items())]


def state_text(
    client: Any, only: list[str] | None = None, unicode: bool = True, clock: CtlClock = WALL
) -> str:
    m, lib = client.mission, client.library
    lines = [
        f"mission '{m.name}' at revision {m.revision} "
        f"(library '{lib.name}', {', '.join(client.endpoints)})"
    ]
    for robot in list(m.robots) + [r for r in m.tasks if r not in m.robots]:
        if _shown(robot, only):
            lines += _robot_lines(client, robot, unicode, clock)
    lines.append(_barrier_line(m))
    lines += _marker_lines(m)
    lines += [f"waived {c} at revision {w.revision}: {w.reason}" for c, w in m.waivers.items()]
    legend = ", ".join(f"{glyph(st, unicode)} {st}" for st in _GLYPHS)
    lines.append(f"({legend})")
    return "\n".join(lines)


# ---------------------------------------------------------------- robots


def robots_json(client: Any) -> dict[str, Any]:
    out = state_json(client)["robots"]
    now = datetime.now(UTC)
    for name, entry in out.items():
        t = client.telemetry.get(name)
        entry["telemetry"] = t.model_dump(mode="json") if t else None
        entry["pending_commands"] = [command_json(c, now, client) for c in client.pending(name)]
    return {"revision": client.revision, "robots": out}


def _telemetry_text(t: Any, info: Any = None) -> str:
    """`; battery 90%, link 99%, running explore 40%` (`; last known: ...` out of contact)."""
    out_of_range = "" if t.in_range else " (out of range)"
    c = info.contact if info is not None else None
    known = "last known: " if c is not None and c.state == "out_of_contact" else ""
    return f"; {known}battery {t.battery:.0%}, link {t.link:.0%}{out_of_range}, {_mode_text(t)}"


def _mode_text(t: Any) -> str:
    """`running explore 40%`: the mode, and the skill it executes."""
    if not t.skill:
        return t.mode
    return f"{t.mode} {t.skill}" + (f" {t.progress:.0%}" if t.progress is not None else "")


def _manifest_lines(man: dict[str, Any] | None) -> list[str]:
    if not man:
        return ["  (no manifest: never registered with this server)"]
    mods = [f"{x['name']} {x['version']}" for x in man["modules"]]
    skills = [f"{k} {v}" for k, v in man["skills"].items()]
    return [f"  modules: {_listed(mods)}", f"  skills:  {_listed(skills)}", *_properties(man)]


def _listed(items: list[str]) -> str:
    return ", ".join(items) or "none"


def _properties(man: dict[str, Any]) -> list[str]:
    """`  properties: arm=ur5, ...` (none: no line)."""
    props = [f"{k}={short_value(v)}" for k, v in man["properties"].items()]
    return ["  properties: " + ", ".join(props)] if props else []


def robots_text(client: Any, clock: CtlClock = WALL) -> str:
    data = robots_json(client)["robots"]
    if not data:
        return "no robots"
    return "\n".join(
        line for name, r in data.items() for line in _robot_block(client, name, r, clock)
    )


def _robot_block(client: Any, name: str, r: dict[str, Any], clock: CtlClock) -> list[str]:
    """A robot of `ctl robots`: presence, link and telemetry, manifest, pending commands."""
    presence = _presence(client.robots.get(name), clock)
    head = f"{name} ({r['type'] or '?'}{_standing(name, r)}): {presence}"
    t = client.telemetry.get(name)
    link = link_text(client, name, datetime.now(UTC), clock)
    head += (f"; {link}" if link else "") + (
        _telemetry_text(t, client.robots.get(name)) if t is not None else ""
    )
    now = datetime.now(UTC)
    return [
        head,
        *_manifest_lines(r["manifest"]),
        *(f"  pending: {command_line(c, now, clock=clock)}" for c in client.pending(name)),
    ]


def _standing(name: str, r: dict[str, Any]) -> str:
    """`, retired: ...`: where a robot stands with the mission (in it: nothing)."""
    if r["joining"]:
        return f", asks to join: missionctl ctl robots add {name}"
    if r["retired"]:
        return f", retired: {r['retired']}"
    return ", not in the mission" if not r["in_mission"] else ""


# ---------------------------------------------------------------- pending


def pending_json(client: Any, only: list[str] | None = None) -> dict[str, Any]:
    now = datetime.now(UTC)
    cmds = [c for c in client.pending() if _shown(c.robot, only)]
    return {
        "revision": client.revision,
        "pending": [command_json(c, now, client) for c in cmds],
        # applied, their skills not ended: verified until they are
        "executing": [command_json(c, now, client) for c in _executing(client, only)],
    }


def _executing(client: Any, only: list[str] | None) -> list[Any]:
    from backend.cli.ctl.verify import executing

    return [c for c in executing(client) if _shown(c.robot, only)]


def pending_text(client: Any, only: list[str] | None = None, clock: CtlClock = WALL) -> str:
    now = datetime.now(UTC)
    cmds = [c for c in client.pending() if _shown(c.robot, only)]
    cmds += _executing(client, only)
    if not cmds:
        return "no pending commands" + (f" for {', '.join(only)}" if only else "")
    return "\n".join(command_line(c, now, client, clock) for c in cmds)


# ---------------------------------------------------------------- describe


@dataclass(frozen=True)
class Outcome:
    """An applied operation, as `describe` sees it."""

    op: Any
    value: dict[str, Any]
    revision: int
    changed: bool  # the revision moved (or the request had been applied before)
    mission: Any  # the mission after it (None: unknown)
    clock: CtlClock = WALL  # the mission clock its times are said in

    @property
    def at(self) -> str:
        return f"at revision {self.revision}"

    def unchanged(self, what: str) -> str:
        return f"{what}; nothing changed (revision {self.revision})"


def _ids(v: Any) -> str:
    return ", ".join(v) if isinstance(v, list) else str(v)


def _moved(o: Outcome) -> str:
    if not o.changed:
        return o.unchanged(f"{o.op.id} is already at position {o.op.index}")
    found = o.mission.find(o.op.id) if o.mission is not None else None
    where = f" of {found[0]}'s unsynchronized section" if found else ""
    return f"moved {o.op.id} to position {o.op.index}{where} {o.at}"


def _edited(o: Outcome) -> str:
    if not o.changed:
        return o.unchanged(f"{o.op.id} already had these values")
    return f"edited {o.op.id} {o.at}"


def _queued(o: Outcome, what: str) -> str:
    v = o.value
    expires = v.get("expires")
    until = ""
    if expires:
        until = f" (expires {o.clock.stamp(datetime.fromisoformat(expires))})"
    return (
        f"queued for {v.get('robot', '?')}, command {v.get('command', '?')}: {what}{until} {o.at}"
    )


def _controlled(o: Outcome) -> str:
    commands = o.value.get("commands", {})
    if len(commands) == 1 and o.op.robot is not None:
        [(robot, cid)] = commands.items()
        return f"queued for {robot}, command {cid}: {o.op.op} {o.at}"
    queued = ", ".join(f"{r} (command {cid})" for r, cid in commands.items()) or "no robot"
    return f"{o.op.op} queued for {queued} {o.at}"


def _cancelled(o: Outcome) -> str:
    v = o.value
    if v.get("state") == "cancelled":
        return f"cancelled command {o.op.command} to {v.get('robot', '?')} {o.at}"
    return (
        f"asked {v.get('robot', '?')} to cancel command {o.op.command} (it was sent: "
        f"its answer says whether it was applied) {o.at}"
    )


def _marker_moved(o: Outcome) -> str:
    if not o.changed:
        return o.unchanged(f"marker {o.op.name} is already there")
    return f"moved marker {o.op.name} {o.at}"


def _loaded(o: Outcome) -> str:
    m = o.op.mission
    n = sum(len(t) for t in m.tasks.values())
    how = "keeping its statuses" if o.op.keep_state else "as a plan"
    return f"loaded mission '{m.name}' ({len(m.robots)} robots, {n} skills) {how} {o.at}"


def _barrier_wait(b: Any) -> str:
    """'10m, then continue' / 'for ever' (a barrier's timeout)."""
    if b.timeout is None:
        return "for ever"
    return f"{span_text(b.timeout)}, then {b.on_timeout}"


# the protocol's operation name (`op.op`) -> one line saying what it did
DESCRIBE: dict[str, Callable[[Outcome], str]] = {
    "add": lambda o: f"added {o.value.get('id', '?')} ({o.op.skill}) to {o.op.robot} {o.at}",
    "delete": lambda o: f"deleted {', '.join(o.op.ids)} {o.at}",
    "move": _moved,
    "edit": _edited,
    "sync": lambda o: _queued(o, f"sync {_ids(o.value.get('skills', []))}"),
    "unsync": lambda o: _queued(o, f"unsync {_ids(o.value.get('skills', []))}"),
    **dict.fromkeys(CONTROL_OPS, _controlled),
    "retry": lambda o: _queued(o, f"retry {o.op.id} as {o.value.get('id', '?')}"),
    "cancel": _cancelled,
    "barrier": lambda o: (
        f"created barrier {o.value.get('barrier', '?')} ({', '.join(o.op.ids)})"
        + (f", waits {_barrier_wait(o.op)}" if o.op.timeout is not None else "")
        + f" {o.at}"
    ),
    "unbarrier": lambda o: f"removed barrier {o.op.barrier} {o.at}",
    "barrier_edit": lambda o: f"barrier {o.op.barrier} waits {_barrier_wait(o.op)} {o.at}",
    "marker_add": lambda o: f"added marker {o.op.name} ({o.op.marker.kind}) {o.at}",
    "marker_move": _marker_moved,
    "marker_rename": lambda o: f"renamed marker {o.op.name} to {o.op.new_name} {o.at}",
    "marker_delete": lambda o: f"deleted marker {o.op.name} {o.at}",
    "load": _loaded,
    "new": lambda o: f"started a new mission '{o.op.name}' {o.at}",
    "undo": lambda o: f"undid {o.value.get('undone', 'the last edit')} {o.at}",
    "redo": lambda o: f"redid {o.value.get('redone', 'the last undone edit')} {o.at}",
    "waive": lambda o: (
        f"waived {o.op.check} {o.at}" if o.changed else o.unchanged(f"{o.op.check} was waived")
    ),
    "unwaive": lambda o: f"withdrew the waiver of {o.op.check} {o.at}",
    **TEAM_DESCRIBE,
    **QUESTION_DESCRIBE,
}


def describe(op: Any, reply: Any, before: int, mission: Any, clock: CtlClock = WALL) -> str:
    """One line saying what an applied operation did (its times on `clock`)."""
    changed = reply.revision != before or reply.duplicate
    outcome = Outcome(op, reply.value, reply.revision, changed, mission, clock)
    text = DESCRIBE.get(op.op, lambda o: f"{o.op.op} done {o.at}")(outcome)
    if reply.duplicate:
        text += " (this request had been applied already)"
    return text


# ---------------------------------------------------------------- watch


def _skill_status(e: Any) -> str:
    # A status change stamps started_at/finished_at itself: not news.
    parts = [str(e.status)] if e.status is not None else []
    if e.info:
        parts.append(f"({e.info})")
    if e.attempt is not None:
        parts.append(f"attempt {e.attempt}")
    return f"{e.id}: {' '.join(parts) or 'timestamps'}"


def _skill_edited(e: Any) -> str:
    fields = [k for k in ("label", "params", "bindings", "policies") if getattr(e, k) is not None]
    return f"{e.id}: changed {', '.join(fields)}"


def _mission_replaced(e: Any) -> str:
    n = sum(len(t) for t in e.mission.tasks.values())
    return f"mission replaced: '{e.mission.name}' ({n} skills)"


# event kind (`e.ev`) -> a phrase of a watch line (report_seq, bookkeeping: none)
EVENT_TEXT: dict[str, Callable[[Any], str]] = {
    "skill_added": lambda e: (
        f"+{e.skill.id} {e.skill.skill} on {e.robot} at {e.index} ({e.skill.status.value})"
    ),
    "skill_removed": lambda e: f"-{e.id} from {e.robot}",
    "skill_moved": lambda e: f"{e.id} moved to {e.index} on {e.robot}",
    "skill_status": _skill_status,
    "skill_edited": _skill_edited,
    "barrier_set": lambda e: f"barrier {e.id} = {' + '.join(e.barrier.skills)}",
    "barrier_removed": lambda e: f"barrier {e.id} removed",
    "marker_set": lambda e: f"marker {e.name}: {_marker_text(e.marker)}",
    "marker_removed": lambda e: f"marker {e.name} removed",
    "mission_replaced": _mission_replaced,
    "command_queued": lambda e: (
        f"command {e.command.id} queued for {e.command.robot}: {e.command.op}"
        + (f" {', '.join(e.command.skills)}" if e.command.skills else "")
    ),
    "command_changed": lambda e: (
        f"command {e.id}: "
        + (str(e.state) if e.state is not None else "cancel requested")
        + (f" ({e.reason})" if e.reason else "")
        + (f", did {', '.join(e.done)}" if e.done else "")
    ),
    "waiver_set": lambda e: f"waived {e.check}: {e.waiver.reason}",
    "waiver_removed": lambda e: f"waiver of {e.check} withdrawn",
    "robot_added": lambda e: f"robot {e.name} ({e.spec.type}) joined the mission",
    "robot_retired": lambda e: f"robot {e.name} retired: {e.reason}",
    **QUESTION_EVENT_TEXT,
}


def _event_text(e: Any) -> str | None:
    text = EVENT_TEXT.get(e.ev)
    return text(e) if text else None


def _events_text(batch: Any) -> str:
    parts = [t for t in (_event_text(e) for e in batch.events) if t]
    who = f" by {batch.actor}" if batch.actor else ""
    return f"r{batch.revision} {batch.op or 'change'}{who}: {'; '.join(parts) or 'bookkeeping'}"


def _alert_text(a: Any) -> str:
    where = f" [{a.robot}{'/' + a.skill if a.skill else ''}]" if a.robot else ""
    return f"{a.level}{where}: {a.message}"


def fleet_text(r: Any, clock: CtlClock = WALL) -> str:
    """A robot's line of `watch`: `robot lru1 online since sim 0:20:00, in contact`."""
    return f"robot {r.name} {_presence(r, clock)}"


# the client's message kind -> a line of `watch` (telemetry and others: none)
WATCH_TEXT: dict[str, Callable[[Any, CtlClock], str]] = {
    "events": lambda batch, _clock: _events_text(batch),
    "fleet": fleet_text,  # the one with stamps: said on the clock
    "alert": lambda a, _clock: _alert_text(a),
    "malformed": lambda m, _clock: f"unreadable {m.what} on {m.key} (ignored): {m.error}",
    "connection": lambda state, _clock: f"connection: {state}",
    "state": lambda s, _clock: f"resynchronized at revision {s.revision} (server {s.server_id})",
}

WATCH_JSON: dict[str, Callable[[Any], dict[str, Any]]] = {
    "events": lambda b: {"kind": "events", **b.model_dump(mode="json")},
    "fleet": lambda r: {"kind": "fleet", "robot": r.model_dump(mode="json")},
    "alert": lambda a: {"kind": "alert", **a.model_dump(mode="json")},
    "malformed": lambda m: {"kind": "malformed", "what": m.what, "key": m.key, "error": m.error},
    "connection": lambda state: {"kind": "connection", "state": state},
    "state": lambda s: {"kind": "resync", "revision": s.revision, "server_id": s.server_id},
}


def watch_line(kind: str, payload: Any, as_json: bool, clock: CtlClock = WALL) -> str | None:
    """A line of `watch` (None: nothing to say); its times on `clock` (text only)."""
    if as_json:
        obj = WATCH_JSON.get(kind)
        return json.dumps(obj(payload)) if obj else None
    text = WATCH_TEXT.get(kind)
    return text(payload, clock) if text else None
