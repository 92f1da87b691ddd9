"""`ctl check` and `ctl timeline`: the plan's checks and predicted timeline,
computed here from what a console sees (backend.core.plan): the mission and
library, the robots' telemetry (waited for briefly), and the simulator's map
and status when one answers. The same inputs give a console the same answers.

    check [ROBOT...]   one line per finding (errors first), exit 1 while an
                       error is not waived; --json: {"ok", "errors",
                       "warnings", "waived", "findings": [...], "inputs"}
    timeline           per robot its skills' predicted start and end, waits,
                       battery and spans out of coverage, and the plan's end;
                       --json: {"now", "end", "critical", "critical_robot",
                       "robots": {...}} with ISO times

Their text is on the mission clock (backend/cli/ctl/clock.py): while a sim
runs, times `sim h:mm:ss` and waits and the link delay in sim seconds (the
forecast's wall seconds × its speed); else the wall's. --json stays wall.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import time
from datetime import UTC, datetime
from typing import Any

from backend.cli.ctl.clock import WALL, CtlClock
from backend.core.plan.branches import BranchCost
from backend.core.plan.checks import Finding, run_checks
from backend.core.plan.forecast import Forecast, Forecaster, RobotForecast, SkillForecast
from backend.core.plan.inputs import PlanInputs
from backend.exit_codes import EXIT_OK, EXIT_REFUSED
from backend.transport.timeouts import rtt

# seconds to wait for one sample of every online robot: a still robot sends one every
# 5 s (telemetry goes on change, backend/agent/telemetry.py), plus the link's round trip
TELEMETRY_WAIT = 5.5
MARK = {"error": ("✖", "E"), "warning": ("⚠", "W")}


def _print_json(obj: Any) -> None:
    print(json.dumps(obj, ensure_ascii=False, default=str), flush=True)


async def wait_telemetry(client: Any) -> None:
    """Wait briefly for one telemetry sample of every online robot."""
    done = asyncio.Event()

    def check(_event: object = None) -> None:  # any client event may complete it
        online = [n for n, r in client.robots.items() if r.online]
        if all(n in client.telemetry for n in online):
            done.set()

    client.add_listener(check)
    check()
    try:
        await asyncio.wait_for(done.wait(), TELEMETRY_WAIT + rtt(client.login.link_delay_hint))
    except TimeoutError:
        pass  # a robot that publishes nothing: shown and planned without its telemetry
    finally:
        client.remove_listener(check)


async def gather(client: Any, timeout: float) -> PlanInputs:
    return (await gather_clocked(client, timeout))[0]


async def gather_clocked(client: Any, timeout: float) -> tuple[PlanInputs, CtlClock]:
    """The plan's inputs, and the mission clock their text is said on (the
    sim's status asked once, for both)."""
    # imported here: the map's mirror is numpy, which other ctl commands never load
    from backend.client.planning import fetch_site, plan_inputs

    await wait_telemetry(client)
    site, status = await fetch_site(client.session, min(timeout, 3.0))
    now = time.time()
    clock = CtlClock.of_status(status, datetime.fromtimestamp(now, UTC))
    return plan_inputs(now, dict(client.telemetry), site, status), clock


async def sync_forecast(client: Any, op: Any, timeout: float) -> dict[str, Any]:
    """What `ctl sync` sends with the sync: the forecast of the skills it
    synchronizes (backend/core/plan/at_sync.py), from the inputs a console has."""
    from backend.core.plan.at_sync import at_sync

    inputs = await gather(client, timeout)
    forecast = Forecaster(client.library).forecast(client.mission, inputs)
    return at_sync(forecast, client.mission.tasks.get(op.robot, []), op.through)


def _inputs_json(inputs: PlanInputs) -> dict[str, Any]:
    return {
        "telemetry": sorted(inputs.robots),
        "site_map": inputs.site is not None,
        "link_delay_s": inputs.link.one_way_s,
        "speed": inputs.speed,
    }


def _inputs_text(inputs: PlanInputs, clock: CtlClock = WALL) -> str:
    tele = ", ".join(sorted(inputs.robots)) or "no robot"
    site = (
        "the site map" if inputs.site is not None else "no site map (coverage, terrain unchecked)"
    )
    return f"telemetry of {tele}; {site}; link delay {_delay(inputs.link.one_way_s, clock)}"


def _delay(wall_s: float, clock: CtlClock) -> str:
    """The link's one-way delay: `10 min` on the sim's clock, `2 s` on the wall's."""
    return clock.duration(wall_s) if clock.simulated else f"{wall_s:g} s"


# -- check ---------------------------------------------------------------------------


def _concerns(f: Finding, robots: list[str], owner: dict[str, str]) -> bool:
    return not robots or f.robot in robots or any(owner.get(s) in robots for s in f.skills)


def _finding_json(f: Finding) -> dict[str, Any]:
    return {
        "id": f.id,
        "rule": f.rule,
        "severity": f.severity,
        "robot": f.robot,
        "skills": list(f.skills),
        "message": f.message,
        "waiver": f.waiver.model_dump() if f.waiver is not None else None,
    }


def _finding_lines(f: Finding, unicode: bool) -> list[str]:
    mark = MARK[f.severity][0 if unicode else 1]
    lines = [f"{mark} {f.id}  {f.message}"]
    if f.waiver is not None:
        lines.append(f"  waived at revision {f.waiver.revision}: {f.waiver.reason}")
    return lines


async def check(client: Any, args: argparse.Namespace) -> int:
    from backend.cli.ctl.render import unicode_ok

    inputs, clock = await gather_clocked(client, args.timeout)
    found = _findings(client, list(args.robots or []), inputs)
    if args.json:
        _print_json(_check_json(found, inputs))
    else:
        _print_check(found, inputs, unicode_ok(), clock)
    return EXIT_REFUSED if any(f.blocking for f in found) else EXIT_OK


def _findings(client: Any, robots: list[str], inputs: PlanInputs) -> list[Finding]:
    """The plan's findings that concern `robots` (none given: all)."""
    m = client.mission
    owner = {s.id: r for r, t in m.tasks.items() for s in t}
    return [f for f in run_checks(m, client.library, inputs) if _concerns(f, robots, owner)]


def _check_json(found: list[Finding], inputs: PlanInputs) -> dict[str, Any]:
    errors = sum(f.severity == "error" for f in found)
    return {
        "ok": not any(f.blocking for f in found),
        "errors": errors,
        "warnings": len(found) - errors,
        "waived": sum(f.waiver is not None for f in found),
        "findings": [_finding_json(f) for f in found],
        "inputs": _inputs_json(inputs),
    }


def _print_check(
    found: list[Finding], inputs: PlanInputs, unicode: bool, clock: CtlClock = WALL
) -> None:
    for f in found:
        for line in _finding_lines(f, unicode):
            print(line)
    errors = sum(f.severity == "error" for f in found)
    waived = sum(f.waiver is not None for f in found)
    what = f"{errors} error(s) ({waived} waived), {len(found) - errors} warning(s)"
    if not found:
        what = "no findings: the plan passes every check"
    print(f"{what} — checked with {_inputs_text(inputs, clock)}", flush=True)


# -- timeline ------------------------------------------------------------------------


def _iso(t: float | None) -> str | None:
    return datetime.fromtimestamp(t, UTC).isoformat() if t is not None else None


def _clock(t: float) -> str:
    """A forecast's instant on the wall's clock (the JSON's summary)."""
    return WALL.at(t)


def _span_s(s: float) -> str:
    s = max(0.0, s)
    return (
        f"{int(s // 3600)}:{int(s % 3600 // 60):02d}:{int(s % 60):02d}"
        if s >= 3600
        else (f"{int(s // 60)}:{int(s % 60):02d}")
    )


def _skill_json(f: SkillForecast, s: Any) -> dict[str, Any]:
    return {
        "id": f.id,
        "skill": s.skill,
        "label": s.label,
        "status": s.status.value,
        "ready": _iso(f.ready),
        "start": _iso(f.start),
        "end": _iso(f.end),
        "wait_s": round(f.wait_s, 3),
        "barrier": f.barrier,
        "battery_start": f.battery_start,
        "battery_min": f.battery_min,
        "battery_end": f.battery_end,
        "out_of_coverage": [[_iso(a), _iso(b)] for a, b in f.out_of_coverage],
        "assumed": _branch_json(f.assumed),
        "worst": _branch_json(f.worst),
    }


def _branch_json(b: BranchCost | None) -> dict[str, Any] | None:
    """A contingency branch as the forecast costs it (backend.core.plan.branches)."""
    if b is None:
        return None
    return {
        "trigger": b.trigger,
        "branch": b.text,
        "before_s": round(b.before_s, 1),
        "busy_s": round(b.busy_s, 1),
        "battery_min": b.battery_min,
        "battery_end": b.battery_end,
    }


def _branch_words(f: SkillForecast) -> list[str]:
    """'on timeout → skip (assumed: its timeout is short)', 'if it fails:
    goto@POI-A +3:20, battery 12%'."""
    out = []
    if f.assumed is not None:
        out.append(f"on timeout → {f.assumed.text} (assumed: the timeout is shorter)")
    w = f.worst
    if w is not None and not (f.assumed is not None and w.trigger == "timeout"):
        when = "if it fails" if w.trigger == "failure" else "on timeout"
        out.append(f"{when}: {w.text} +{_span_s(w.busy_s)}, battery {_pct(w.battery_min)}")
    return out


def timeline_json(fc: Forecast, mission: Any) -> dict[str, Any]:
    robots: dict[str, Any] = {}
    for robot, r in fc.robots.items():
        skills = {s.id: s for s in mission.tasks.get(robot, [])}
        robots[robot] = {
            "end": _iso(r.end),
            "blocked_at": r.blocked_at,
            "battery_end": r.battery_end,
            "battery_assumed": r.battery_assumed,
            "halted": r.halted,
            "skills": [_skill_json(f, skills[f.id]) for f in fc.robot_skills(robot)],
        }
    return {
        "now": _iso(fc.now),
        "end": _iso(fc.end),
        "summary": fc.summary(_clock),
        "critical": fc.critical_path(),
        "critical_robot": fc.critical_robot,
        "robots": robots,
    }


def _pct(x: float | None) -> str:
    return "?" if x is None else f"{x * 100:.0f}%"


def _skill_line(f: SkillForecast, s: Any, clock: CtlClock = WALL) -> str:
    """A skill's predicted start and end, its wait (mission seconds), battery, spans out
    of coverage and contingency branches (robot seconds: mission time already)."""
    span = f"{clock.at(f.start)} - {clock.at(f.end)}"
    parts = [f"  {f.id:<12} {(s.label or s.skill)[:28]:<28} {span}"]
    if f.wait_s > 0.5:
        parts.append(f"waits {_span_s(clock.span(f.wait_s) or 0.0)} at {f.barrier}")
    if f.battery_end is not None:
        parts.append(f"battery {_pct(f.battery_end)}")
    for a, b in f.out_of_coverage:
        parts.append(f"out of coverage {clock.at(a)}-{clock.at(b)}")
    parts += _branch_words(f)
    return "  ".join(parts)


def timeline_text(fc: Forecast, mission: Any, clock: CtlClock = WALL) -> str:
    """The timeline for a person, its times on `clock` (the wall's without a sim)."""
    lines = [f"now {clock.at(fc.now)} · {fc.summary(clock.at)}"]
    for robot, r in fc.robots.items():
        skills = {s.id: s for s in mission.tasks.get(robot, [])}
        rows = [_skill_line(f, skills[f.id], clock) for f in fc.robot_skills(robot)]
        lines += [_robot_head(robot, r, bool(rows), clock), *rows]
    return "\n".join(lines)


def _robot_head(robot: str, r: RobotForecast, planned: bool, clock: CtlClock = WALL) -> str:
    """`lru1: ends 14:02:10, battery 40% at the end` (held, nothing planned)."""
    head = f"{robot}: ends {clock.at(r.end)}" if r.end is not None else f"{robot}:"
    if r.blocked_at is not None:
        head += f" never: held at {r.blocked_at}"
    elif not planned:
        head += " nothing planned"
    if r.battery_end is not None:
        head += f", battery {_pct(r.battery_end)} at the end" + (
            " (from an assumed full battery)" if r.battery_assumed else ""
        )
    return head


async def timeline(client: Any, args: argparse.Namespace) -> int:
    inputs, clock = await gather_clocked(client, args.timeout)
    fc = Forecaster(client.library).forecast(client.mission, inputs)
    if args.json:
        _print_json(timeline_json(fc, client.mission))
    else:
        print(timeline_text(fc, client.mission, clock), flush=True)
    return EXIT_OK
