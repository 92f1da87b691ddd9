"""ctl's output: state, robots, watch lines and what an operation did, as text and JSON."""

from __future__ import annotations

import json
import re
import sys
from datetime import datetime
from typing import Any

from backend.cli.ctl.args import CONTROL_OPS
from backend.core.params import POSE_FIELDS, POSITION_FIELDS

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


def short_value(v: Any, limit: int = 40) -> str:
    """A compact rendering of a parameter value for one line of `state`."""
    if (
        isinstance(v, dict)
        and v
        and set(v) <= set(POSE_FIELDS)
        and all(isinstance(x, int | float) for x in v.values())
    ):
        text = f"({_num(v.get('x', 0))},{_num(v.get('y', 0))}"
        extra = [f"{k}={_num(v[k])}" for k in ("z", "roll", "pitch", "yaw") if v.get(k)]
        text += (" " + " ".join(extra) if extra else "") + ")"
    elif (
        isinstance(v, list)
        and v
        and all(isinstance(p, dict) and set(p) <= set(POSITION_FIELDS) for p in v)
    ):
        text = f"[{len(v)} points]"
    elif isinstance(v, str):
        text = v if v and re.fullmatch(r"[\w.\-@/]+", v) else json.dumps(v, ensure_ascii=False)
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


def short_params(s: Any, library: Any) -> str:
    parts = []
    for name, value in s.params.items():
        if name in s.bindings:
            parts.append(f"{name}=@{s.bindings[name]}")
        elif _differs_from_default(library, s.skill, name, value):
            parts.append(f"{name}={short_value(value)}")
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


def _presence(info: Any) -> str:
    if info is None:
        return "not registered"
    if info.online:
        return f"online since {_time(info.since)}" if info.since else "online"
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


def state_json(client: Any, only: list[str] | None = None) -> dict[str, Any]:
    m, lib = client.mission, client.library
    robots: dict[str, Any] = {}
    for name in list(m.robots) + [r for r in client.robots if r not in m.robots]:
        if only and name not in only:
            continue
        spec = m.robots.get(name)
        info = client.robots.get(name)
        rtype = spec.type if spec else (info.manifest.type if info and info.manifest else None)
        rt = lib.robot_types.get(rtype) if rtype else None
        robots[name] = {
            "type": rtype,
            "kind": rt.kind if rt else None,
            "in_mission": spec is not None,
            "online": bool(info and info.online),
            "since": info.since.isoformat() if info and info.since else None,
            "manifest": info.manifest.model_dump(mode="json") if info and info.manifest else None,
        }
    tasks: dict[str, Any] = {}
    for robot, task in m.tasks.items():
        if only and robot not in only:
            continue
        tasks[robot] = [
            {
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
                "started_at": s.started_at.isoformat() if s.started_at else None,
                "finished_at": s.finished_at.isoformat() if s.finished_at else None,
            }
            for s in task
        ]
    return {
        "revision": m.revision,
        "name": m.name,
        "library": m.library,
        "server_id": client.server_id,
        "robots": robots,
        "tasks": tasks,
        "barriers": {bid: list(b.skills) for bid, b in m.barriers.items()},
        "markers": {n: mk.model_dump(mode="json") for n, mk in m.markers.items()},
    }


def state_text(client: Any, only: list[str] | None = None, unicode: bool = True) -> str:
    m, lib = client.mission, client.library
    dash = "—" if unicode else "-"
    lines = [
        f"mission '{m.name}' at revision {m.revision} (library '{lib.name}', {', '.join(client.endpoints)})"
    ]
    robots = list(m.robots) + [r for r in m.tasks if r not in m.robots]
    for robot in robots:
        if only and robot not in only:
            continue
        spec = m.robots.get(robot)
        rtype = spec.type if spec else "?"
        kind = lib.robot_types[rtype].kind if rtype in lib.robot_types else ""
        lines.append(
            f"{robot} ({rtype}{', ' + kind if kind == 'static' else ''}) {dash} {_presence(client.robots.get(robot))}"
        )
        task = m.tasks.get(robot, [])
        if not task:
            lines.append("  (no skills)")
            continue
        ids = [s.id + (f" [{m.barrier_of(s.id)}]" if m.barrier_of(s.id) else "") for s in task]
        wid = max(len(i) for i in ids)
        wlabel = max(len(s.label) for s in task)
        wskill = max(len(s.skill) for s in task)
        for s, ident in zip(task, ids, strict=True):
            line = f"  {glyph(s.status.value, unicode)} {ident:<{wid}}  {s.label:<{wlabel}}  {s.skill:<{wskill}}"
            extra = short_params(s, lib)
            if extra:
                line += "  " + extra
            if s.attempt > 1:
                line += f"  (attempt {s.attempt})"
            if not s.policies.is_default():
                p = s.policies
                pol = []
                if p.retries:
                    pol.append(f"retries={p.retries}")
                if p.pause_out_of_comms:
                    pol.append("pause-out-of-comms")
                if p.recharge_below is not None:
                    pol.append(f"recharge<{p.recharge_below:g}")
                line += "  {" + " ".join(pol) + "}"
            if s.status_info:
                line += f"  {dash} {s.status_info}"
            lines.append(line.rstrip())
    if m.barriers:
        lines.append(
            "barriers: "
            + "; ".join(f"{bid} = {' + '.join(b.skills)}" for bid, b in m.barriers.items())
        )
    else:
        lines.append("barriers: none")
    if m.markers:
        lines.append("markers:")
        w = max(len(n) for n in m.markers)
        lines += [f"  {n:<{w}}  {_marker_text(mk)}" for n, mk in m.markers.items()]
    else:
        lines.append("markers: none")
    legend = ", ".join(f"{glyph(st, unicode)} {st}" for st in _GLYPHS)
    lines.append(f"({legend})")
    return "\n".join(lines)


def robots_json(client: Any) -> dict[str, Any]:
    out = state_json(client)["robots"]
    for name, entry in out.items():
        t = client.telemetry.get(name)
        entry["telemetry"] = t.model_dump(mode="json") if t else None
    return {"revision": client.revision, "robots": out}


def robots_text(client: Any) -> str:
    data = robots_json(client)["robots"]
    if not data:
        return "no robots"
    lines = []
    for name, r in data.items():
        head = f"{name} ({r['type'] or '?'}{', not in the mission' if not r['in_mission'] else ''}): {_presence(client.robots.get(name))}"
        t = client.telemetry.get(name)
        if t is not None:
            head += f"; battery {t.battery:.0%}, link {t.link:.0%}{'' if t.in_range else ' (out of range)'}, {t.mode}"
            if t.skill:
                head += f" {t.skill}" + (f" {t.progress:.0%}" if t.progress is not None else "")
        lines.append(head)
        man = r["manifest"]
        if man:
            mods = ", ".join(f"{x['name']} {x['version']}" for x in man["modules"]) or "none"
            skills = ", ".join(f"{k} {v}" for k, v in man["skills"].items()) or "none"
            lines.append(f"  modules: {mods}")
            lines.append(f"  skills:  {skills}")
            if man["properties"]:
                lines.append(
                    "  properties: "
                    + ", ".join(f"{k}={short_value(v)}" for k, v in man["properties"].items())
                )
        else:
            lines.append("  (no manifest: never registered with this server)")
    return "\n".join(lines)


def _ids(v: Any) -> str:
    return ", ".join(v) if isinstance(v, list) else str(v)


def describe(op: Any, reply: Any, before: int, mission: Any) -> str:
    """One line saying what an applied operation did."""
    rev = reply.revision
    at = f"at revision {rev}"
    v = reply.value
    changed = rev != before or reply.duplicate
    name = op.op
    if name == "add":
        text = f"added {v.get('id', '?')} ({op.skill}) to {op.robot} {at}"
    elif name == "delete":
        text = f"deleted {', '.join(op.ids)} {at}"
    elif name == "move":
        found = mission.find(op.id) if mission is not None else None
        where = f" of {found[0]}'s unsynchronized section" if found else ""
        text = (
            f"moved {op.id} to position {op.index}{where} {at}"
            if changed
            else f"{op.id} is already at position {op.index}; nothing changed (revision {rev})"
        )
    elif name == "edit":
        text = (
            f"edited {op.id} {at}"
            if changed
            else f"{op.id} already had these values; nothing changed (revision {rev})"
        )
    elif name == "sync":
        text = f"synchronized {_ids(v.get('synchronized', []))} to {op.robot} {at}"
    elif name == "unsync":
        back = v.get("unsynchronized", [])
        text = f"unsynchronized {_ids(back) or 'nothing'} from {op.robot} {at}"
    elif name in CONTROL_OPS:
        robots = v.get("robots", {})
        ok = [r for r, res in robots.items() if res == "ok"]
        target = ", ".join(ok) if ok else (op.robot or "all robots")
        text = f"{name} sent to {target} {at}"
    elif name == "retry":
        text = f"retrying {op.id} as {v.get('id', '?')} {at}"
    elif name == "barrier":
        text = f"created barrier {v.get('barrier', '?')} ({', '.join(op.ids)}) {at}"
    elif name == "unbarrier":
        text = f"removed barrier {op.barrier} {at}"
    elif name == "marker_add":
        text = f"added marker {op.name} ({op.marker.kind}) {at}"
    elif name == "marker_move":
        text = (
            f"moved marker {op.name} {at}"
            if changed
            else f"marker {op.name} is already there; nothing changed (revision {rev})"
        )
    elif name == "marker_rename":
        text = f"renamed marker {op.name} to {op.new_name} {at}"
    elif name == "marker_delete":
        text = f"deleted marker {op.name} {at}"
    elif name == "load":
        m = op.mission
        n = sum(len(t) for t in m.tasks.values())
        text = f"loaded mission '{m.name}' ({len(m.robots)} robots, {n} skills) {at}"
    elif name == "new":
        text = f"started a new mission '{op.name}' {at}"
    elif name == "undo":
        text = f"undid {v.get('undone', 'the last edit')} {at}"
    elif name == "redo":
        text = f"redid {v.get('redone', 'the last undone edit')} {at}"
    else:
        text = f"{name} done {at}"
    if reply.duplicate:
        text += " (this request had been applied already)"
    return text


def _event_text(e: Any) -> str | None:
    kind = e.ev
    if kind == "skill_added":
        s = e.skill
        return f"+{s.id} {s.skill} on {e.robot} at {e.index} ({s.status.value})"
    if kind == "skill_removed":
        return f"-{e.id} from {e.robot}"
    if kind == "skill_moved":
        return f"{e.id} moved to {e.index} on {e.robot}"
    if kind == "skill_changed":
        # A status change stamps started_at/finished_at itself: not news.
        ch = {k: v for k, v in e.changes.items() if k not in ("started_at", "finished_at", "rev")}
        parts = []
        if "status" in ch:
            parts.append(str(ch.pop("status")))
        if ch.get("status_info"):
            parts.append(f"({ch['status_info']})")
        ch.pop("status_info", None)
        if "attempt" in ch:
            parts.append(f"attempt {ch.pop('attempt')}")
        if ch:
            parts.append("changed " + ", ".join(sorted(ch)))
        return f"{e.id}: {' '.join(parts) or 'timestamps'}"
    if kind == "barrier_set":
        return f"barrier {e.id} = {' + '.join(e.barrier.skills)}"
    if kind == "barrier_removed":
        return f"barrier {e.id} removed"
    if kind == "marker_set":
        return f"marker {e.name}: {_marker_text(e.marker)}"
    if kind == "marker_removed":
        return f"marker {e.name} removed"
    if kind == "mission_replaced":
        n = sum(len(t) for t in e.mission.tasks.values())
        return f"mission replaced: '{e.mission.name}' ({n} skills)"
    return None  # report_seq: bookkeeping


def watch_line(kind: str, payload: Any, as_json: bool) -> str | None:
    if as_json:
        if kind == "events":
            return json.dumps({"kind": "events", **payload.model_dump(mode="json")})
        if kind == "fleet":
            return json.dumps({"kind": "fleet", "robot": payload.model_dump(mode="json")})
        if kind == "alert":
            return json.dumps({"kind": "alert", **payload.model_dump(mode="json")})
        if kind == "malformed":
            return json.dumps(
                {
                    "kind": "malformed",
                    "what": payload.what,
                    "key": payload.key,
                    "error": payload.error,
                }
            )
        if kind == "connection":
            return json.dumps({"kind": "connection", "state": payload})
        if kind == "state":
            return json.dumps(
                {"kind": "resync", "revision": payload.revision, "server_id": payload.server_id}
            )
        return None
    if kind == "events":
        parts = [t for t in (_event_text(e) for e in payload.events) if t]
        who = f" by {payload.actor}" if payload.actor else ""
        return f"r{payload.revision} {payload.op or 'change'}{who}: {'; '.join(parts) or 'bookkeeping'}"
    if kind == "fleet":
        return f"robot {payload.name} {_presence(payload)}"
    if kind == "alert":
        where = (
            f" [{payload.robot}{'/' + payload.skill if payload.skill else ''}]"
            if payload.robot
            else ""
        )
        return f"{payload.level}{where}: {payload.message}"
    if kind == "malformed":
        return f"unreadable {payload.what} on {payload.key} (ignored): {payload.error}"
    if kind == "connection":
        return f"connection: {payload}"
    if kind == "state":
        return f"resynchronized at revision {payload.revision} (server {payload.server_id})"
    return None
