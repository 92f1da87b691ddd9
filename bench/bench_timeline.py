"""Benchmark of the timeline screen against the schedule panel, in one run (not a test).

    .venv/bin/python bench/bench_timeline.py                 # print a Markdown section
    .venv/bin/python bench/bench_timeline.py --write docs/performance.md

The console benchmark's 10,000-skill mission (bench_console.build_mission),
headless Textual at 200x50, in one process: the state is posted and the
schedule's first frame timed (as bench_console does); then the plan is
refreshed (forecast and checks) and the timeline (F7) shown: time to its
first frame; then one status change (posted as an event) until the timeline
shows the new forecast, against the same change on the schedule. With
--write, the "## Console: timeline" section is replaced; the rest is left.
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import time
from datetime import date
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench_console import SIZE, FrameClock, build_mission  # noqa: E402
from report import machine, write_section  # noqa: E402

HEADING = "## Console: timeline"
CHANGES = 15


async def run() -> dict[str, float]:
    from backend.client.events import BatchApplied, ConnectionState, StateSynced
    from backend.core import events as ev
    from backend.protocol.messages import StateSnapshot
    from console.app import MissionApp
    from console.messages import Incoming

    mission, library = build_mission()
    app = MissionApp()
    app.animation_level = "none"
    out: dict[str, float] = {}
    async with app.run_test(size=SIZE) as pilot:
        clock = FrameClock(app)
        app.post_message(Incoming(ConnectionState("connected")))
        await pilot.pause()
        screen = app.mission_screen
        t0 = time.perf_counter()
        snap = StateSnapshot(
            server_id="bench", revision=mission.revision, mission=mission, library=library
        )
        app.post_message(Incoming(StateSynced(snap)))
        out["schedule_first_ms"] = 1e3 * await clock.next_frame(
            t0, lambda: len(screen.schedule.columns) == 20
        )
        await pilot.pause()
        t = time.perf_counter()
        app.refresh_plan(force=True)
        out["plan_ms"] = 1e3 * (time.perf_counter() - t)
        t = time.perf_counter()
        # watch frames while the key is processed: `press` returns only once the app is
        # idle, after the first frame, and the next frame may wait for a timer's tick
        first = asyncio.ensure_future(
            clock.next_frame(t, lambda: app.screen is not screen and bool(app.screen.view.rows))
        )
        await pilot.press("f7")
        out["timeline_first_ms"] = 1e3 * await first
        rev = mission.revision
        tl_times, sched_times = [], []
        for k in range(CHANGES):
            for shown, times in (("timeline", tl_times), ("mission", sched_times)):
                app.switch_mode(shown)
                await pilot.pause()
                rev += 1
                sid = f"r{k % 4:02d}-{202 + k}"
                batch = ev.EventBatch(
                    revision=rev, events=[ev.SkillStatusChanged(id=sid, status="paused")]
                )
                # the app's handler called as the message loop would (for both screens),
                # then the plan timer's tick without waiting for it
                t = time.perf_counter()
                app._incoming(Incoming(BatchApplied(batch)))
                app.refresh_plan(force=True)
                times.append(
                    await clock.next_frame(
                        t, lambda sid=sid: app.model.find(sid)[2].status.value == "paused"
                    )
                )
        out["timeline_change_ms"] = 1e3 * statistics.median(tl_times)
        out["schedule_change_ms"] = 1e3 * statistics.median(sched_times)
    return out


def section(r: dict[str, float]) -> str:
    ratio_first = r["timeline_first_ms"] / r["schedule_first_ms"]
    ratio_change = r["timeline_change_ms"] / r["schedule_change_ms"]
    return "\n".join(
        [
            HEADING,
            "",
            "The timeline screen (F7) against the schedule panel on the console benchmark's "
            "10,000-skill mission (20 robots x 500 drive_to; 10 barriers), headless at 200x50, "
            "in one process: the schedule's first frame after the state is posted; the plan's "
            "forecast and checks computed from scratch; the timeline's first frame once shown; "
            f"one status change until the frame shows it (median of {CHANGES}: the app's "
            "handler of the event, the plan's recompute, the frame; the schedule shown in "
            "turn with the timeline, so both pay the same).",
            "",
            "Reproduce: `.venv/bin/python bench/bench_timeline.py --write docs/performance.md` "
            f"({date.today().isoformat()}; {machine()}).",
            "",
            "| measure | timeline | schedule panel | timeline / schedule |",
            "| --- | ---: | ---: | ---: |",
            f"| first frame | {r['timeline_first_ms']:.0f} ms | {r['schedule_first_ms']:.0f} ms "
            f"| {ratio_first:.2f} |",
            f"| one status change -> frame, median | {r['timeline_change_ms']:.1f} ms | "
            f"{r['schedule_change_ms']:.1f} ms | {ratio_change:.2f} |",
            f"| the plan's forecast and checks from scratch | {r['plan_ms']:.0f} ms | | |",
            "",
        ]
    )


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--write", metavar="FILE", help=f"write/update the '{HEADING}' section of FILE")
    args = ap.parse_args()
    text = section(asyncio.run(run()))
    if args.write:
        write_section(Path(args.write), HEADING, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
