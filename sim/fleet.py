"""The simulated fleet: one RobotAgent per mission robot, all on one asyncio loop.

    fleet = SimFleet(mission, library, world_spec, connect=["tcp/127.0.0.1:7447"], speed=50)
    await fleet.start()
    ...
    await fleet.stop()

Besides the agents it runs the world's background physics (charging at the
lander, hovering drones), the map feed (deltas at most every `feed_period`
wall seconds, snapshot queryable) and the sim status (queryable and live
publication). See backend/protocol/mapfeed.py for the wire format.
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
import math
import time
import uuid
from collections import Counter, deque
from typing import Any

import zenoh

from backend import transport
from backend.agent import STEADY, Link, RobotAgent, SkillFailed
from backend.core.library import Library
from backend.core.model import Mission, Pose
from backend.protocol import mapfeed as mf
from backend.transport import QueryFailed
from sim.calibration import drift
from sim.calibration import properties as manifest_properties
from sim.choice import SimChooser
from sim.comms import CommsWindow
from sim.errors import SimError
from sim.exchange import WorldExchange
from sim.robot import SimRobot
from sim.skills.registry import RobotSkills
from sim.status import ground_status, truth
from sim.team import TeamEvents
from sim.world import World
from sim.worldfile import RobotModel, WorldFile

log = logging.getLogger(__name__)

SIM_VERSION = "0.1.0"
STATUS_MIN = 0.5  # wall seconds between status publications (when something changed)
STATUS_MAX = 2.0  # ... and at least this often (--link-budget off: the full status each time)
STATUS_HEARTBEAT = 10.0  # with the link budget: a patch at least this often
STATUS_KEYFRAME = 60.0  # ... and the full status this often (a follower that missed one)


def step_for(speed: float) -> float:
    """Sim seconds per skill step: ~50 ms of wall time, 0.25..5 s of sim time."""
    return min(5.0, max(0.25, speed * 0.05))


class SimLink(Link):
    """The operator link of one simulated robot: coverage from the world grid."""

    def __init__(self, world: World, robot: SimRobot, fleet: SimFleet):
        # no super().__init__: reachable/quality are computed here
        self.world = world
        self.robot = robot
        self.fleet = fleet
        self.reachable = True

    @property
    def delay_s(self) -> float:  # type: ignore[override]
        """Wall seconds: the link delay is sim time."""
        return self.fleet.link_delay / self.fleet.speed

    def in_range(self) -> bool:
        return self.fleet.ground_open() and self.world.in_range(self.robot)

    def can_reach(self, robot: str) -> bool:
        """Robot to robot: through the network when both are covered, or direct radio."""
        other = self.world.robots.get(robot)
        return other is not None and self.world.can_talk(self.robot, other)

    @property
    def quality(self) -> float:  # type: ignore[override]
        return self.world.link_quality(self.robot.x, self.robot.y)


class SimFleet:
    def __init__(
        self,
        mission: Mission,
        library: Library,
        world_spec: WorldFile,
        *,
        connect: list[str],
        speed: float = 1.0,
        seed: int | None = None,
        link_delay: float = 0.0,
        comms_window: CommsWindow | None = None,
        telemetry_hz: float = 4.0,
        feed_period: float = 0.5,
        zenoh_extra: dict[str, Any] | None = None,
        link_delay_hint: float = 0.0,
        link_budget: bool = True,
        telemetry_rates: dict[str, float] | None = None,
        team: TeamEvents | None = None,
    ):
        if speed <= 0 or not math.isfinite(speed):
            raise ValueError("the speed must be a positive number")
        self.mission = mission
        self.library = library
        self.world = World(world_spec, seed=seed)
        self.connect = list(connect)
        self.speed = float(speed)
        self.dt = step_for(self.speed)
        self.link_delay = float(link_delay)  # one way, sim seconds
        self.comms_window = comms_window  # None: always in contact (coverage permitting)
        self.feed_period = feed_period
        self.zenoh_extra = zenoh_extra
        self.link_delay_hint = link_delay_hint  # the network's delay (s), not the sim's
        # off: telemetry at a steady rate and the full status at every publication, as
        # before issue 31 (the baseline of bench/bench_linkbudget.py)
        self.link_budget = link_budget
        self._status_seq = 0  # live publications so far
        self._status_sent: dict[str, Any] | None = None  # the last one, as a patch's base
        self._status_full_at = -math.inf
        self.robot_seconds = 0.0
        self.exchanges: Counter[str] = Counter(
            asks=0, tells=0, answered=0, unknown=0, unreachable=0
        )
        self.exchange_log: deque[str] = deque(maxlen=30)
        self.notes: dict[str, str] = {}
        self.agents: dict[str, RobotAgent] = {}
        self.feed_bytes = 0
        self.status_bytes = 0
        self._seq = 0
        self.feed_id = uuid.uuid4().hex[:12]  # a restarted sim is a new feed: followers resync
        self._encoder: mf.TileEncoder | None = None
        self._objects: mf.MapObjects | None = None
        self._session: zenoh.Session | None = None
        self._entities: list[Any] = []
        self._delta_pub: zenoh.Publisher | None = None
        self._status_pub: zenoh.Publisher | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._started_wall = 0.0
        self._clock_at = (0.0, 0.0)  # (wall, sim) the clock counts from
        self.warnings: list[str] = [
            f"the skill library's figures differ from the world's: {d}"
            for d in drift(library, world_spec, self.world.models)
        ]
        self._add_robots(mission, telemetry_hz, telemetry_rates or {})
        self.telemetry_hz = telemetry_hz
        self.team = team  # robots that break or join (sim/team.py)
        if team is not None:
            team.check(self)

    # ------------------------------------------------------------ agents

    def _add_robots(self, mission: Mission, hz: float, rates: dict[str, float]) -> None:
        """A robot and its agent for each of the mission's robots the world has a
        model for (the others: a warning)."""
        for index, (name, spec) in enumerate(mission.robots.items()):
            if spec.type not in self.world.models:
                self.warnings.append(
                    f"not simulating {name}: the world has no model for type '{spec.type}' "
                    f"(it knows: {', '.join(sorted(self.world.models))}); it stays offline"
                )
                continue
            robot = self.world.add_robot(name, spec.type, index=index)
            self.agents[name] = self._make_agent(robot, rates.get(name, hz))
        if not self.agents:
            raise SimError("the mission has no robot this world can simulate")

    def _make_agent(self, robot: SimRobot, telemetry_hz: float) -> RobotAgent:
        rtype = self.library.robot_types.get(robot.type)
        if rtype is None:
            raise SimError(f"robot {robot.name}: type '{robot.type}' is not in the skill library")
        m = robot.model
        agent = RobotAgent(
            robot.name,
            robot.type,
            connect=self.connect,
            modules=_modules(m),
            properties=manifest_properties(self.world.spec, m),
            telemetry_hz=telemetry_hz,
            telemetry=None if self.link_budget else STEADY,
            zenoh_extra=self.zenoh_extra,
            link_delay_hint=self.link_delay_hint,
        )
        agent.time_scale = self.speed
        agent.mission_time = self.now

        def pose() -> Pose:
            r = robot
            return Pose(x=round(r.x, 3), y=round(r.y, 3), z=round(r.z, 3), yaw=round(r.yaw, 4))

        def battery() -> float:
            return robot.battery

        agent.pose = pose
        agent.battery = battery
        agent.link = SimLink(self.world, robot, self)
        self._add_skills(agent, robot, rtype.skills)
        WorldExchange(self.world, robot).register(agent)
        agent.on_choose(SimChooser(self.ask, self.world, robot))  # markers chosen on board
        return agent

    def _add_skills(self, agent: RobotAgent, robot: SimRobot, skills: list[str]) -> None:
        """The skills of the robot's type the simulator has (the others: a warning)."""
        handlers = RobotSkills(self, robot).handlers()
        missing = [s for s in skills if s not in handlers]
        if missing:
            self.warnings.append(
                f"{robot.name} offers no {', '.join(missing)} (the simulator has no such skill): "
                "syncing them is refused"
            )
        for name in skills:
            if name not in handlers:
                continue
            spec = self.library.skills.get(name)
            version = spec.version if spec is not None else "1.0.0"
            agent.add_skill(name, self._wrap(robot, name, handlers[name]), version=version)

    def _wrap(self, robot: SimRobot, name: str, fn: Any) -> Any:
        """The handler with the robot's activity kept for the world; its
        signature is `fn`'s (`functools.wraps`), which the agent checks
        against the library's."""

        @functools.wraps(fn)
        async def handler(ctx: Any, **params: Any) -> Any:
            if self.team is not None and self.team.arm_failed(robot.name, name):
                raise SkillFailed(f"{robot.name}'s manipulator failed: it cannot {name}")
            robot.activity = name
            robot.paused = lambda: ctx.paused
            try:
                return await fn(ctx, **params)  # a Success carries the result text
            finally:
                robot.activity = None
                robot.paused = lambda: False

        handler.__name__ = f"{robot.name}_{name}"
        return handler

    async def join(self, name: str, robot_type: str) -> None:
        """A robot arrives (`--join`): it registers under its new name."""
        robot = self.world.add_robot(name, robot_type, index=len(self.world.robots))
        agent = self.agents[name] = self._make_agent(robot, self.telemetry_hz)
        await agent.start()

    # ------------------------------------------------------------ world knowledge exchange

    def _exchange(self, text: str) -> None:
        self.exchange_log.append(f"[{self.world.now():7.0f} s] {text}")

    async def ask(
        self, sender: SimRobot, target: str, topic: str, data: dict[str, Any]
    ) -> dict[str, Any] | None:
        """`sender` asks `target` (through the SDK), if they can talk at all."""
        other = self.world.robots.get(target)
        agent = self.agents.get(sender.name)
        if other is None or agent is None:
            return None
        if not self.world.can_talk(sender, other):
            self.exchanges["unreachable"] += 1
            self._exchange(f"{sender.name} cannot reach {target} to ask about {topic}")
            return None
        self.exchanges["asks"] += 1
        answer = await agent.ask(target, topic, data)
        self.exchanges["answered" if answer is not None else "unknown"] += 1
        said = _brief(answer) if answer is not None else "unknown"
        self._exchange(f"{sender.name} asked {target} about {topic}: {said}")
        return answer

    async def tell(self, sender: SimRobot, target: str, topic: str, data: dict[str, Any]) -> bool:
        other = self.world.robots.get(target)
        agent = self.agents.get(sender.name)
        if other is None or agent is None:
            return False
        if not self.world.can_talk(sender, other):
            self.exchanges["unreachable"] += 1
            self._exchange(f"{sender.name} cannot reach {target} to tell about {topic}")
            return False
        self.exchanges["tells"] += 1
        ok = await agent.tell(target, topic, data)
        self._exchange(f"{sender.name} told {target} about {topic}: {_brief(data)}")
        return ok

    def note(self, robot: SimRobot, text: str) -> None:
        """The outcome of a skill: the robot reports it with its state (the ground view)."""
        self.notes[robot.name] = text
        robot.result = text

    # ------------------------------------------------------------ lifecycle

    async def start(self) -> None:
        cfg = transport.client_config(self.connect, extra=self.zenoh_extra)
        s = self._session = await asyncio.to_thread(
            transport.open_session, cfg, what="the mission server's router"
        )
        try:
            g = self.world.geom
            self._encoder = mf.TileEncoder(
                mf.MapMeta(
                    world=self.world.spec.name,
                    seed=self.world.seed,
                    x0=g.x0,
                    y0=g.y0,
                    cell=g.cell,
                    width=g.nx,
                    height=g.ny,
                )
            )
            self._encoder.delta(self._layers())  # the snapshot's starting point (seq 0)
            self._objects = self.world.ground.objects()
            self._delta_pub = transport.declare_publisher(s, mf.KEY_MAP_DELTA)
            self._status_pub = transport.declare_publisher(s, mf.KEY_STATUS_LIVE)
            self._entities += [
                transport.serve_async(s, mf.KEY_MAP_SNAPSHOT, self._on_snapshot),
                transport.serve_async(s, mf.KEY_STATUS, self._on_status),
            ]
            self._started_wall = time.monotonic()
            self._clock_at = (self._started_wall, self.world.clock)
            self.world.clock_source = self.now
            for agent in self.agents.values():
                await agent.start()
            self._tasks = [
                asyncio.create_task(self._physics(), name="sim-physics"),
                asyncio.create_task(self._feed(), name="sim-feed"),
                asyncio.create_task(self._status_loop(), name="sim-status"),
            ]
            if self.team is not None:
                self._tasks.append(asyncio.create_task(self.team.run(self), name="sim-team"))
        except BaseException:
            await self.stop()
            raise

    async def stop(self) -> None:
        tasks, self._tasks = self._tasks, []
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for agent in self.agents.values():
            try:
                await agent.stop()
            except Exception:
                log.exception("stopping %s failed", agent.name)
        session, self._session = self._session, None
        self._entities.clear()
        self._delta_pub = self._status_pub = None
        if session is not None:
            await asyncio.to_thread(transport.close_session, session)

    async def __aenter__(self) -> SimFleet:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # ------------------------------------------------------------ background physics

    def now(self) -> float:
        """The sim clock: wall time since the start times the speed."""
        wall, sim = self._clock_at
        return sim + (time.monotonic() - wall) * self.speed

    def ground_open(self) -> bool:
        """Is the ground in contact now (inside a comms window)?"""
        return self.comms_window is None or self.comms_window.is_open(self.now())

    async def _physics(self) -> None:
        """Idle robots: charge at the lander; hovering drones drain. The robots' downlinks."""
        loop = asyncio.get_running_loop()
        w = self.world
        while True:
            await asyncio.sleep(0.1)
            now = loop.time()
            clock = self.now()
            dt, w.clock = clock - w.clock, clock
            for r in w.robots.values():
                if r.activity is None or r.paused():  # else its skill moves it
                    _rest(w, r, dt)
            w.pump_downlink(now, self.link_delay / self.speed, ground_open=self.ground_open())

    # ------------------------------------------------------------ map feed

    def _layers(self) -> dict[str, Any]:
        """The map feed's layers as the ground knows them."""
        return self.world.ground.layers(self.world.terrain.grid, self.world.coverage)

    def _map_delta(self) -> mf.MapDelta | None:
        assert self._encoder is not None
        tiles = self._encoder.delta(self._layers())
        objects = self.world.ground.objects()
        changed = objects != self._objects
        if not tiles and not changed:
            return None
        self._objects = objects
        self._seq += 1
        return mf.MapDelta(
            feed=self.feed_id,
            seq=self._seq,
            sim_time=round(self.world.now(), 2),
            speed=self.speed,
            tiles=tiles,
            objects=objects if changed else None,
        )

    async def _feed(self) -> None:
        while True:
            await asyncio.sleep(self.feed_period)
            delta = self._map_delta()
            if delta is not None and self._delta_pub is not None:
                payload = mf.dump(delta)
                self.feed_bytes += len(payload)
                self._delta_pub.put(payload)

    def snapshot(self) -> mf.MapSnapshot:
        assert self._encoder is not None and self._objects is not None
        return mf.MapSnapshot(
            feed=self.feed_id,
            meta=self._encoder.meta,
            seq=self._seq,
            sim_time=round(self.world.now(), 2),
            speed=self.speed,
            tiles=self._encoder.full(),
            objects=self._objects,
        )

    async def _on_snapshot(self, payload: bytes) -> bytes:
        return mf.dump(self.snapshot())

    # ------------------------------------------------------------ status

    def status(self, *, with_truth: bool = False) -> mf.SimStatus:
        """The ground view (what robots reported); the truth as well if asked for."""
        st = ground_status(
            self.world, speed=self.speed, link_delay=self.link_delay, window=self.comms_window
        )
        if with_truth:
            st.truth = truth(self.world, exchanges=self.exchanges, exchange_log=self.exchange_log)
        st.feed, st.seq = self.feed_id, self._status_seq
        return st

    def _digest(self) -> tuple[Any, ...]:
        """What a new live publication is sent for (ground view only)."""
        w = self.world
        return (
            w.ground.score,
            len(w.ground.deliveries),
            w.ground.version,
            tuple(
                (
                    r.name,
                    w.in_range(r),
                    r.activity,
                    round(r.battery * 20),
                    r.airborne,
                    w.docked(r),
                    r.box,
                    tuple(r.stones),
                    r.result,
                )
                for r in w.robots.values()
                if w.in_range(r)
            ),
        )

    async def _on_status(self, payload: bytes) -> bytes:
        return mf.dump(self.status(with_truth=wants_truth(payload)))

    async def _status_loop(self) -> None:
        """Publish the status when it changed (at most every `STATUS_MIN` s)
        and at least every `STATUS_HEARTBEAT` s: what changed (a merge patch),
        the full status first and every `STATUS_KEYFRAME` s. Without the link
        budget: the full status, at least every `STATUS_MAX` s."""
        last_digest: tuple[Any, ...] | None = None
        last_put = 0.0
        heartbeat = STATUS_HEARTBEAT if self.link_budget else STATUS_MAX
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(STATUS_MIN)
            digest = self._digest()
            now = loop.time()
            if digest != last_digest or now - last_put >= heartbeat:
                last_digest, last_put = digest, now
                if self._status_pub is not None:
                    payload = self._status_update(now)
                    self.status_bytes += len(payload)
                    self._status_pub.put(payload)

    def _status_update(self, now: float) -> bytes:
        st = ground_status(
            self.world, speed=self.speed, link_delay=self.link_delay, window=self.comms_window
        )
        if not self.link_budget:
            return st.model_dump_json(exclude={"feed", "seq"}).encode()
        self._status_seq += 1
        raw = st.model_dump(mode="json", exclude={"feed", "seq"})
        sent, self._status_sent = self._status_sent, raw
        if sent is None or now - self._status_full_at >= STATUS_KEYFRAME:
            self._status_full_at = now
            return mf.dump(mf.StatusUpdate(feed=self.feed_id, seq=self._status_seq, full=st))
        patch = mf.merge_patch(sent, raw) or {}
        return mf.dump(mf.StatusUpdate(feed=self.feed_id, seq=self._status_seq, patch=patch))


def _modules(m: RobotModel) -> dict[str, str]:
    """The software modules a simulated robot registers with: one per capability."""
    return {"missionctl-sim": SIM_VERSION, "nav": "1.0.0", **dict.fromkeys(m.capabilities, "1.0.0")}


def _rest(w: World, r: SimRobot, dt: float) -> None:
    """`dt` sim seconds of a robot no skill moves: a paused skill's pause lasts, a
    hovering drone drains, one at the lander charges."""
    if r.activity is not None:
        r.paused_s += dt
    if r.kind == "drone" and r.airborne:
        _hover(w, r, dt)
    elif w.docked(r):
        r.charge(dt)


def _hover(w: World, r: SimRobot, dt: float) -> None:
    """A drone hovering drains; at the reserve it comes down where it is."""
    r.battery = max(0.0, r.battery - r.flight_energy(dt))
    if r.usable <= 0.0:
        r.airborne, r.z = False, 0.0
        w.log(
            f"{r.name} made an emergency landing at ({r.x:.1f}, {r.y:.1f}): "
            "battery at the reserve while hovering"
        )


def wants_truth(payload: bytes) -> bool:
    """A status query asking for the truth: the payload {"truth": true}."""
    try:
        return json.loads(payload or b"{}").get("truth") is True
    except (ValueError, AttributeError):
        return False


def _brief(data: dict[str, Any] | None) -> str:
    if not data:
        return "-"
    if "id" in data:
        at = f"({data.get('x', 0):.1f}, {data.get('y', 0):.1f})"
        return f"{data['id']} at {at} {data.get('state', '')}".strip()
    if "box" in data:
        return f"{data['box']} {data.get('where', '')}".strip()
    if "slots" in data:
        return "shelf " + (
            ", ".join(f"{k}: {v}" for k, v in sorted(data["slots"].items())) or "empty"
        )
    return ", ".join(sorted(data))[:60]


async def query_status(
    session: Any, timeout: float = 5.0, *, with_truth: bool = False
) -> mf.SimStatus:
    payload = mf.TRUTH_QUERY if with_truth else b""
    raw = await transport.query(session, mf.KEY_STATUS, payload, timeout=timeout)
    return mf.SimStatus.model_validate_json(raw)


__all__ = ["SimFleet", "SimLink", "query_status", "step_for", "wants_truth", "QueryFailed"]
