"""Predictions against the simulator: the opening mission, predicted vs actual.

    .venv/bin/python bench/bench_plan_sim.py                 # print a Markdown section
    .venv/bin/python bench/bench_plan_sim.py --write docs/performance.md

The mission server and `missionctl sim` (the default world, --speed 10, seed 1)
run as subprocesses; this process follows them like a console (telemetry, the
map feed, the sim's status), synchronizes every robot's whole plan of
missions/mars_sample_return.yaml, takes the forecast (backend.core.plan) the
moment before `run`, runs every robot, and waits until every skill finished.
For each skill: predicted and actual end, both from the run command, in robot
(sim) seconds (wall seconds x the speed); the errors' median and worst. And the
battery each skill used: predicted (the forecast's level at its start minus at its
end) against the simulator's (the robot's telemetry, interpolated at the skill's
reported start and end), for the skills of robots with a battery that do not charge.

With --write, the "## Plan: predictions against the simulator" section of the
file is replaced; the rest is left as it is.
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import statistics
import sys
import tempfile
import time
from datetime import date
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench_sim import MISSION, WORLD, Proc  # noqa: E402
from report import machine, write_section  # noqa: E402

from backend import transport  # noqa: E402
from backend.client.client import MissionClient  # noqa: E402
from backend.client.events import ClientEvent, TelemetryReceived  # noqa: E402
from backend.client.mapfollow import MapFeed  # noqa: E402
from backend.client.planning import MirrorSite, plan_inputs  # noqa: E402
from backend.core.model import ACTIVE, FINISHED, Status  # noqa: E402
from backend.core.ops import Control, Sync  # noqa: E402
from backend.core.plan.forecast import Forecaster  # noqa: E402
from backend.protocol import mapfeed as mf  # noqa: E402

SPEED = 10.0
HEADING = "## Plan: predictions against the simulator"
TIMEOUT = 600.0  # wall seconds for the whole mission
TARGET = 0.10  # median error of the battery used per skill (issue 34)

Samples = list[tuple[float, float]]  # (robot's clock, battery), in time order


def battery_at(samples: Samples, t: float) -> float | None:
    """The battery at time t, interpolated between the telemetry samples around it."""
    if not samples:
        return None
    i = bisect.bisect_left([at for at, _ in samples], t)
    if i == 0 or i == len(samples):
        return samples[min(i, len(samples) - 1)][1]
    (t0, b0), (t1, b1) = samples[i - 1], samples[i]
    return b0 + (b1 - b0) * (t - t0) / (t1 - t0) if t1 > t0 else b1


def _use(fc: Any, robot: str, sid: str) -> float | None:
    """The battery the forecast has the skill use (None: no battery, or it charges)."""
    track = fc.tracks.get(robot)
    i = track.course.index.get(sid) if track is not None else None
    if i is None:
        return None
    step = track.course.steps[i]
    if step.leg is None or step.leg.charge_to is not None or step.battery_end is None:
        return None
    return step.battery_start - step.battery_end


def _over(task: list[Any]) -> bool:
    """Every skill finished, or a failure halted the robot."""
    if all(s.status in FINISHED for s in task):
        return True
    return any(s.status == Status.FAILURE for s in task) and not any(
        s.status in ACTIVE for s in task
    )


async def run(tmp: Path) -> dict[str, Any]:
    endpoint = transport.loopback_endpoint(transport.free_port())
    server = Proc(
        [
            sys.executable,
            "-m",
            "backend.cli",
            "server",
            "--mission",
            str(MISSION),
            "--listen",
            endpoint,
            "--db",
            str(tmp / "plan.db"),
        ],
        tmp / "server.log",
    )
    sim = client = feed = None
    try:
        server.wait_line("listening on")
        client = MissionClient(endpoint, telemetry=True)
        await client.connect()
        sim = Proc(
            [
                sys.executable,
                "-m",
                "backend.cli",
                "sim",
                "--mission",
                str(MISSION),
                "--world",
                str(WORLD),
                "--connect",
                endpoint,
                "--speed",
                f"{SPEED:g}",
                "--seed",
                "1",
            ],
            tmp / "sim.log",
        )
        sim.wait_line("missionctl sim: world")
        m = client.mission
        await client.wait_for(lambda m: all(client.robots[r].online for r in m.robots), 60)
        feed = MapFeed(client.session, lambda _u: None)
        await feed.start()
        samples: dict[str, Samples] = {r: [] for r in m.robots}

        def telemetry(event: ClientEvent) -> None:
            if isinstance(event, TelemetryReceived):
                t = event.telemetry
                samples.setdefault(t.robot, []).append((t.at.timestamp(), t.battery))

        client.add_listener(telemetry)
        for robot in m.robots:
            await client.submit(Sync(robot=robot), timeout=30)
        await client.wait_for(lambda m: all(r in client.telemetry for r in m.robots), 30)
        status = mf.SimStatus.model_validate_json(
            await transport.query(client.session, mf.KEY_STATUS, b"", timeout=10)
        )
        site = MirrorSite(feed.mirror) if feed.mirror.ready else None
        inputs = plan_inputs(time.time(), dict(client.telemetry), site, status)
        fc = Forecaster(client.library).forecast(client.mission, inputs)
        t0 = time.time()
        await client.submit(Control(op="run"), timeout=30)
        await client.wait_for(lambda m: all(_over(t) for t in m.tasks.values()), TIMEOUT)
        rows = []
        for robot, task in client.mission.tasks.items():
            seen = sorted(samples.get(robot, []))
            for s in task:
                f = fc.skill(s.id)
                use = _use(fc, robot, s.id)
                used = None
                if use is not None and s.started_at and s.finished_at:
                    b0 = battery_at(seen, s.started_at.timestamp())
                    b1 = battery_at(seen, s.finished_at.timestamp())
                    used = b0 - b1 if b0 is not None and b1 is not None else None
                rows.append(
                    {
                        "robot": robot,
                        "id": s.id,
                        "label": s.label or s.skill,
                        "status": s.status.value,
                        "predicted": (f.end - t0) * SPEED if f else None,
                        "actual": (s.finished_at.timestamp() - t0) * SPEED
                        if s.finished_at
                        else None,
                        "use_predicted": use,
                        "use_actual": used,
                        "info": s.status_info,
                    }
                )
        return {"rows": rows, "site": site is not None, "speed": status.speed}
    finally:
        if feed is not None:
            feed.close()
        if client is not None:
            await client.close()
        if sim is not None:
            sim.stop()
        server.stop()


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{x * 100:.1f} %"


def _energy(rows: list[dict[str, Any]]) -> list[str]:
    """The battery-use summary: median and worst relative error, against the target."""
    both = [
        r
        for r in rows
        if r["status"] == Status.SUCCESS
        and r["use_predicted"] is not None
        and r["use_actual"] is not None
        and r["use_actual"] > 0
    ]
    if not both:
        return []
    rel = [abs(r["use_predicted"] - r["use_actual"]) / r["use_actual"] for r in both]
    worst = max(zip(rel, both, strict=True), key=lambda x: x[0])
    median = statistics.median(rel)
    verdict = "within" if median <= TARGET else "above"
    return [
        "",
        f"Battery used, over the {len(both)} skills that succeeded on a robot with a battery "
        f"and do not charge: median error {median * 100:.1f} % of the simulator's "
        f"({verdict} the {TARGET * 100:.0f} % target), worst {worst[0] * 100:.0f} % "
        f"({worst[1]['id']}, {worst[1]['label']}); in all "
        f"{sum(r['use_predicted'] for r in both) * 100:.1f} % of a battery predicted, "
        f"{sum(r['use_actual'] for r in both) * 100:.1f} % used.",
    ]


def section(result: dict[str, Any]) -> str:
    rows = result["rows"]
    ok = [r for r in rows if r["status"] == Status.SUCCESS and r["predicted"] is not None]
    errors = [r["actual"] - r["predicted"] for r in ok]
    rel = [abs(e) / r["actual"] for e, r in zip(errors, ok, strict=True) if r["actual"] > 0]
    lines = [
        HEADING,
        "",
        "The opening mission (missions/mars_sample_return.yaml) in the simulator, default world, "
        f"`--speed {SPEED:g}`, seed 1: every robot's plan synchronized, the forecast taken "
        "just before `run` (with the robots' telemetry, the map feed and the sim's status), "
        "then every skill run to its end. Times are robot (sim) seconds from the run command. "
        "Battery used is in % of a full battery: predicted, the forecast's level at the "
        "skill's start minus at its end; simulated, the robot's telemetry at the skill's "
        "reported start minus at its end (interpolated between samples); not for charging "
        "skills nor the lander (no battery). The library's figures are the world's "
        "(sim/calibration.py; tests/sim/test_calibration.py fails when they drift apart).",
        "",
        "Reproduce: `.venv/bin/python bench/bench_plan_sim.py --write docs/performance.md` "
        f"({date.today().isoformat()}; {machine()}).",
        "",
        "| robot | skill | status | predicted end | actual end | error "
        "| battery predicted | battery used | error |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        p = f"{r['predicted']:.0f} s" if r["predicted"] is not None else "none"
        a = f"{r['actual']:.0f} s" if r["actual"] is not None else "-"
        e = (
            f"{r['actual'] - r['predicted']:+.0f} s"
            if r["predicted"] is not None and r["actual"] is not None
            else ""
        )
        up, ua = r["use_predicted"], r["use_actual"]
        ue = f"{(up - ua) / ua * 100:+.0f} %" if up is not None and ua else ""
        lines.append(
            f"| {r['robot']} | {r['id']} {r['label']} | {r['status']} | {p} | {a} | {e} "
            f"| {_pct(up)} | {_pct(ua)} | {ue} |"
        )
    if errors:
        worst = max(ok, key=lambda r: abs(r["actual"] - r["predicted"]))
        lines += [
            "",
            f"Over the {len(ok)} skills that succeeded: median absolute error of the end "
            f"{statistics.median(abs(e) for e in errors):.0f} s "
            f"({statistics.median(rel) * 100:.0f} % of the actual end), worst "
            f"{max(abs(e) for e in errors):.0f} s ({worst['id']}, {worst['label']}).",
        ]
    lines += _energy(rows)
    lines += [
        "",
        "Before issue 35 (the library's rovers at 1 km per battery, explore costing only a "
        "rover's work, Ardea at 2 m/s and 64 m²/s), this bench measured on 2026-11-27: median "
        "battery error 50.0 % (45.4 % of a battery predicted, 72.7 % used), median end error "
        "10 s, worst 81 s (ardea-4, recharge). Known outlier now: an explore of a small area "
        "(lru1-2, 1200 m²) maps in about half the time the survey rate predicts (the rate is "
        "for large areas; the sensor's first look and the lanes' overlap take in much of a "
        "small one).",
    ]
    failed = [r for r in rows if r["status"] == Status.FAILURE]
    if failed:
        lines.append(
            "Failed in the run (not counted): "
            + "; ".join(f"{r['id']}: {r['info']}" for r in failed)
            + "."
        )
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--write", metavar="FILE", help=f"write/update the '{HEADING}' section of FILE")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        result = asyncio.run(run(Path(tmp)))
    text = section(result)
    if args.write:
        write_section(Path(args.write), HEADING, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
