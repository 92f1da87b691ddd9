"""Predictions against the simulator: the opening mission, predicted vs actual.

    .venv/bin/python bench/bench_plan_sim.py                 # print a Markdown section
    .venv/bin/python bench/bench_plan_sim.py --write docs/performance.md

The mission server and `missionctl sim` (the default world, --speed 10, seed 1)
run as subprocesses; this process follows them like a console (telemetry, the
map feed, the sim's status), synchronizes every robot's whole plan of
missions/mars_sample_return.yaml, takes the forecast (backend.core.plan) the
moment before `run`, runs every robot, and waits until every skill finished.
For each skill: predicted and actual end, both from the run command, in robot
(sim) seconds (wall seconds x the speed); the errors' median and worst.

With --write, the "## Plan: predictions against the simulator" section of the
file is replaced; the rest is left as it is.
"""

from __future__ import annotations

import argparse
import asyncio
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
from backend.client.mapfollow import MapFeed  # noqa: E402
from backend.client.planning import MirrorSite, plan_inputs  # noqa: E402
from backend.core.model import ACTIVE, FINISHED, Status  # noqa: E402
from backend.core.ops import Control, Sync  # noqa: E402
from backend.core.plan.forecast import Forecaster  # noqa: E402
from backend.protocol import mapfeed as mf  # noqa: E402

SPEED = 10.0
HEADING = "## Plan: predictions against the simulator"
TIMEOUT = 600.0  # wall seconds for the whole mission


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
            for s in task:
                f = fc.skill(s.id)
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
        "The world is the simulator lane's current one (issue 21 recalibrates it): these "
        "figures measure the library's models against it as it is on this branch.",
        "",
        "Reproduce: `.venv/bin/python bench/bench_plan_sim.py --write docs/performance.md` "
        f"({date.today().isoformat()}; {machine()}).",
        "",
        "| robot | skill | status | predicted end | actual end | error |",
        "| --- | --- | --- | ---: | ---: | ---: |",
    ]
    for r in rows:
        p = f"{r['predicted']:.0f} s" if r["predicted"] is not None else "none"
        a = f"{r['actual']:.0f} s" if r["actual"] is not None else "-"
        e = (
            f"{r['actual'] - r['predicted']:+.0f} s"
            if r["predicted"] is not None and r["actual"] is not None
            else ""
        )
        lines.append(f"| {r['robot']} | {r['id']} {r['label']} | {r['status']} | {p} | {a} | {e} |")
    if errors:
        worst = max(ok, key=lambda r: abs(r["actual"] - r["predicted"]))
        lines += [
            "",
            f"Over the {len(ok)} skills that succeeded: median absolute error of the end "
            f"{statistics.median(abs(e) for e in errors):.0f} s "
            f"({statistics.median(rel) * 100:.0f} % of the actual end), worst "
            f"{max(abs(e) for e in errors):.0f} s ({worst['id']}, {worst['label']}).",
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
