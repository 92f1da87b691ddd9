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
from backend.cli.ctl.questions import DESCRIBE as QUESTION_DESCRIBE
from backend.cli.ctl.questions import EVENT_TEXT as QUESTION_EVENT_TEXT
from backend.cli.ctl.team import DESCRIBE as TEAM_DESCRIBE
from backend.core.contact import sim_time_text
from backend.core.contingency import marks, taken_text
from backend.core.params import POSE_FIELDS, POSITION_FIELDS, is_angle, pose_text, value_text

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
    if spec is not None and is_angle(spec) and isinstance(v, int | float):
        text = value_text(spec, v)
    elif _is_pose(v):
        text = _pose_text(v)
    elif _is_area(v):
        text = f"[{len(v)} points]"
    elif isinstance(v, str):
        text = _str_text(v)
    else:
        text = json.dumps(v, separators=(",", ":"), ensure_ascii=False)
    return text if len(text) <= limit else text[: limit - 3] + "..."


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


def _time(t: datetime | None) -> str:
    if t is None:
        return ""
    try:
        return t.astimezone().strftime("%H:%M:%S")
    except (ValueError, OSError):
        return t.strftime("%H:%M:%S")


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


def _presence(info: Any) -> str:
    if info is None:
        return "not registered"
    c = info.contact
    if info.online and c is not None and c.state == "out_of_contact":  # never "online" then
        return _contact(c) + (f" (present since {_time(info.since)})" if info.since else "")
    if info.online:
        online = f"online since {_time(info.since)}" if info.since else "online"
        return online + (f", {_contact(c)}" if c is not None and c.state != "offline" else "")
    return (
        f"offline since {_time(info.since)}"
        if info.since
        else "offline (not seen since the server started)"
    )


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
    return text + (f"  {mk.description}" if mk.description else "")


def _shown(robot: str, only: list[str] | None) -> bool:
    return not only or robot in only


def _iso(t: datetime | None) -> str | None:
    return t.isoformat() if t else None


def age_text(seconds: float | None) -> str:
    """12 s, 4 min, 2 h 5 min."""
    if seconds is None:
        return "?"
    s = max(0, round(seconds))
    if s < 120:
        return f"{s} s"
    if s < 7200:
        return f"{s // 60} min"
    return f"{s // 3600} h {s % 3600 // 60} min"


def _since(t: datetime | None, now: datetime) -> float | None:
    return (now - t).total_seconds() if t is not None else None


def command_line(c: Any, now: datetime, client: Any = None) -> str:
    """One pending (or settled) command: `17 lru1 sync lru1-1, lru1-2: sent 12 s ago ...`."""
    what = f"{c.op} {', '.join(c.skills)}" if c.skills else c.op
    if c.state.value == "queued":
        when = f"queued {age_text(_since(c.created, now))} ago, not sent yet"
    elif c.state.value == "sent":
        when = f"sent {age_text(_since(c.sent, now))} ago, no answer yet"
    else:
        when = f"{c.state.value} {_time(c.settled)}" + (f": {c.reason}" if c.reason else "")
    extra = _command_notes(c, now) + _stage_note(client, c, now)
    tail = f" [{'; '.join(extra)}]" if extra else ""
    return f"command {c.id} to {c.robot} (seq {c.seq}): {what}: {when}{tail}"


def _command_notes(c: Any, now: datetime) -> list[str]:
    extra = []
    if c.expires is not None and c.pending:
        passed = " (passed)" if c.expires <= now else ""
        extra.append(f"expires {_time(c.expires)}{passed}")
    if c.cancel_requested and c.pending:
        extra.append("cancel requested")
    return extra


def _stage_note(client: Any, c: Any, now: datetime) -> list[str]:
    """The stage it waits for, with its due (the server's verification)."""
    from backend.cli.ctl.verify import stage_text

    text = stage_text(client, c, now, _time) if client is not None else ""
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


def link_text(client: Any, name: str, now: datetime) -> str:
    """`delay 2.0 s, heard 3 s ago, 2 pending` (+ `stale: last known state`)."""
    ls = client.link(name, now)
    parts = []
    if ls.delay_s is not None:
        parts.append(f"delay {ls.delay_s:.1f} s")
    if ls.heard_age_s is not None:
        parts.append(f"heard {age_text(ls.heard_age_s)} ago")
    if ls.pending:
        parts.append(f"{len(ls.pending)} pending")
    if ls.stale and ls.online:
        parts.append("stale: last known state")
    return ", ".join(parts)


# ---------------------------------------------------------------- state --json


def _robot_json(client: Any, name: str, now: datetime | None = None) -> dict[str, Any]:
    spec = client.mission.robots.get(name)
    info = client.robots.get(name)
    manifest = info.manifest if info else None
    rtype = spec.type if spec else (manifest.type if manifest else None)
    rt = client.library.robot_types.get(rtype) if rtype else None
    return {
        "type": rtype,
        "kind": rt.kind if rt else None,
        "in_mission": spec is not None,
        "joining": bool(info and info.joining),
        "retired": spec.retired if spec else "",
        "online": bool(info and info.online),
        "since": _iso(info.since) if info else None,
        "contact": info.contact.model_dump(mode="json") if info and info.contact else None,
        "manifest": manifest.model_dump(mode="json") if manifest else None,
        "link": link_json(client, name, now or datetime.now(UTC)),
    }


def _skill_json(m: Any, s: Any, locks: dict[str, Any] | None = None) -> dict[str, Any]:
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
        "started_at": _iso(s.started_at),
        "finished_at": _iso(s.finished_at),
    }


def state_json(client: Any, only: list[str] | None = None) -> dict[str, Any]:
    m = client.mission
    now = datetime.now(UTC)
    names = list(m.robots) + [r for r in client.robots if r not in m.robots]
    locks = m.command_locks()
    return {
        "revision": m.revision,
        "name": m.name,
        "library": m.library,
        "server_id": client.server_id,
        "robots": {n: _robot_json(client, n, now) for n in names if _shown(n, only)},
        "tasks": {
            r: [_skill_json(m, s, locks) for s in task]
            for r, task in m.tasks.items()
            if _shown(r, only)
        },
        "uplink": {
            r: [command_json(c, now) for c in cmds]
            for r, cmds in m.uplink.items()
            if _shown(r, only)
        },
        "barriers": {bid: list(b.skills) for bid, b in m.barriers.items()},
        "markers": {n: mk.model_dump(mode="json") for n, mk in m.markers.items()},
        "waivers": {c: w.model_dump(mode="json") for c, w in m.waivers.items()},
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
    `pending`: (command, now) when a pending command concerns it."""
    parts = [columns]
    if pending is not None:
        c, now = pending
        doing = {"sync": "uplinking", "retry": "retrying", "unsync": "unsynchronizing"}[c.op]
        since = c.sent if c.sent is not None else c.created
        verb = "sent" if c.sent is not None else "queued"
        parts.append(f"({doing}: command {c.id}, {verb} {age_text(_since(since, now))} ago)")
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


def _task_lines(m: Any, task: list[Any], lib: Any, unicode: bool) -> list[str]:
    if not task:
        return ["  (no skills)"]
    locks = m.command_locks()
    now = datetime.now(UTC)
    dash = "—" if unicode else "-"
    ids = [s.id + (f" [{m.barrier_of(s.id)}]" if m.barrier_of(s.id) else "") for s in task]
    wid = max(len(i) for i in ids)
    wlabel = max(len(s.label) for s in task)
    wskill = max(len(s.skill) for s in task)
    return [
        _skill_line(
            s,
            f"  {glyph(s.status.value, unicode)} {ident:<{wid}}  {s.label:<{wlabel}}  "
            f"{s.skill:<{wskill}}",
            lib,
            dash,
            (locks[s.id], now) if s.id in locks else None,
        )
        for s, ident in zip(task, ids, strict=True)
    ]


def _robot_lines(client: Any, robot: str, unicode: bool) -> list[str]:
    m, lib = client.mission, client.library
    spec = m.robots.get(robot)
    rtype = spec.type if spec else "?"
    kind = lib.robot_types[rtype].kind if rtype in lib.robot_types else ""
    static = ", " + kind if kind == "static" else ""
    dash = "—" if unicode else "-"
    now = datetime.now(UTC)
    link = link_text(client, robot, now)
    head = f"{robot} ({rtype}{static}) {dash} {_presence(client.robots.get(robot))}"
    pending = [f"  pending: {command_line(c, now)}" for c in m.pending_commands(robot)]
    return [
        head + (f"; {link}" if link else ""),
        *_task_lines(m, m.tasks.get(robot, []), lib, unicode),
        *pending,
    ]


def _barrier_line(m: Any) -> str:
    if not m.barriers:
        return "barriers: none"
    return "barriers: " + "; ".join(
        f"{bid} = {' + '.join(b.skills)}" for bid, b in m.barriers.items()
    )


def _marker_lines(m: Any) -> list[str]:
    if not m.markers:
        return ["markers: none"]
    w = max(len(n) for n in m.markers)
    return ["markers:", *(f"  {n:<{w}}  {_marker_text(mk)}" for n, mk in m.markers.items())]


def state_text(client: Any, only: list[str] | None = None, unicode: bool = True) -> str:
    m, lib = client.mission, client.library
    lines = [
        f"mission '{m.name}' at revision {m.revision} "
        f"(library '{lib.name}', {', '.join(client.endpoints)})"
    ]
    for robot in list(m.robots) + [r for r in m.tasks if r not in m.robots]:
        if _shown(robot, only):
            lines += _robot_lines(client, robot, unicode)
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
    text = f"; {known}battery {t.battery:.0%}, link {t.link:.0%}{out_of_range}, {t.mode}"
    if t.skill:
        text += f" {t.skill}" + (f" {t.progress:.0%}" if t.progress is not None else "")
    return text


def _manifest_lines(man: dict[str, Any] | None) -> list[str]:
    if not man:
        return ["  (no manifest: never registered with this server)"]
    mods = ", ".join(f"{x['name']} {x['version']}" for x in man["modules"]) or "none"
    skills = ", ".join(f"{k} {v}" for k, v in man["skills"].items()) or "none"
    lines = [f"  modules: {mods}", f"  skills:  {skills}"]
    if man["properties"]:
        lines.append(
            "  properties: "
            + ", ".join(f"{k}={short_value(v)}" for k, v in man["properties"].items())
        )
    return lines


def robots_text(client: Any) -> str:
    data = robots_json(client)["robots"]
    if not data:
        return "no robots"
    lines = []
    for name, r in data.items():
        outside = ", not in the mission" if not r["in_mission"] else ""
        if r["joining"]:
            outside = f", asks to join: missionctl ctl robots add {name}"
        elif r["retired"]:
            outside = f", retired: {r['retired']}"
        head = f"{name} ({r['type'] or '?'}{outside}): {_presence(client.robots.get(name))}"
        t = client.telemetry.get(name)
        link = link_text(client, name, datetime.now(UTC))
        lines.append(
            head
            + (f"; {link}" if link else "")
            + (_telemetry_text(t, client.robots.get(name)) if t is not None else "")
        )
        lines += _manifest_lines(r["manifest"])
        now = datetime.now(UTC)
        lines += [f"  pending: {command_line(c, now)}" for c in client.pending(name)]
    return "\n".join(lines)


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


def pending_text(client: Any, only: list[str] | None = None) -> str:
    now = datetime.now(UTC)
    cmds = [c for c in client.pending() if _shown(c.robot, only)]
    cmds += _executing(client, only)
    if not cmds:
        return "no pending commands" + (f" for {', '.join(only)}" if only else "")
    return "\n".join(command_line(c, now, client) for c in cmds)


# ---------------------------------------------------------------- describe


@dataclass(frozen=True)
class Outcome:
    """An applied operation, as `describe` sees it."""

    op: Any
    value: dict[str, Any]
    revision: int
    changed: bool  # the revision moved (or the request had been applied before)
    mission: Any  # the mission after it (None: unknown)

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
        until = f" (expires {_time(datetime.fromisoformat(expires))})"
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
        f"created barrier {o.value.get('barrier', '?')} ({', '.join(o.op.ids)}) {o.at}"
    ),
    "unbarrier": lambda o: f"removed barrier {o.op.barrier} {o.at}",
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


def describe(op: Any, reply: Any, before: int, mission: Any) -> str:
    """One line saying what an applied operation did."""
    changed = reply.revision != before or reply.duplicate
    outcome = Outcome(op, reply.value, reply.revision, changed, mission)
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


# the client's message kind -> a line of `watch` (telemetry and others: none)
WATCH_TEXT: dict[str, Callable[[Any], str]] = {
    "events": _events_text,
    "fleet": lambda r: f"robot {r.name} {_presence(r)}",
    "alert": _alert_text,
    "malformed": lambda m: f"unreadable {m.what} on {m.key} (ignored): {m.error}",
    "connection": lambda state: f"connection: {state}",
    "state": lambda s: f"resynchronized at revision {s.revision} (server {s.server_id})",
}

WATCH_JSON: dict[str, Callable[[Any], dict[str, Any]]] = {
    "events": lambda b: {"kind": "events", **b.model_dump(mode="json")},
    "fleet": lambda r: {"kind": "fleet", "robot": r.model_dump(mode="json")},
    "alert": lambda a: {"kind": "alert", **a.model_dump(mode="json")},
    "malformed": lambda m: {"kind": "malformed", "what": m.what, "key": m.key, "error": m.error},
    "connection": lambda state: {"kind": "connection", "state": state},
    "state": lambda s: {"kind": "resync", "revision": s.revision, "server_id": s.server_id},
}


def watch_line(kind: str, payload: Any, as_json: bool) -> str | None:
    if as_json:
        obj = WATCH_JSON.get(kind)
        return json.dumps(obj(payload)) if obj else None
    text = WATCH_TEXT.get(kind)
    return text(payload) if text else None
