"""Benchmark of the simulated fleet (`missionctl sim`): sim speed and map-feed bandwidth.

    .venv/bin/python bench/bench_sim.py                  # print a Markdown table
    .venv/bin/python bench/bench_sim.py --write docs/performance.md
    .venv/bin/python bench/bench_sim.py --quick          # shorter windows

Setup: the mission server and `missionctl sim` run as subprocesses on a
loopback port, the sim pinned to one CPU core (`taskset -c 0`); this process
drives them with backend.client.client.MissionClient and listens to the sim's feed.
For the speed, every mobile robot patrols across the site (drive_to/fly_to
legs); for the map feed, every robot explores a large area of its own (drones
after taking off). The benchmark world raises battery capacities so that no
robot stops to recharge during a window, and the missions' library says the
same (batteries that do not drain), or the plan checks refuse the syncs.

Measures
- sim speed factor: robot (sim) seconds stepped by the skills per wall second,
  averaged over the robots busy during the whole window, at several requested
  `--speed`s, with the 4 robots of the pilot mission and with 50 robots
  (17 LRU1-type, 17 LRU2-type, 16 drones). When the requested speed is above
  what one core can simulate, the achieved factor is the sim's throughput;
- CPU of the sim process during the window (percent of one core);
- map-feed bytes per second (deltas: changed 16x16 tiles, zlib+base64, at most
  2 Hz) and status bytes per second, while all robots explore, at `--speed 1`
  (the operator's case) and 10, plus the size of a late joiner's snapshot.

With --write, the "## Simulated fleet" section of the file is replaced (the
file is created when missing); the rest is left as it is.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from datetime import date
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from report import machine, write_section  # noqa: E402

from backend import transport  # noqa: E402
from backend.client.client import MissionClient  # noqa: E402
from backend.core.ops import AddSkill, Control, Sync  # noqa: E402
from backend.protocol import mapfeed as mf  # noqa: E402

MISSION = ROOT / "missions" / "mars_sample_return.yaml"
LIBRARY = ROOT / "missions" / "libraries" / "mars.yaml"
WORLD = ROOT / "missions" / "worlds" / "mars.yaml"
SECTION = "## Simulated fleet"


# ---------------------------------------------------------------- files


def bench_world(tmp: Path) -> Path:
    data = yaml.safe_load(WORLD.read_text())
    models = data["models"]
    for name in ("lru_science", "lru_manipulator"):
        models[name]["metres_per_battery"] = 1_000_000
    models["drone"]["flight_s_per_battery"] = 1_000_000
    out = tmp / "bench-world.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def bench_library(tmp: Path) -> Path:
    """The library as the benchmark world has it: batteries that never drain
    (else the plan checks refuse the long patrols' syncs, as they should)."""
    data = yaml.safe_load(LIBRARY.read_text())
    for spec in data["robot_types"].values():
        if "battery" in spec:
            spec["battery"].update(per_metre=0.0, per_s=0.0)
    for skill in data["skills"].values():
        skill.pop("energy", None)
    out = tmp / "bench-library.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def pilot_mission(tmp: Path) -> Path:
    """The pilot mission on the benchmark's library."""
    data = yaml.safe_load(MISSION.read_text())
    data["library"] = str(bench_library(tmp))
    out = tmp / "mission-pilot.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def big_mission(tmp: Path, n: int) -> Path:
    types = ["lru_science", "lru_manipulator", "drone"]
    robots = {f"r{i:02d}": {"type": types[i % 3]} for i in range(n)}
    data = {
        "format": "missionctl/mission@1",
        "name": f"{n} robots",
        "library": str(bench_library(tmp)),
        "robots": robots,
        "tasks": {r: [] for r in robots},
    }
    out = tmp / f"mission-{n}.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def patrol_points() -> list[tuple[float, float]]:
    """Eight reachable points on a 120 m ring around the lander (seed 1)."""
    import math

    from sim.world import World
    from sim.worldfile import load_world

    world = World(load_world(WORLD), seed=1)
    out = []
    for k in range(8):
        a = 2 * math.pi * k / 8
        p = world.terrain.nearest_free(120 * math.cos(a), 120 * math.sin(a), max_r=20)
        assert p is not None
        out.append((round(p[0], 1), round(p[1], 1)))
    return out


PATROL = patrol_points()
LEGS_FEW, LEGS_MANY = 100, 30  # patrol legs per robot (fewer for the 50-robot fleet: setup time)


def areas_for(index: int) -> list[list[dict[str, float]]]:
    """Four 150 m x 150 m quadrant-sized areas, starting with a different one per robot."""
    quads = [(-155, -155), (5, -155), (5, 5), (-155, 5)]
    out = []
    for k in range(4):
        x0, y0 = quads[(index + k) % 4]
        out.append(
            [
                {"x": x0, "y": y0},
                {"x": x0 + 150, "y": y0},
                {"x": x0 + 150, "y": y0 + 150},
                {"x": x0, "y": y0 + 150},
            ]
        )
    return out


# ---------------------------------------------------------------- processes


class Proc:
    def __init__(self, args: list[str], log: Path):
        self.log = open(log, "w")
        self.p = subprocess.Popen(
            args,
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self.lines: list[str] = []
        self.cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            self.log.write(line)
            with self.cond:
                self.lines.append(line)
                self.cond.notify_all()
        with self.cond:
            self.cond.notify_all()

    def wait_line(self, text: str, timeout: float = 60.0) -> None:
        with self.cond:
            if not self.cond.wait_for(
                lambda: any(text in ln for ln in self.lines) or self.p.poll() is not None, timeout
            ):
                raise RuntimeError(f"timed out waiting for {text!r}")
            if not any(text in ln for ln in self.lines):
                raise RuntimeError(f"process ended: {''.join(self.lines[-10:])}")

    def cpu_seconds(self) -> float:
        with open(f"/proc/{self.p.pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self) -> None:
        if self.p.poll() is None:
            self.p.terminate()
            try:
                self.p.wait(15)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()
        self.log.close()


# ---------------------------------------------------------------- one run


async def run_case(
    tmp: Path,
    mission: Path,
    world: Path,
    speed: float,
    window: float,
    warmup: float,
    workload: str = "patrol",
) -> dict[str, Any]:
    port = transport.free_port()
    endpoint = transport.loopback_endpoint(port)
    server = Proc(
        [
            sys.executable,
            "-m",
            "backend.cli",
            "server",
            "--mission",
            str(mission),
            "--listen",
            endpoint,
            "--db",
            str(tmp / f"bench-{port}.db"),
        ],
        tmp / f"server-{port}.log",
    )
    sim: Proc | None = None
    client: MissionClient | None = None
    try:
        server.wait_line("listening on")
        client = MissionClient(endpoint, telemetry=False)
        await client.connect()
        pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
        sim = Proc(
            pin
            + [
                sys.executable,
                "-m",
                "backend.cli",
                "sim",
                "--mission",
                str(mission),
                "--world",
                str(world),
                "--connect",
                endpoint,
                "--speed",
                f"{speed:g}",
                "--seed",
                "1",
            ],
            tmp / f"sim-{port}.log",
        )
        sim.wait_line("missionctl sim: world")
        await client.wait_for(lambda m: all(client.robots[r].online for r in m.robots), 60)
        assert client.mission is not None and client.library is not None
        robots = [
            r
            for r, spec in client.mission.robots.items()
            if client.library.robot_types[spec.type].kind == "dynamic"
        ]
        for i, r in enumerate(robots):
            skills = client.library.robot_types[client.mission.robots[r].type].skills
            await send_plan(client, r, plan_for(i, skills, workload, len(robots)))
        return await measure(client, sim, robots, speed, window, warmup)
    finally:
        if client is not None:
            await client.close()
        if sim is not None:
            sim.stop()
        server.stop()


def plan_for(i: int, skills: Any, workload: str, n_mobile: int) -> list[tuple[str, dict[str, Any]]]:
    """The skills the i-th mobile robot is given: exploring areas, or patrolling."""
    plan: list[tuple[str, dict[str, Any]]] = []
    if "takeoff" in skills:
        plan.append(("takeoff", {"altitude": 3.0}))
    if workload == "explore":
        return plan + [("explore", {"area": area, "max_duration": 3600}) for area in areas_for(i)]
    # patrol: back and forth across the site
    a, b = PATROL[i % len(PATROL)], PATROL[(i + len(PATROL) // 2) % len(PATROL)]
    for leg in range(LEGS_FEW if n_mobile <= 10 else LEGS_MANY):
        x, y = b if leg % 2 == 0 else a
        if "fly_to" in skills:
            plan.append(("fly_to", {"goal": {"x": x, "y": y}, "speed": 0.5, "altitude": 3.0}))
        else:
            plan.append(("drive_to", {"goal": {"x": x, "y": y}}))
    return plan


async def send_plan(
    client: MissionClient, robot: str, plan: list[tuple[str, dict[str, Any]]]
) -> None:
    last = ""
    for k, (name, params) in enumerate(plan):
        # at the head of the plan: the pilot mission's own skills stay unsynchronized
        reply = await client.submit(AddSkill(robot=robot, skill=name, params=params, at=k))
        last = reply.value["id"]
    await client.submit(Sync(robot=robot, through=last))


async def measure(
    client: MissionClient,
    sim: Proc,
    robots: list[str],
    speed: float,
    window: float,
    warmup: float,
) -> dict[str, Any]:
    """Run the mission; the sim's speed, CPU and map feed over `window` s after `warmup`."""
    assert client.mission is not None
    # the map feed, from the benchmark's side
    feed = {"bytes": 0, "deltas": 0, "tiles": 0}
    status_bytes = [0]

    def on_delta(msg: transport.Message) -> None:
        feed["bytes"] += len(msg.payload)
        feed["deltas"] += 1
        feed["tiles"] += msg.payload.count(b'"layer"')

    def on_status(msg: transport.Message) -> None:
        status_bytes[0] += len(msg.payload)

    subs = [
        transport.subscribe(client.session, mf.KEY_MAP_DELTA, on_delta),
        transport.subscribe(client.session, mf.KEY_STATUS_LIVE, on_status),
    ]
    await client.submit(Control(op="run"))
    await asyncio.sleep(warmup)  # a benchmark may sleep: it measures over wall time

    async def status() -> mf.SimTruth:  # the robots as they are, not as last heard
        raw = await transport.query(client.session, mf.KEY_STATUS, mf.TRUTH_QUERY, timeout=30)
        truth = mf.SimStatus.model_validate_json(raw).truth
        assert truth is not None
        return truth

    s0, t0, c0 = await status(), time.monotonic(), sim.cpu_seconds()
    b0, d0, k0, st0 = feed["bytes"], feed["deltas"], feed["tiles"], status_bytes[0]
    await asyncio.sleep(window)
    s1, t1, c1 = await status(), time.monotonic(), sim.cpu_seconds()
    b1, d1, k1, st1 = feed["bytes"], feed["deltas"], feed["tiles"], status_bytes[0]
    wall = t1 - t0
    busy = [r for r in robots if s0.robots[r].activity and s1.robots[r].activity]
    factors = [(s1.robots[r].sim_seconds - s0.robots[r].sim_seconds) / wall for r in busy]
    snap = await transport.query(client.session, mf.KEY_MAP_SNAPSHOT, b"", timeout=30)
    for sub in subs:
        sub.undeclare()
    return {
        "robots": len(client.mission.robots),
        "mobile": len(robots),
        "speed": speed,
        "busy": len(busy),
        "factor": statistics.mean(factors) if factors else 0.0,
        "factor_min": min(factors) if factors else 0.0,
        "cpu": (c1 - c0) / wall,
        "feed_bps": (b1 - b0) / wall,
        "deltas_ps": (d1 - d0) / wall,
        "tiles_ps": (k1 - k0) / wall,
        "status_bps": (st1 - st0) / wall,
        "snapshot_bytes": len(snap),
        "explored": s1.explored,
        "wall": wall,
    }


# ---------------------------------------------------------------- report


def table(results: dict[str, list[dict[str, Any]]]) -> str:
    lines = [
        SECTION,
        "",
        "The simulated fleet (`missionctl sim`) against the mission server, both as",
        "processes on loopback; the sim pinned to one core (`taskset -c 0`). The",
        "benchmark world raises battery capacities so that no robot stops to recharge.",
        "",
        "Reproduce: `.venv/bin/python bench/bench_sim.py --write docs/performance.md`",
        "",
        f"Machine: {machine()}. Date: {date.today().isoformat()}.",
        "",
        "Sim speed: robot seconds simulated per wall second, mean over the robots busy",
        "during the whole window (and the slowest one). Workload: every mobile robot",
        "patrols across the site (drive_to / fly_to legs of ~240 m, A* routes, terrain",
        "mapping on the way). Each skill steps its robot in `min(5, max(0.25, speed x 0.05))`",
        "s of sim time with `ctx.sleep`; when the requested speed is more than one core",
        "can simulate, the achieved factor is the sim's throughput.",
        "",
        "| Robots (mobile) | Requested speed | Achieved speed (mean / slowest robot) | Sim CPU "
        "(one core) |",
        "|---|---|---|---|",
    ]
    for r in results["speed"]:
        lines.append(
            f"| {r['robots']} ({r['mobile']}) | {r['speed']:g}x | {r['factor']:,.0f}x / "
            f"{r['factor_min']:,.0f}x | {r['cpu'] * 100:.0f}% |"
        )
    lines += [
        "",
        "Map feed while all robots explore (each its own 150 m x 150 m area; deltas of",
        "changed 16x16 tiles, zlib+base64, at most 2 Hz; robot poses ride on telemetry",
        "and are not counted):",
        "",
        "| Robots | Speed | Map feed | Deltas/s | Tiles/s | Sim status (live) | Snapshot (late "
        "joiner) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results["feed"]:
        lines.append(
            f"| {r['robots']} | {r['speed']:g}x | {r['feed_bps'] / 1000:,.1f} kB/s | "
            f"{r['deltas_ps']:.1f} | {r['tiles_ps']:.1f} | {r['status_bps'] / 1000:,.1f} kB/s | "
            f"{r['snapshot_bytes'] / 1000:,.1f} kB |"
        )
    lines += [
        "",
        "The site grid is 160 x 160 cells of 2 m (two layers: terrain as explored, link",
        "coverage). The sim status publication goes out on change (at most every 0.5 s)",
        "and at least every 2 s; it carries every robot, so it grows with the fleet.",
        "",
    ]
    return "\n".join(lines)


async def main_async(args: argparse.Namespace) -> dict[str, list[dict[str, Any]]]:
    window = 4.0 if args.quick else 8.0
    warmup = 1.5 if args.quick else 2.0
    results: dict[str, list[dict[str, Any]]] = {"speed": [], "feed": []}
    with tempfile.TemporaryDirectory(prefix="bench-sim-") as d:
        tmp = Path(d)
        world = bench_world(tmp)
        fifty = big_mission(tmp, 50)
        pilot = pilot_mission(tmp)
        cases = [
            (pilot, s) for s in ((50, 1000, 10000) if args.quick else (1, 50, 200, 1000, 10000))
        ]
        cases += [(fifty, s) for s in ((50, 1000) if args.quick else (50, 200, 1000, 10000))]
        for mission, speed in cases:
            r = await run_case(tmp, mission, world, speed, window, warmup)
            print(
                f"  speed: {r['robots']} robots at {speed:g}x -> {r['factor']:,.0f}x (cpu "
                f"{r['cpu']:.0%})",
                file=sys.stderr,
            )
            results["speed"].append(r)
        for mission, speed in [(pilot, 1), (pilot, 10), (fifty, 1)]:
            r = await run_case(
                tmp, mission, world, speed, window * (2 if speed == 1 else 1), warmup, "explore"
            )
            print(
                f"  feed: {r['robots']} robots at {speed:g}x -> {r['feed_bps']:,.0f} B/s",
                file=sys.stderr,
            )
            results["feed"].append(r)
    return results


def main() -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--write", metavar="FILE", help="replace the '## Simulated fleet' section of FILE"
    )
    p.add_argument("--quick", action="store_true", help="shorter windows, fewer speeds")
    args = p.parse_args()
    results = asyncio.run(main_async(args))
    text = table(results)
    print(text)
    if args.write:
        write_section(Path(args.write), SECTION, text)
        print(f"wrote {args.write}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
