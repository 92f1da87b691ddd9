"""docs/robots.md replayed: each python block marked `<!-- replayed: NAME -->`
is written to a file and run as a robot process against a live mission server
(missions/tutorial.yaml, free loopback port, its own db); a MissionClient
drives the mission and the test checks what the guide's text promises. A
change to the guide or to the SDK that breaks an example fails here.

The only change made to an example: its endpoint tcp/127.0.0.1:7447 becomes
the test server's. Waiting is on the client's state and telemetry and on the
robots' output, never on sleeps."""

from __future__ import annotations

import asyncio
import importlib.util
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from backend.client.client import MissionClient
from backend.client.events import ClientEvent, TelemetryReceived
from backend.core.model import Policies, Pose
from backend.core.ops import AddBarrier, AddSkill, Control, DeleteSkills, Retry, Sync

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "robots.md"
GUIDE_ENDPOINT = "tcp/127.0.0.1:7447"
EXAMPLES = ("first-robot", "versions", "handlers", "pair")
WAIT = 20.0

pytestmark = pytest.mark.timeout(180)


def _load(relpath: str) -> Any:
    """A helper module of another test directory (tests/ is not a package)."""
    spec = importlib.util.spec_from_file_location(
        f"_doc_helpers_{Path(relpath).stem}", ROOT / "tests" / relpath
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_server_harness = _load("server/harness.py")
Cluster, Proc, status = _server_harness.Cluster, _server_harness.Proc, _server_harness.status
ctl = _load("cli/helpers.py").ctl


# ---------------------------------------------------------------- the guide


def replayed_blocks() -> dict[str, str]:
    text = GUIDE.read_text()
    found = dict(
        re.findall(r"<!-- replayed: ([\w-]+) -->\n```python\n(.*?)^```", text, re.M | re.S)
    )
    missing = [n for n in EXAMPLES if n not in found]
    assert not missing, (
        f"docs/robots.md lost its replayed example(s) {missing} (marked <!-- replayed: NAME -->)"
    )
    return found


def flat(text: str) -> str:
    return " ".join(text.split())


def test_every_python_block_of_the_guide_compiles_and_the_examples_are_marked() -> None:
    blocks = re.findall(r"^```python\n(.*?)^```", GUIDE.read_text(), re.M | re.S)
    for i, code in enumerate(blocks):
        compile(code, f"docs/robots.md python block {i + 1}", "exec")
    assert set(replayed_blocks()) == set(EXAMPLES)
    for code in replayed_blocks().values():
        assert GUIDE_ENDPOINT in code


# ---------------------------------------------------------------- fixtures


@pytest.fixture
def cluster(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    # the examples import backend, wherever they are written
    monkeypatch.setenv("PYTHONPATH", str(ROOT))
    c = Cluster(tmp_path, "missions/tutorial.yaml")
    c.start_server()
    yield c
    c.stop()


def robot(
    cluster: Any,
    tmp_path: Path,
    example: str,
    *argv: str,
    edit: Callable[[str], str] = str,
    ready: str | None = None,
) -> Proc:
    """Run the guide's example as a robot process; wait for its "ready NAME"."""
    code = edit(replayed_blocks()[example].replace(GUIDE_ENDPOINT, cluster.endpoint))
    path = tmp_path / f"{example.replace('-', '_')}.py"
    path.write_text(code)
    proc = Proc([sys.executable, str(path), *argv])
    cluster.procs.append(proc)  # stopped in teardown
    if ready is not None:
        proc.wait_line(ready)
    return proc


def drive(cluster: Any, scenario: Callable[[MissionClient], Any]) -> None:
    async def main() -> None:
        client = MissionClient(cluster.endpoint, client_id="robots-doc")
        await client.connect()
        try:
            await asyncio.wait_for(scenario(client), 150)
        finally:
            await client.close()

    asyncio.run(main())


class Telemetry:
    """Waits on the client's telemetry (each sample wakes the waiters)."""

    def __init__(self, client: MissionClient):
        self.client = client
        self.tick = asyncio.Event()
        self.count = 0
        client.add_listener(self._on)

    def _on(self, event: ClientEvent) -> None:
        if isinstance(event, TelemetryReceived):
            self.count += 1
            self.tick.set()

    async def until(
        self, robot: str, pred: Callable[[Any], bool], what: str, timeout: float = WAIT
    ) -> Any:
        try:
            async with asyncio.timeout(timeout):
                while True:
                    t = self.client.telemetry.get(robot)
                    if t is not None and pred(t):
                        return t
                    self.tick.clear()
                    await self.tick.wait()
        except TimeoutError:
            raise AssertionError(
                f"{what}: not within {timeout}s; last telemetry {self.client.telemetry.get(robot)}"
            ) from None

    async def next_samples(self, robot: str, n: int) -> list[Any]:
        """The next `n` samples of `robot` (as the client sees them)."""
        seen = []
        last = self.client.telemetry.get(robot)
        async with asyncio.timeout(WAIT):
            while len(seen) < n:
                self.tick.clear()
                await self.tick.wait()
                t = self.client.telemetry.get(robot)
                if t is not None and t is not last:
                    seen.append(t)
                    last = t
        return seen


async def until(c: MissionClient, pred: Callable[[Any], bool], timeout: float = WAIT) -> Any:
    return await c.wait_for(pred, timeout)


def info(m: Any, sid: str) -> str:
    return m.find(sid)[2].status_info


def add(robot_name: str, skill: str, **kw: Any) -> AddSkill:
    return AddSkill(robot=robot_name, skill=skill, **kw)


async def added(c: MissionClient, op: AddSkill) -> str:
    return (await c.submit(op)).value["id"]


def reports(proc: Proc, sid: str) -> list[str]:
    """The `report SEQ ID STATUS attempt N INFO` lines the handlers example prints, for `sid`."""
    out = []
    for line in proc.output().splitlines():
        parts = line.split()
        if len(parts) >= 6 and parts[0] == "report" and parts[2] == sid:
            out.append(" ".join(parts[3:]))
    return out


# ---------------------------------------------------------------- section 1


def test_first_robot_gets_typed_values_and_exits_cleanly(cluster: Any, tmp_path: Path) -> None:
    proc = robot(cluster, tmp_path, "first-robot", ready="ready lru1")

    async def scenario(c: MissionClient) -> None:
        manifest = c.robots["lru1"].manifest
        assert manifest is not None
        assert {(m.name, m.version) for m in manifest.modules} == {
            ("nav", "2.1.0"),
            ("camera", "1.0.3"),
        }
        assert manifest.properties == {"camera": "multispectral"}
        assert manifest.skills == {
            "drive_to": "1.0.0",
            "explore": "1.0.0",
            "take_science_image": "1.0.0",
        }
        area = [{"x": 0, "y": 0}, {"x": 4, "y": 0}, {"x": 4, "y": 3}]
        e = await added(c, add("lru1", "explore", params={"area": area}))
        await c.submit(Sync(robot="lru1"))
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, e) == "success")
        # typed: a Pose from the marker POI-A, the float default; raw: a dict,
        # the enum as a string, the dict default; an area as Positions
        assert info(m, "lru1-1") == "arrived at (10, 5) at 0.5 m/s"
        assert (
            info(m, "lru1-2")
            == "multispectral image of (10, 5) at 20 ms, bound to {'target': 'POI-A'}"
        )
        assert info(m, e) == "explored 3 corners, x 0..4 m, with stereo_camera"

    drive(cluster, scenario)
    proc.stop()  # SIGTERM: the signal handler ends the `async with`, the session closes
    assert proc.p.returncode == 0, proc.output()


def test_a_robot_of_an_unknown_type_outside_the_mission_is_refused(
    cluster: Any, tmp_path: Path
) -> None:
    def rename(code: str) -> str:
        return code.replace('"lru2", "lru_manipulator"', '"lru7", "hovercraft"')

    proc = robot(cluster, tmp_path, "versions", edit=rename)
    line = proc.wait_line("RegistrationRefused: ")
    assert "the mission server refused robot lru7: robot lru7 is a 'hovercraft'" in line
    assert "add robot type 'hovercraft'" in line
    assert proc.p.wait(WAIT) != 0


def test_incompatible_major_version_is_refused_at_sync(cluster: Any, tmp_path: Path) -> None:
    robot(cluster, tmp_path, "versions", ready="ready lru2")
    r = ctl(cluster.endpoint, "sync", "lru2", "--through", "lru2-1")
    assert r.returncode == 0, r.stderr
    r = ctl(cluster.endpoint, "sync", "lru2")
    assert r.returncode == 1, r.stdout + r.stderr
    promised = (
        "lru2 implements identify_stone 2.0.0, the library needs 1.0.0 (major versions "
        "differ); lru2-2 stays unsynchronized"
    )
    assert promised in flat(GUIDE.read_text())
    assert promised in flat(r.stderr), r.stderr


# ---------------------------------------------------------------- sections 2 and 3


def test_handlers_progress_pause_stop_failure_retry_and_server_loss(
    cluster: Any, tmp_path: Path
) -> None:
    proc = robot(cluster, tmp_path, "handlers", ready="ready lru1")

    async def scenario(c: MissionClient) -> None:
        tel = Telemetry(c)
        await c.submit(DeleteSkills(ids=["lru1-1", "lru1-2"]))  # the tutorial's: a 22 s drive

        # progress, then pause: the reported progress stops, run resumes it
        d = await added(c, add("lru1", "drive_to", params={"goal": {"x": 3, "y": 0}, "speed": 1.0}))
        await c.submit(Sync(robot="lru1"))
        await c.submit(Control(op="run", robot="lru1"))
        t = await tel.until("lru1", lambda t: t.skill == d and (t.progress or 0) > 0, "progress")
        assert "m to go" in t.info and t.eta_s is not None
        await c.submit(Control(op="pause", robot="lru1"))
        await until(c, lambda m: status(m, d) == "paused")
        held = (await tel.until("lru1", lambda t: t.mode == "paused", "paused telemetry")).progress
        for later in await tel.next_samples("lru1", 3):
            assert later.progress == held, "the handler kept going while paused"
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, d) == "success")
        assert info(m, d) == "drove 3 m"

        # stop: back to the queue, halted; run starts it from the beginning
        s = await added(c, add("lru1", "drive_to", params={"goal": {"x": 3, "y": 0}, "speed": 1.0}))
        await c.submit(Sync(robot="lru1"))  # still in run mode: it starts at once
        await tel.until(
            "lru1", lambda t: t.skill == s and (t.progress or 0) > 0, "progress of the second drive"
        )
        await c.submit(Control(op="stop", robot="lru1"))
        await until(c, lambda m: status(m, s) == "idle_synchronized")
        await tel.until("lru1", lambda t: t.mode == "halted" and t.skill is None, "halted")
        await c.submit(Control(op="run", robot="lru1"))
        await until(c, lambda m: status(m, s) == "success")
        assert [r.split()[0] for r in reports(proc, s)] == [
            "running",
            "idle_synchronized",
            "running",
            "success",
        ]

        # a plain function, then a failure halts the queue; retry runs attempt 2
        f = await added(c, add("lru1", "identify_stone", params={"target": {"x": 1, "y": 1}}))
        n = await added(c, add("lru1", "take_science_image", params={"target": {"x": 1, "y": 2}}))
        await c.submit(Sync(robot="lru1"))
        m = await until(c, lambda m: status(m, f) == "failure")
        assert info(m, f) == "no stone within 8 m of (1, 1)"  # the library's default radius
        assert status(m, n) == "idle_synchronized"
        await tel.until("lru1", lambda t: t.mode == "halted", "halted after the failure")
        retry = (await c.submit(Retry(id=f))).value["id"]
        assert retry == f"{f}.2"
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, n) == "success")
        assert (status(m, retry), m.find(retry)[2].attempt) == ("success", 2)
        assert info(m, retry) == "stone s1 found on attempt 2"
        assert info(m, n) == "10 bands of (1, 2)"

        # a retry policy: the robot retries by itself, staying running
        g = await added(
            c,
            add(
                "lru1",
                "identify_stone",
                params={"target": {"x": 1, "y": 1}},
                policies=Policies(retries=1),
            ),
        )
        await c.submit(Sync(robot="lru1"))
        m = await until(c, lambda m: status(m, g) == "success")
        assert m.find(g)[2].attempt == 2
        assert reports(proc, g) == [
            "running attempt 1",
            "running attempt 2 retry 1/1 after: no stone within 8 m of (1, 1)",
            "success attempt 2 stone s1 found on attempt 2",
        ]

        # the server dies mid-skill: the robot finishes, its reports wait and
        # reach the restarted server (same db) in order
        k = await added(c, add("lru1", "drive_to", params={"goal": {"x": 2, "y": 0}, "speed": 1.0}))
        await c.submit(Sync(robot="lru1"))
        await until(c, lambda m: status(m, k) == "running")
        cluster.server.kill()
        await asyncio.to_thread(proc.wait_line, f" {k} success ")
        cluster.start_server()
        await until(c, lambda m: c.connected and status(m, k) == "success", 30)
        seqs = [
            int(line.split()[1])
            for line in proc.output().splitlines()
            if line.startswith("report ")
        ]
        # numbered per robot in one sequence with its answers to commands:
        # increasing, each number once (the answers take the numbers between)
        assert seqs == sorted(set(seqs)) and seqs[0] >= 1

    drive(cluster, scenario)


# ---------------------------------------------------------------- section 4


def test_pair_telemetry_barrier_offline_partner_and_ask(cluster: Any, tmp_path: Path) -> None:
    robot(cluster, tmp_path, "pair", "lru1", ready="ready lru1")
    lru2 = robot(cluster, tmp_path, "pair", "lru2", ready="ready lru2")

    async def scenario(c: MissionClient) -> None:
        tel = Telemetry(c)
        t = await tel.until("lru1", lambda t: t.pose == Pose(x=1.0, y=2.0, yaw=0.5), "lru1's pose")
        assert (t.battery, t.link, t.mode) == (0.9, 0.8, "idle")
        assert c.robots["lru2"].manifest.skills == {
            "identify_stone": "1.0.0",
            "pick_stone": "1.0.0",
        }
        await c.submit(DeleteSkills(ids=["lru1-1", "lru1-2", "lru2-1", "lru2-2"]))

        p = await added(c, add("lru1", "identify_stone", params={"target": {"x": 1, "y": 1}}))
        q = await added(c, add("lru2", "identify_stone", params={"target": {"x": 1, "y": 1}}))
        await c.submit(AddBarrier(ids=[p, q]))
        await c.submit(Sync(robot="lru1"))
        await c.submit(Sync(robot="lru2"))
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, p) == "synchwaiting")
        assert info(m, p) == "waiting for lru2" and status(m, q) == "idle_synchronized"

        lru2.kill()  # the partner goes away: the waiting robot says so
        # lru1 sees the token go on its own, so its report may reach the
        # client before or after the server's presence event: wait for both
        m = await until(
            c, lambda m: info(m, p) == "waiting for lru2 (offline)" and not c.robots["lru2"].online
        )
        assert status(m, p) == "synchwaiting"

        # back, without its queue: its skill returns to the plan (RegisterReply.missing)
        robot(cluster, tmp_path, "pair", "lru2", ready="ready lru2")
        await until(c, lambda m: status(m, q) == "idle" and info(m, p) == "waiting for lru2")
        await c.submit(Sync(robot="lru2"))
        await c.submit(Control(op="run", robot="lru2"))
        m = await until(c, lambda m: status(m, p) == "success" and status(m, q) == "success")
        assert (info(m, p), info(m, q)) == ("lru1 sees stone s1", "lru2 sees stone s1")

        # robot to robot: lru2 asks lru1 where the stone is
        k = await added(c, add("lru2", "pick_stone", params={"target": {"x": 1, "y": 1}}))
        await c.submit(Sync(robot="lru2"))  # lru2 is in run mode: it starts at once
        m = await until(c, lambda m: status(m, k) == "success")
        assert info(m, k) == "picked s1 at (1.5, 1) as lru1 said"

    drive(cluster, scenario)
