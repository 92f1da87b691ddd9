"""How the console writes statuses, values and times: glyphs, short words,
one-line parameter summaries (Textual-free, so it is unit-tested without a terminal)."""

from __future__ import annotations

import re
from datetime import datetime
from typing import Any

from backend.core.contingency import marks as contingency_marks
from backend.core.library import Library
from backend.core.model import SkillInstance, Status
from backend.core.params import POSE_FIELDS, ParamSpec, pose_text, value_text

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
    if (
        isinstance(v, dict)
        and t in ("pose", "position")
        or (isinstance(v, dict) and set(v) <= set(POSE_FIELDS) and v)
    ):
        return pose_text(v)  # (x,y) and what is not 0: (3,4 yaw=90°)
    if t == "area" and isinstance(v, list):
        return f"area[{len(v)}]"
    if isinstance(v, list):
        return "[" + ",".join(fmt_number(x) for x in v[:3]) + ("…" if len(v) > 3 else "") + "]"
    if isinstance(v, dict):
        return (
            "{"
            + ",".join(f"{k}:{fmt_number(x)}" for k, x in list(v.items())[:2])
            + ("…" if len(v) > 2 else "")
            + "}"
        )
    if spec is not None and isinstance(v, int | float) and not isinstance(v, bool):
        return value_text(spec, v)  # with its unit; an angle in degrees
    return fmt_number(v)


def param_summary(skill: SkillInstance, library: Library | None) -> str:
    """Bindings and the values that differ from the library defaults."""
    spec = library.skills.get(skill.skill) if library else None
    parts: list[str] = []
    for name, marker in skill.bindings.items():
        parts.append(f"{name}@{marker}")
    for name, value in skill.params.items():
        if name in skill.bindings:
            continue
        pspec = spec.params.get(name) if spec else None
        if pspec is not None and pspec.default is not None:
            try:
                from backend.core.params import normalize_value

                if normalize_value(pspec, pspec.default) == value:
                    continue
            except Exception:
                pass
        parts.append(f"{name}={fmt_value(pspec, value)}")
    parts.extend(policy_marks(skill))
    return " ".join(parts)


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
