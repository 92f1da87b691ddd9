"""How the console writes statuses, values and times: glyphs, short words,
one-line parameter summaries (Textual-free, so it is unit-tested without a terminal)."""

from __future__ import annotations

import re
from datetime import datetime
from typing import Any

from backend.core.contingency import marks as contingency_marks
from backend.core.library import Library
from backend.core.model import SkillInstance, Status
from backend.core.params import POSE_FIELDS, ParamSpec, normalize_value, pose_text, value_text

# -- statuses -------------------------------------------------------------------

GLYPHS: dict[Status, str] = {
    Status.SUCCESS: "✓",
    Status.FAILURE: "✗",
    Status.RUNNING: "▶",
    Status.PAUSED: "‖",
    Status.SYNCHWAITING: "◷",
    Status.IDLE_SYNCHRONIZED: "●",
    Status.IDLE: "○",
}

# short words for places where the full status does not fit
STATUS_WORDS: dict[Status, str] = {
    Status.SUCCESS: "success",
    Status.FAILURE: "failure",
    Status.RUNNING: "running",
    Status.PAUSED: "paused",
    Status.SYNCHWAITING: "waiting at barrier",
    Status.IDLE_SYNCHRONIZED: "queued",
    Status.IDLE: "idle",
}

# CSS-friendly names (theme variables $status-<name>, component classes)
STATUS_CSS: dict[Status, str] = {s: s.value.replace("_", "-") for s in Status}


def fmt_clock(t: datetime | None) -> str:
    """HH:MM:SS in local time (deterministic: from a timestamp, never `now`)."""
    if t is None:
        return "--:--:--"
    if t.tzinfo is not None:
        t = t.astimezone()
    return t.strftime("%H:%M:%S")


def fmt_duration(seconds: float | None) -> str:
    if seconds is None:
        return "?"
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{(s % 3600) // 60:02d}m"


def fmt_number(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def fmt_value(spec: ParamSpec | None, v: Any) -> str:
    """A short, one-line rendering of a parameter value (angles in degrees)."""
    t = spec.type if spec else None
    if isinstance(v, dict):
        return _dict_text(t, v)
    if isinstance(v, list):
        return f"area[{len(v)}]" if t == "area" else _clipped("[", list(map(fmt_number, v)), 3, "]")
    if spec is not None and isinstance(v, int | float) and not isinstance(v, bool):
        return value_text(spec, v)  # with its unit; an angle in degrees
    return fmt_number(v)


def _dict_text(kind: str | None, v: dict[str, Any]) -> str:
    if kind in ("pose", "position") or (v and set(v) <= set(POSE_FIELDS)):
        return pose_text(v)  # (x,y) and what is not 0: (3,4 yaw=90°)
    return _clipped("{", [f"{k}:{fmt_number(x)}" for k, x in v.items()], 2, "}")


def _clipped(opening: str, items: list[str], room: int, closing: str) -> str:
    """'[1,2,3…]': the first `room` items, and an ellipsis when there are more."""
    more = "…" if len(items) > room else ""
    return opening + ",".join(items[:room]) + more + closing


def param_summary(skill: SkillInstance, library: Library | None) -> str:
    """Bindings and the values that differ from the library defaults."""
    spec = library.skills.get(skill.skill) if library else None
    specs = spec.params if spec else {}
    parts = [f"{name}@{marker}" for name, marker in skill.bindings.items()]
    parts += [
        f"{name}={fmt_value(specs.get(name), value)}"
        for name, value in skill.params.items()
        if name not in skill.bindings and not _is_default(specs.get(name), value)
    ]
    return " ".join(parts + policy_marks(skill))


def _is_default(spec: ParamSpec | None, value: Any) -> bool:
    if spec is None or spec.default is None:
        return False
    try:
        return bool(normalize_value(spec, spec.default) == value)
    except Exception:  # a default its kind cannot read: the value is worth showing
        return False


def policy_marks(skill: SkillInstance) -> list[str]:
    """Short marks for the policies that are set: 'retry×2 pause-out-of-comms recharge<20%
    ⏱10m→skip'."""
    p = skill.policies
    marks = [f"retry×{p.retries}"] if p.retries else []
    if p.pause_out_of_comms:
        marks.append("pause-out-of-comms")
    if p.recharge_below is not None:
        marks.append(f"recharge<{round(p.recharge_below * 100)}%")
    return marks + contingency_marks(p)  # ⏱10m→skip ✗→recharge@Lander


def skill_title(skill: SkillInstance) -> str:
    return skill.label or skill.skill


# an absolute file path (not the '/' of 'tcp/127.0.0.1:7447' or of '1/2')
_ABSOLUTE_PATH = re.compile(r"(?<![\w.~:/])/(?:[\w.\-]+/)+([\w.\-]+)")


def without_paths(text: str) -> str:
    """A message for a notification: absolute file paths shortened to their
    file name ('…/sim.log'), which is what tells an operator something."""
    return _ABSOLUTE_PATH.sub(r"…/\1", text)
