"""Benchmark of the plan's predictions and checks (backend.core.plan; not a test).

    .venv/bin/python bench/bench_plan.py                 # print a Markdown table
    .venv/bin/python bench/bench_plan.py --write docs/performance.md

On the console benchmark's 10,000-skill mission (20 robots x 500 drive_to:
200 done, one running, 99 queued, 200 planned each; 10 barriers), with every
robot's telemetry and, for the "map" rows, a 160 x 160 site map (rocks, a
coverage disc) as the map feed's mirror gives it (backend/client/planning.py):

- cold forecast: a new `Forecaster` (every leg built);
- after one event: a skill's status changes (the event applied to the
  mission, as a console's mirror does) -> the next forecast;
- after an edit of an unsynchronized skill (its goal moves);
- after one robot's telemetry sample;
- the clock moving on (nothing else changed);
- the plan checks on a forecast; the server's sync gate for one robot.

The baseline is applying that one event batch to the mission
(`apply_events`), which every console does anyway: each row says how many
times that it costs. With --write, the "## Plan: predictions and checks"
section of the file is replaced; the rest is left as it is.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from collections.abc import Callable
from datetime import date
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench_console import build_mission  # noqa: E402
from report import machine, write_section  # noqa: E402

from backend.client.planning import MirrorSite  # noqa: E402
from backend.core import events as ev  # noqa: E402
from backend.core.plan.checks import run_checks  # noqa: E402
from backend.core.plan.forecast import Forecaster  # noqa: E402
from backend.core.plan.gate import check_sync  # noqa: E402
from backend.core.plan.inputs import PlanInputs, RobotNow  # noqa: E402
from backend.core.rules.base import Refusal  # noqa: E402
from backend.core.rules.engine import Engine  # noqa: E402

REPEAT = 21
HEADING = "## Plan: predictions and checks"


def site_map() -> MirrorSite:
    import numpy as np

    from backend.protocol.mapfeed import (
        LanderItem,
        MapMeta,
        MapMirror,
        MapObjects,
        MapSnapshot,
        TileEncoder,
    )

    n = 160
    meta = MapMeta(world="bench", seed=1, x0=-160, y0=-160, cell=2.0, width=n, height=n)
    rng = np.random.default_rng(1)
    terrain = np.ones((n, n), dtype=np.uint8)
    for _ in range(40):  # rock fields
        i, j, r = rng.integers(0, n), rng.integers(0, n), rng.integers(1, 4)
        terrain[max(0, i - r) : i + r, max(0, j - r) : j + r] = 3
    yy, xx = np.mgrid[0:n, 0:n]
    coverage = (np.hypot(xx - n / 2, yy - n / 2) < 30).astype(np.uint8) * 200
    tiles = TileEncoder(meta).delta({"terrain": terrain, "coverage": coverage})
    mirror = MapMirror()
    lander = LanderItem(x=0, y=0, pad_radius=5, comm_radius=60)
    mirror.apply_snapshot(
        MapSnapshot(meta=meta, seq=0, sim_time=0, tiles=tiles, objects=MapObjects(lander=lander))
    )
    return MirrorSite(mirror)


def telemetry(mission: Any, t: float, moved: str | None = None) -> dict[str, RobotNow]:
    out = {}
    for robot, task in mission.tasks.items():
        running = next((s for s in task if s.status.value == "running"), None)
        x = 3.0 if robot == moved else 0.0
        out[robot] = RobotNow(
            at=t,
            x=x,
            y=float(robot[1:]),
            battery=0.9,
            skill=running.id if running else None,
            progress=0.5,
            eta_s=30.0,
            mode="running",
        )
    return out


def median_ms(fn: Callable[[], Any], repeat: int = REPEAT) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


def measure(with_map: bool) -> dict[str, float]:
    mission, library = build_mission()
    site = site_map() if with_map else None
    now = time.time()
    base = PlanInputs(now=now, robots=telemetry(mission, now), site=site, home=(0.0, 0.0))
    out: dict[str, float] = {}
    out["cold"] = median_ms(lambda: Forecaster(library).forecast(mission, base), 3)
    f = Forecaster(library)
    fc = f.forecast(mission, base)
    revision = [mission.revision]

    def batch(events: list[Any]) -> ev.EventBatch:
        revision[0] += 1
        return ev.EventBatch(revision=revision[0], events=events)

    # one status change: a queued skill of r03 pauses, then runs again (two events in turn)
    flips = iter(["paused", "running"] * REPEAT * 2)
    out["apply"] = median_ms(
        lambda: ev.apply_events(
            mission, batch([ev.SkillStatusChanged(id="r03-201", status=next(flips))])
        )
    )

    def status_event() -> None:
        ev.apply_events(mission, batch([ev.SkillStatusChanged(id="r03-201", status=next(flips))]))
        f.forecast(mission, base)

    out["event"] = median_ms(status_event) - out["apply"]
    xs = iter(range(10_000))

    def edit_event() -> None:
        goal = {
            "x": float(next(xs) % 90),
            "y": 7.0,
            "z": 0.0,
            "roll": 0.0,
            "pitch": 0.0,
            "yaw": 0.0,
        }
        ev.apply_events(
            mission,
            batch(
                [
                    ev.SkillEdited(
                        id="r05-350", params={"goal": goal, "speed": 0.5, "tolerance": 0.5}
                    )
                ]
            ),
        )
        f.forecast(mission, base)

    out["edit"] = median_ms(edit_event) - out["apply"]
    ticks = iter(range(1, 10_000))

    def sample() -> None:
        k = next(ticks)
        f.forecast(
            mission,
            PlanInputs(
                now=now + k,
                robots={**base.robots, "r07": telemetry(mission, now + k, "r07")["r07"]},
                site=site,
                home=(0.0, 0.0),
            ),
        )

    out["telemetry"] = median_ms(sample)
    out["clock"] = median_ms(
        lambda: f.forecast(
            mission, PlanInputs(now=now + next(ticks), robots=base.robots, site=site, home=(0, 0))
        )
    )
    fc = f.forecast(mission, base)
    out["checks"] = median_ms(lambda: run_checks(mission, library, base, forecast=fc))
    engine = Engine(mission, library)

    def gate() -> None:
        try:
            check_sync(engine, "r04", ["r04-301"])
        except Refusal:
            pass

    out["gate"] = median_ms(gate)
    return out


ROWS = [
    ("cold", "cold forecast (every leg built, new `Forecaster`)"),
    ("event", "forecast after one status event"),
    ("edit", "forecast after an edit of an unsynchronized skill"),
    ("telemetry", "forecast after one robot's telemetry sample"),
    ("clock", "forecast as the clock moves on (nothing else changed)"),
    ("checks", "plan checks on a forecast (every rule)"),
    ("gate", "server's sync gate for one robot (mission and library only)"),
]


def table(plain: dict[str, float], mapped: dict[str, float]) -> str:
    lines = [
        "| measure | no map | with the site map | cold / this (no map, map) |",
        "| --- | ---: | ---: | ---: |",
        f"| baseline: apply the one event batch to the mission | {plain['apply']:.3f} ms | "
        f"{mapped['apply']:.3f} ms | |",
    ]
    for key, what in ROWS:
        a, b = plain[key], mapped[key]
        ratio = "1" if key == "cold" else f"{plain['cold'] / a:.0f}x, {mapped['cold'] / b:.0f}x"
        lines.append(f"| {what} | {a:.1f} ms | {b:.1f} ms | {ratio} |")
    return "\n".join(lines)


INTRO = (
    "Predictions (`backend.core.plan.forecast`) and plan checks (`backend.core.plan.checks`) "
    "on the console benchmark's 10,000-skill mission (20 robots x 500 drive_to: 200 done, one "
    'running, 99 queued, 200 planned each; 10 barriers), every robot with telemetry; "with the '
    "site map\" adds a 160 x 160 map (rock fields, a coverage disc) read through the map feed's "
    "mirror (`backend/client/planning.py`: coverage along every path, routes round rocks). "
    "Medians of {repeat} runs (cold: of 3). The baseline is applying the one event batch to the "
    "mission, which every console does anyway; the last column says how many times cheaper "
    "than a cold forecast each recompute is."
)
OUTRO = (
    "An event recomputes the legs of the skills it replaced and the course of their robot "
    "(legs elsewhere stay cached); the clock pass lays *segments* (runs of skills without a "
    "wait), not skills, so it costs per robot the number of its barriers; a skill's times are "
    "looked up when asked (a timeline asks only for what it shows). The checks walk every "
    "planned skill once per rule; with a map they ask it about every goal and path. A map "
    "update that changes the terrain or the coverage makes every leg cold again (the cold row "
    "with the map): a console recomputes on map updates at most every few seconds."
)


def section(plain: dict[str, float], mapped: dict[str, float]) -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    how = (
        "Reproduce: `.venv/bin/python bench/bench_plan.py --write docs/performance.md` "
        f"({date.today().isoformat()}; {machine()}; load average {load:.1f} while measuring)."
    )
    parts = [HEADING, INTRO.format(repeat=REPEAT), how, table(plain, mapped), OUTRO]
    return "\n\n".join(parts) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--write", metavar="FILE", help=f"write/update the '{HEADING}' section of FILE")
    args = ap.parse_args()
    plain = measure(False)
    mapped = measure(True)
    text = section(plain, mapped)
    if args.write:
        write_section(Path(args.write), HEADING, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
