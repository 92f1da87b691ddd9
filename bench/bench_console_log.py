"""The console's event log at its bound (10,000 entries, console/state/eventlog.py):
memory of the entries, the log screen's redraw (a filter keystroke) and one
new entry while shown, against a 100-entry log measured in the same run.

    .venv/bin/python bench/bench_console_log.py [--write docs/performance.md]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import time
import tracemalloc
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from report import machine, write_section  # noqa: E402

from console.state.eventlog import LOG_LIMIT, EventLog  # noqa: E402

T0 = datetime(2026, 3, 14, 10, 42, 7, tzinfo=UTC)


def fill(log: EventLog, n: int) -> None:
    for i in range(n):
        log.add(
            "report",
            f"▶ lru{i % 20}-{i} running",
            T0,
            robots=[f"lru{i % 20}"],
            skill=f"lru{i % 20}-{i}",
            client=f"lru{i % 20}",
            op="report",
            revision=i,
        )


def memory(n: int) -> float:
    tracemalloc.start()
    log = EventLog()
    fill(log, n)
    size, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return size / 1e6


async def screen_times(n: int, repeats: int = 5) -> tuple[float, float]:
    """(median redraw s, median append-one-entry s) of the log screen."""
    from console.app import MissionApp
    from console.state.changes import Topic, change

    app = MissionApp()
    app.animation_level = "none"
    async with app.run_test(size=(120, 40)) as pilot:
        fill(app.event_log, n)
        await pilot.press("f5")
        await pilot.pause()
        screen = app.screen
        redraws, appends = [], []
        for _ in range(repeats):
            t = time.perf_counter()
            screen.redraw()
            await pilot.pause()
            redraws.append(time.perf_counter() - t)
            t = time.perf_counter()
            app.event_log.add("refusal", "one more", T0, robots=["lru1"])
            app.publish(change(Topic.LOG))
            await pilot.pause()
            appends.append(time.perf_counter() - t)
        return statistics.median(redraws), statistics.median(appends)


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--write", metavar="FILE", help="replace the '## Console event log' section of FILE"
    )
    args = ap.parse_args()
    base_n = 100
    mem_full, mem_base = memory(LOG_LIMIT), memory(base_n)
    redraw_full, append_full = asyncio.run(screen_times(LOG_LIMIT))
    redraw_base, append_base = asyncio.run(screen_times(base_n))
    import textual

    text = f"""## Console event log

The event log keeps the last {LOG_LIMIT:,} entries in memory; its screen shows the last 1,000 \
matching ones (a `DataTable` of 10,000 rows took 2.7 s to fill on this machine). Headless at \
120x40, median of 5.

Reproduce: `.venv/bin/python bench/bench_console_log.py --write docs/performance.md` \
({time.strftime("%Y-%m-%d")}, {machine(f"textual {textual.__version__}")}).

| measure | {LOG_LIMIT:,} entries | {base_n} entries (baseline) | ratio |
| --- | ---: | ---: | ---: |
| memory of the entries (tracemalloc) | {mem_full:.1f} MB | {mem_base:.2f} MB | \
{mem_full / mem_base:.0f}x |
| log screen redraw (a filter keystroke) | {redraw_full * 1000:.0f} ms | \
{redraw_base * 1000:.0f} ms | {redraw_full / redraw_base:.1f}x |
| one new entry while the log is shown | {append_full * 1000:.1f} ms | \
{append_base * 1000:.1f} ms | {append_full / append_base:.1f}x |
"""
    print(text)
    if args.write:
        write_section(Path(args.write), "## Console event log", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
