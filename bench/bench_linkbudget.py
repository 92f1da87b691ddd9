"""The link budget and the delay tolerance of a deployment through a site relay.

    .venv/bin/python bench/bench_linkbudget.py                    # print a Markdown section
    .venv/bin/python bench/bench_linkbudget.py --write docs/performance.md
    .venv/bin/python bench/bench_linkbudget.py --budget-only --window 60

Two machines' worth of processes on loopback, as docs/deployment.md sets them
up: the ground's `missionctl server`; the long link, a TCP proxy delaying
every byte by D each way and counting them (tests/transport/delay_proxy.py);
the site's relay (`missionctl router`) connected through it; `missionctl sim`
(the default world, seed 1) connected to the relay; and at the ground, a
console's worth of subscriptions in this process (the mission client with
telemetry, the map feed, the sim's live status), counting what each key
brings.

1. Link budget: the opening mission (missions/mars_sample_return.yaml) at sim
   speed 1, every robot's plan synchronized and run; bytes per second over
   the link, site -> ground and ground -> site, from the run command until
   every skill finished (at most `--window` seconds), the busiest 30 s, and
   per key (payload bytes as the ground receives them;
   "the rest" is the robot link's queries and replies, presence, and Zenoh's
   framing and keep-alives: the proxy's count minus the keys'). Twice in one
   run: with `missionctl sim --link-budget off` (telemetry at a steady rate,
   the full status at every publication, as before issue 31: the baseline)
   and with the defaults. Target: <= 1.2 kB/s site -> ground (9.6 kbit/s).
2. Delay tolerance: at D = 0, 1.3 s and 6 s (every process given
   `--link-delay-hint D`): how long after the sim started every robot is
   online at the ground, and sync -> acknowledged (a sync of one robot's plan
   from the ground until its answer is in the ground's mirror) minus 2 D.

With --write, the "## Link budget and delay tolerance" section of the file is
replaced (the rest of the file is left as it is).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "bench", ROOT / "tests" / "transport"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from bench_sim import MISSION, WORLD, Proc  # noqa: E402
from delay_proxy import DelayProxy  # noqa: E402
from report import machine, write_section  # noqa: E402

from backend import transport  # noqa: E402
from backend.client.client import MissionClient  # noqa: E402
from backend.client.mapfollow import MapFeed  # noqa: E402
from backend.core.model import ACTIVE, FINISHED, Status  # noqa: E402
from backend.core.ops import Control, Sync  # noqa: E402
from backend.protocol import mapfeed as mf  # noqa: E402
from backend.protocol.keys import Keys  # noqa: E402
from backend.transport.login import Login  # noqa: E402

HEADING = "## Link budget and delay tolerance"
TARGET_BPS = 1200.0
SAMPLE_S = 10.0  # the proxy's count is read this often ...
PEAK_S = 30.0  # ... for the busiest 30 s
DELAYS = (0.0, 1.3, 6.0)
KEYS = {
    "telemetry": Keys.ALL_TELEMETRY,
    "sim status": mf.KEY_STATUS_LIVE,
    "map feed": mf.KEY_MAP_DELTA,
}


@dataclass
class Counter:
    bytes: int = 0
    messages: int = 0

    def add(self, n: int) -> None:
        self.bytes += n
        self.messages += 1


@dataclass
class Watch:
    """A console's worth of subscriptions at the ground, counting per key."""

    client: MissionClient
    feed: MapFeed | None = None
    counters: dict[str, Counter] = field(default_factory=dict)
    entities: list[Any] = field(default_factory=list)

    def start_counting(self) -> None:
        assert self.client.session is not None
        for name, key in KEYS.items():
            counter = self.counters.setdefault(name, Counter())
            # the same session as the client's subscribers: nothing more crosses the link
            self.entities.append(
                transport.subscribe(
                    self.client.session, key, lambda m, c=counter: c.add(len(m.payload))
                )
            )

    def snapshot(self) -> dict[str, tuple[int, int]]:
        return {k: (c.bytes, c.messages) for k, c in self.counters.items()}


class Deployment:
    """server <- delay proxy (D) <- relay <- sim, on free loopback ports."""

    def __init__(
        self, tmp: Path, delay: float, *, sim_args: list[str] = (), relay_args: list[str] = ()
    ):
        self.tmp = tmp
        self.delay = delay
        self.hint = ["--link-delay-hint", f"{delay:g}s"]
        self.sim_args = list(sim_args)
        self.relay_args = list(relay_args)
        self.ground = transport.loopback_endpoint(transport.free_port())
        self.site = transport.loopback_endpoint(transport.free_port())
        self.procs: list[Proc] = []
        self.proxy: DelayProxy | None = None
        self.sim_started = 0.0

    def _proc(self, name: str, *args: str) -> Proc:
        proc = Proc([sys.executable, "-m", "backend.cli", *args], self.tmp / f"{name}.log")
        self.procs.append(proc)
        return proc

    def start(self) -> None:
        db = self.tmp / f"mission-{time.monotonic_ns()}.db"
        server = self._proc(
            "server", "server", "--mission", str(MISSION), "--db", str(db),
            "--listen", self.ground, *self.hint,
        )  # fmt: skip
        server.wait_line("listening on")
        port = int(self.ground.rsplit(":", 1)[1])
        self.proxy = DelayProxy(("127.0.0.1", port), self.delay).start()
        relay = self._proc(
            "router", "router", "--listen", self.site,
            "--connect", transport.loopback_endpoint(self.proxy.port), *self.hint,
            *self.relay_args,
        )  # fmt: skip
        relay.wait_line("relaying")
        self.sim_started = time.monotonic()
        sim = self._proc(
            "sim", "sim", "--mission", str(MISSION), "--world", str(WORLD), "--seed", "1",
            "--connect", self.site, *self.hint, *self.sim_args,
        )  # fmt: skip
        sim.wait_line("missionctl sim: world", timeout=120)

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()
        if self.proxy is not None:
            self.proxy.close()


async def _watch(dep: Deployment) -> Watch:
    login = Login(link_delay_hint=dep.delay)
    client = MissionClient(dep.ground, login=login, client_id="bench-watch")
    await client.connect()
    watch = Watch(client)
    watch.start_counting()
    return watch


def _over(mission: Any) -> bool:
    """Every skill of the opening mission finished (or a failure halted its robot)."""
    return all(
        all(s.status in FINISHED for s in task)
        or (
            any(s.status == Status.FAILURE for s in task)
            and not any(s.status in ACTIVE for s in task)
        )
        for task in mission.tasks.values()
    )


def _peak(samples: list[tuple[float, int]]) -> float:
    """The busiest PEAK_S seconds, bytes per second (the samples' steps)."""
    best = 0.0
    for i, (t0, b0) in enumerate(samples):
        for t1, b1 in samples[i + 1 :]:
            if t1 - t0 >= PEAK_S - 1e-6:
                best = max(best, (b1 - b0) / (t1 - t0))
                break
    return best


async def _online(watch: Watch, timeout: float) -> None:
    c = watch.client
    await c.wait_for(lambda m: all(c.robots[r].online for r in m.robots), timeout)


ONE_AT_A_TIME = (
    "Minus 2 D, what is left above D = 0 is one round trip more: the lander answers as "
    "soon as the command reaches it (its answer's time stamp is D after the command left), "
    "but its downlink carries one message at a time, and on a long link the previous one "
    "(a report, a 5 s heartbeat) is usually still waiting for its acknowledgement: the "
    "answer waits up to 2 D behind it."
)

# the relay as a plain Zenoh router was before issue 31: timestamps, no compression
PLAIN_ROUTER = (
    "{timestamping: {enabled: true}, transport: {unicast: {compression: {enabled: false}}}}"
)


async def budget_run(tmp: Path, window: float, *, baseline: bool) -> dict[str, Any]:
    relay_args: list[str] = []
    if baseline:
        plain = tmp / "plain-router.json5"
        plain.write_text(PLAIN_ROUTER)
        relay_args = ["--zenoh-config", str(plain)]
    dep = Deployment(
        tmp, 0.0, sim_args=["--link-budget", "off"] if baseline else [], relay_args=relay_args
    )
    watch = None
    try:
        dep.start()
        watch = await _watch(dep)
        await _online(watch, 120)
        watch.feed = MapFeed(watch.client.session, lambda _u: None)
        await watch.feed.start()
        for robot in watch.client.mission.robots:
            await watch.client.submit(Sync(robot=robot))
        await watch.client.submit(Control(op="run"))
        assert dep.proxy is not None
        up0, down0 = dep.proxy.counts()
        keys0 = watch.snapshot()
        started = time.monotonic()
        samples = [(0.0, up0)]  # (seconds from run, bytes up so far): the busiest stretch
        while time.monotonic() - started < window and not _over(watch.client.mission):
            await asyncio.sleep(SAMPLE_S)  # a measuring step, not a synchronisation
            samples.append((time.monotonic() - started, dep.proxy.counts()[0]))
        wall = time.monotonic() - started
        up, down = dep.proxy.counts()
        keys = {k: (b - keys0[k][0], n - keys0[k][1]) for k, (b, n) in watch.snapshot().items()}
        return {
            "wall": wall,
            "finished": _over(watch.client.mission),
            "up": (up - up0) / wall,
            "down": (down - down0) / wall,
            "peak": _peak(samples),
            "keys": {k: (b / wall, n / wall, b / n if n else 0.0) for k, (b, n) in keys.items()},
        }
    finally:
        if watch is not None:
            if watch.feed is not None:
                watch.feed.close()
            watch.entities.clear()
            await watch.client.close()
        dep.stop()


async def delay_run(tmp: Path, delay: float) -> dict[str, float]:
    dep = Deployment(tmp, delay)
    watch = None
    try:
        dep.start()
        watch = await _watch(dep)
        await _online(watch, 60 + 20 * delay)
        online = time.monotonic() - dep.sim_started
        sent = time.monotonic()
        reply = await watch.client.submit(Sync(robot="lander"))
        await watch.client.wait_command(reply.value["command"], 60 + 10 * delay)
        acked = time.monotonic() - sent
        return {"online": online, "acked": acked, "overhead": acked - 2 * delay}
    finally:
        if watch is not None:
            watch.entities.clear()
            await watch.client.close()
        dep.stop()


def _kb(bps: float) -> str:
    return f"{bps / 1000:.2f} kB/s"


def section(result: dict[str, Any], window: float) -> str:
    lines = [
        HEADING,
        "",
        "Two machines' worth of processes on loopback: the ground's `missionctl server`, a "
        "TCP proxy delaying every byte by D each way (the long link; it counts the bytes), "
        "the site's `missionctl router` connected through it, `missionctl sim` (default "
        "world, seed 1, speed 1) connected to the relay, and a console's subscriptions at the "
        "ground (telemetry, map feed, sim status). `bench/bench_linkbudget.py` describes it.",
        "",
        f"Reproduce: `.venv/bin/python bench/bench_linkbudget.py --write docs/performance.md` "
        f"({date.today().isoformat()}; {machine()}).",
    ]
    budget = result.get("budget")
    if budget:
        before, after = budget["before"], budget["after"]
        lines += [
            "",
            f"### Link budget: the opening mission at sim speed 1, "
            f"{after['wall']:.0f} s from `run`"
            + (" (to its end)" if after["finished"] else f" (its first {window:g} s)"),
            "",
            "Before: `missionctl sim --link-budget off` (telemetry at a steady 4 Hz, the full "
            "sim status at every publication) behind a relay configured as a plain Zenoh "
            "router (timestamps, no compression): as before issue 31. After: the defaults. "
            "Both in the same run. Per key: the payloads the ground received (before the "
            "link's compression); the link's totals are what crossed the proxy (compressed, "
            "with the robot link's queries and replies, presence, Zenoh's framing and "
            f"keep-alives). Target: site -> ground <= {_kb(TARGET_BPS)} (9.6 kbit/s).",
            "",
            "| | before | after | after / before |",
            "| --- | ---: | ---: | ---: |",
        ]
        for key in KEYS:
            b, a = before["keys"][key], after["keys"][key]
            lines.append(
                f"| {key} (`{KEYS[key]}`) payloads | {_kb(b[0])} ({b[1]:.1f}/s x {b[2]:.0f} B) | "
                f"{_kb(a[0])} ({a[1]:.1f}/s x {a[2]:.0f} B) | "
                f"{a[0] / b[0] if b[0] else 0:.2f} |"
            )
        lines += [
            f"| **site -> ground, on the link** | **{_kb(before['up'])}** | "
            f"**{_kb(after['up'])}** | **{after['up'] / before['up']:.2f}** |",
            f"| site -> ground, the busiest {PEAK_S:g} s | {_kb(before['peak'])} | "
            f"{_kb(after['peak'])} | {after['peak'] / before['peak']:.2f} |",
            f"| ground -> site, on the link | {_kb(before['down'])} | {_kb(after['down'])} | "
            f"{after['down'] / before['down']:.2f} |",
            "",
            f"After: {_kb(after['up'])} site -> ground "
            f"({after['up'] * 8 / 1000:.1f} kbit/s): target "
            f"{'met' if after['up'] <= TARGET_BPS else 'NOT met'}.",
        ]
    tolerance = result.get("delays")
    if tolerance:
        lines += [
            "",
            "### Delay tolerance through the relay",
            "",
            "Every process given `--link-delay-hint D` and nothing else. Online: from the "
            "sim's start until every robot is online at the ground. Sync -> acked: a sync of "
            "the lander's plan from the ground until the lander's answer is in the ground's "
            "mirror, minus the 2 D the link takes.",
            "",
            "| D (one way) | robots online after | sync -> acked | minus 2 D |",
            "| ---: | ---: | ---: | ---: |",
        ]
        for d, r in tolerance.items():
            lines.append(
                f"| {d:g} s | {r['online']:.1f} s | {r['acked']:.2f} s | {r['overhead']:.2f} s |"
            )
        lines += ["", ONE_AT_A_TIME]
    return "\n".join(lines) + "\n"


async def run(args: argparse.Namespace) -> dict[str, Any]:
    result: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="bench-linkbudget-") as tmp:
        t = Path(tmp)
        if not args.delays_only:
            before = await budget_run(t, args.window, baseline=True)
            after = await budget_run(t, args.window, baseline=False)
            result["budget"] = {"before": before, "after": after}
        if not args.budget_only:
            result["delays"] = {d: await delay_run(t, d) for d in DELAYS}
    return result


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--write", metavar="FILE", help=f"write/update the '{HEADING}' section")
    ap.add_argument(
        "--window",
        type=float,
        default=1200.0,
        metavar="S",
        help="measure at most S seconds from run (default 1200: the whole opening mission, "
        "~10 minutes at speed 1)",
    )
    ap.add_argument("--budget-only", action="store_true")
    ap.add_argument("--delays-only", action="store_true")
    args = ap.parse_args()
    result = asyncio.run(run(args))
    text = section(result, args.window)
    print(text)
    if args.write:
        write_section(Path(args.write), HEADING, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
