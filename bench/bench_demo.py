"""Benchmark: `missionctl demo` launch to first paint (not a test).

    .venv/bin/python bench/bench_demo.py                 # print a Markdown table
    .venv/bin/python bench/bench_demo.py --write docs/performance.md

Runs `missionctl demo` in a pseudo-terminal (80x24, TERM=xterm-256color) and
measures from process start until the terminal output shows the Mars mission
painted: a robot name and a skill label of the mission's plan. The baseline,
measured in the same run and the same way, is a bare Textual app (one Static)
until its text appears: what any Textual program costs to start and paint.
Each run ends with Ctrl+Q; the script then checks that the demo and every
process it started (server, sim) have exited. With --write, the
"## Demo start-up" section of the file is replaced.
"""

from __future__ import annotations

import argparse
import fcntl
import os
import re
import select
import statistics
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

from report import machine, write_section

ROOT = Path(__file__).resolve().parents[1]
MISSIONCTL = Path(sys.executable).with_name("missionctl")
SIZE = (80, 24)
RUNS = 5
ANSI = re.compile(rb"\x1b(\[[0-9;?<>=]*[ -/]*[@-~]|\][^\x07\x1b]*(\x07|\x1b\\)|[@-Z\\-_])")
DEMO_MARKS = ("lru1", "drive to POI-A")  # a robot and a skill label of the Mars mission
BASELINE_MARK = "hello from a bare textual app"
BASELINE_APP = f"""
from textual.app import App
from textual.widgets import Static
class Bare(App):
    def compose(self):
        yield Static({BASELINE_MARK!r})
Bare().run()
"""


def children(pid: int) -> set[int]:
    """Every descendant of `pid` now (from /proc)."""
    parents: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            parents[int(entry)] = int(stat.rsplit(")", 1)[1].split()[1])
    out: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        for c, pp in parents.items():
            if pp == p and c not in out:
                out.add(c)
                todo.append(c)
    return out


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


class PtyRun:
    """A command in a pseudo-terminal; its output read as plain text."""

    def __init__(self, argv: list[str]):
        self.master, slave = os.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", SIZE[1], SIZE[0], 0, 0))
        env = dict(
            os.environ, TERM="xterm-256color", COLORTERM="truecolor", TEXTUAL_ANIMATIONS="none"
        )
        env.pop("TEXTUAL", None)
        self.t0 = time.perf_counter()
        self.proc = subprocess.Popen(
            argv, stdin=slave, stdout=slave, stderr=slave, env=env, cwd=ROOT, start_new_session=True
        )
        os.close(slave)
        self.raw = b""

    def text(self) -> str:
        return ANSI.sub(b"", self.raw).decode("utf-8", "replace")

    def wait_for(self, marks: tuple[str, ...], timeout: float) -> float:
        """Seconds from start until every mark has appeared in the output."""
        deadline = self.t0 + timeout
        while True:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                raise TimeoutError(
                    f"{marks} not painted after {timeout:g} s; output:\n{self.text()[-2000:]}"
                )
            ready, _, _ = select.select([self.master], [], [], remaining)
            if ready:
                try:
                    chunk = os.read(self.master, 65536)
                except OSError:  # the child closed the terminal
                    chunk = b""
                if not chunk:
                    raise RuntimeError(
                        f"exited before painting {marks} (code {self.proc.poll()}):\n"
                        f"{self.text()[-2000:]}"
                    )
                self.raw += chunk
                if all(m in self.text() for m in marks):
                    return time.perf_counter() - self.t0

    def drain(self, seconds: float) -> None:
        end = time.perf_counter() + seconds
        while (left := end - time.perf_counter()) > 0:
            ready, _, _ = select.select([self.master], [], [], left)
            if not ready:
                return
            try:
                if not os.read(self.master, 65536):
                    return
            except OSError:
                return

    def quit(self, timeout: float = 15.0) -> tuple[int | None, list[int]]:
        """Ctrl+Q; returns (exit code, pids of descendants still alive)."""
        descendants = children(self.proc.pid)
        os.write(self.master, b"\x11")
        deadline = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < deadline:
            self.drain(0.1)  # keep reading: a full terminal buffer would block its writes
        code = self.proc.poll()
        while any(alive(p) for p in descendants) and time.monotonic() < deadline:
            time.sleep(0.05)  # polling other processes' exit: nothing to wait on
        left = [p for p in descendants if alive(p)]
        if code is None:
            self.proc.kill()
            self.proc.wait()
        for p in left:
            try:
                os.kill(p, 9)
            except OSError:
                pass
        os.close(self.master)
        return code, left


def measure(
    argv: list[str], marks: tuple[str, ...], timeout: float
) -> tuple[float, int | None, list[int]]:
    run = PtyRun(argv)
    try:
        seconds = run.wait_for(marks, timeout)
        run.drain(0.3)  # let it settle before quitting
    except BaseException:
        run.quit()
        raise
    code, left = run.quit()
    return seconds, code, left


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--runs", type=int, default=RUNS)
    ap.add_argument(
        "--write", metavar="FILE", help="write/update the '## Demo start-up' section of FILE"
    )
    args = ap.parse_args()
    demo, bare, problems = [], [], []
    for _ in range(args.runs):  # interleaved, so both see the same machine load
        s, code, left = measure([sys.executable, "-c", BASELINE_APP], (BASELINE_MARK,), 30)
        bare.append(s)
        s, code, left = measure([str(MISSIONCTL), "demo"], DEMO_MARKS, 60)
        demo.append(s)
        if code != 0 or left:
            problems.append(f"demo exit code {code}, processes left: {left}")
    d, b = statistics.median(demo), statistics.median(bare)
    load = os.getloadavg()[0]
    text = (
        "## Demo start-up\n\n"
        "`missionctl demo` in a pseudo-terminal (80x24): from process start until the terminal "
        "shows the Mars mission (robot `lru1` and its skill `drive to POI-A`), i.e. mission "
        "server started, simulated fleet spawned, console connected, state loaded and painted. "
        "Baseline: a bare Textual app (one `Static`) until its text is painted, measured the same "
        "way, interleaved in the same run. Each demo run is ended with Ctrl+Q and checked to "
        "leave no process behind.\n\n"
        "Reproduce: `.venv/bin/python bench/bench_demo.py --write docs/performance.md`\n\n"
        f"Machine: {machine()}. Date: {time.strftime('%Y-%m-%d')}. Load average while measuring: "
        f"{load:.1f}.\n\n"
        "| Measure | Median of %d | Min | Max | Target |\n"
        "|---|---|---|---|---|\n"
        % args.runs
        + f"| `missionctl demo` launch to first paint of the mission | {d:.2f} s | {min(demo):.2f} "
        f"s | {max(demo):.2f} s | <= 2 s |\n"
        + f"| Bare Textual app launch to first paint (baseline) | {b:.2f} s | {min(bare):.2f} s | "
        f"{max(bare):.2f} s | |\n"
        + f"| Ratio demo / baseline | {d / b:.1f}x | | | |\n"
        + f"| Clean exit on Ctrl+Q (exit code 0, no process left) | {args.runs - len(problems)} of "
        f"{args.runs} | | | all |\n"
    )
    print(text)
    for p in problems:
        print("problem:", p, file=sys.stderr)
    if args.write:
        write_section(Path(args.write), "## Demo start-up", text)
        print(f"wrote the '## Demo start-up' section of {args.write}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
