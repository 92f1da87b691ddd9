"""`ctl suggest SKILL_OR_ID...` (issue 30): the robots that can take skills,
ranked by the forecast (their predicted end with them, the time out of comms
coverage doing them, the battery left); see backend/core/plan/suggest.py."""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from typing import Any

from backend.cli.ctl.clock import WALL, CtlClock
from backend.cli.ctl.errors import UsageError
from backend.cli.ctl.plan import gather_clocked
from backend.core.plan.suggest import Manifests, suggest, taken_words
from backend.core.rules.base import Refusal

RANKED = "the most taken, then the earliest end, the least out of coverage, the most battery"


async def suggest_view(client: Any, args: argparse.Namespace) -> int:
    """`ctl suggest`: the robots ranked for the skills (the forecast's end, battery left)."""
    inputs, clock = await gather_clocked(client, args.timeout)
    try:
        offers = Manifests.of(client.robots)
        hints = suggest(client.mission, client.library, inputs, list(args.what), offers)
    except Refusal as r:
        raise UsageError(f"suggest: {r.message}") from None
    rows = [_hint_json(h, inputs.now) for h in hints]
    if args.json:
        out = {"ok": True, "what": list(args.what), "robots": rows}
        print(json.dumps(out, ensure_ascii=False), flush=True)
    else:
        print(f"who can take {', '.join(args.what)} ({RANKED}):", flush=True)
        for n, row in enumerate(rows, 1):
            print(f"  {n}. {hint_text(row, clock)}", flush=True)
    return 0


def _hint_json(h: Any, now: float) -> dict[str, Any]:
    end = datetime.fromtimestamp(h.end, UTC).isoformat() if h.end is not None else None
    return {
        "robot": h.robot,
        "capable": h.capable,
        "moved": list(h.moved),
        "refused": dict(h.refused),
        "end": end,
        "end_in_s": round(h.end - now, 1) if h.end is not None else None,
        "battery_end": round(h.battery_end, 3) if h.battery_end is not None else None,
        "battery_assumed": h.battery_assumed,
        "out_of_coverage_s": _rounded(h.out_of_coverage_s),
    }


def _rounded(s: float | None) -> float | None:
    return round(s, 1) if s is not None else None


def hint_text(row: dict[str, Any], clock: CtlClock = WALL) -> str:
    """'lru3: ends in 12m30s, battery 62% left' / 'lru2 cannot: lru1-2: ...'; the
    row's wall seconds said in mission time on `clock` (× the sim's speed)."""
    if not row["moved"]:
        return f"{row['robot']} cannot: " + "; ".join(row["refused"].values())
    end_in = clock.span(row["end_in_s"])
    end = _duration(end_in) if end_in is not None else "never (a barrier)"
    stays = "".join(f"; {k} stays: {v}" for k, v in row["refused"].items())
    part = taken_words(len(row["moved"]), len(row["refused"]))
    return f"{row['robot']}: {part}ends in {end}{_battery(row)}{_coverage(row, clock)}{stays}"


def _coverage(row: dict[str, Any], clock: CtlClock) -> str:
    """', 3m10s out of coverage' (nothing without a site map: unknown)."""
    out = clock.span(row["out_of_coverage_s"])
    if out is None:
        return ""
    return f", {_duration(out)} out of coverage" if out >= 0.5 else ", in coverage throughout"


def _battery(row: dict[str, Any]) -> str:
    if row["battery_end"] is None:
        return ""
    assumed = " (no telemetry: full at start)" if row["battery_assumed"] else ""
    return f", battery {row['battery_end']:.0%} left{assumed}"


def _duration(s: float) -> str:
    s = max(0, int(round(s)))
    h, rest = divmod(s, 3600)
    m, sec = divmod(rest, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{sec:02d}s" if m else f"{sec}s")
