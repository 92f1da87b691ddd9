"""The simulated Mars sample-return site: grids (numpy), objects, robots' physics.

Pure state and rules: no Zenoh, no asyncio. The fleet (sim/fleet.py) steps
robots through it from skill handlers.

Truth and ground view: the world holds the truth (every explored cell, every
RSS and stone). What the operator sees (the map feed) is the *ground view*
(sim/ground.py): what robots sent over their downlinks (sim/downlink.py). A
robot out of communication coverage keeps what it learns aboard; it reaches
the ground once the robot is back in range (after the link delay). Elsewhere:
the terrain and routes (sim/terrain.py), the objects (sim/objects.py), a
robot and its energy (sim/robot.py).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from backend.protocol import mapfeed as mf
from sim.downlink import DownlinkPump
from sim.errors import SimError
from sim.ground import GroundView, News, RegionSeen, RobotState, rss_item
from sim.objects import BoxState, RssState, Stone, _fmt
from sim.pathing import GridGeom
from sim.robot import DEFAULT_MODELS, SimRobot
from sim.terrain import Terrain
from sim.worldfile import RobotStart, WorldFile

# ---------------------------------------------------------------- the world


class World:
    def __init__(self, spec: WorldFile, *, seed: int | None = None):
        self.spec = spec
        self.seed = spec.seed if seed is None else int(seed)
        s = spec.site
        nx = int(math.ceil((s.x_max - s.x_min) / s.cell - 1e-9))
        ny = int(math.ceil((s.y_max - s.y_min) / s.cell - 1e-9))
        self.geom = GridGeom(s.x_min, s.y_min, s.cell, nx, ny)
        self.models = {**DEFAULT_MODELS, **spec.models}
        rng = np.random.default_rng(self.seed)
        self.terrain = Terrain(spec, self.geom, rng)
        shape = self.geom.shape
        self.explored = np.zeros(shape, dtype=bool)  # truth: seen by any robot
        self.coverage = np.zeros(shape, dtype=np.float32)  # link quality 0..1
        self.rss: dict[str, RssState] = {}
        self.stones: dict[str, Stone] = {}
        self._place_rss(rng)
        self.boxes: dict[str, BoxState] = {}
        for name, b in spec.boxes.items():
            self.boxes[name] = BoxState(
                name,
                b.kind,
                b.at,
                b.slot if b.at == "shelf" else None,
                b.x if b.x is not None else spec.lander.x,
                b.y if b.y is not None else spec.lander.y,
            )
        self.recompute_coverage()
        self.robots: dict[str, SimRobot] = {}
        # scoring and referee's log
        self.score = 0.0
        self.delivered: list[mf.Delivery] = []
        self.events: deque[str] = deque(maxlen=40)
        self.clock = 0.0  # sim seconds (advanced by the fleet)
        # the fleet's clock between its updates of `clock` (None: `clock` is the time)
        self.clock_source: Callable[[], float] | None = None
        lander = spec.lander
        # what the ground knows: what robots sent over their downlinks
        self.ground = GroundView(
            shape,
            self.boxes,
            mf.LanderItem(
                x=lander.x,
                y=lander.y,
                pad_radius=lander.pad_radius,
                comm_radius=lander.comm_radius,
            ),
        )
        self.downlink = DownlinkPump(self.ground, shape)

    def _place_rss(self, rng: np.random.Generator) -> None:
        for r in self.spec.rss:
            state = RssState(r.name, r.x, r.y, r.radius, r.max_score)
            for k in range(r.stones):
                for _try in range(50):
                    ang = float(rng.uniform(0, 2 * math.pi))
                    dist = r.radius * math.sqrt(float(rng.uniform(0, 1)))
                    x, y = r.x + dist * math.cos(ang), r.y + dist * math.sin(ang)
                    if self.terrain.passable(x, y):
                        break
                sid = f"{r.name}-s{k + 1}"
                self.stones[sid] = Stone(sid, r.name, round(x, 2), round(y, 2))
                state.stones.append(sid)
            self.rss[r.name] = state

    # ------------------------------------------------------------ robots

    def add_robot(
        self, name: str, robot_type: str, start: RobotStart | None = None, index: int = 0
    ) -> SimRobot:
        model = self.models.get(robot_type)
        if model is None:
            raise SimError(
                f"robot {name}: the world has no model for type '{robot_type}' "
                f"(it knows: {', '.join(sorted(self.models))})"
            )
        if start is None:
            start = self.spec.robots.get(name)
        if start is None:
            start = self._spawn(index)
        robot = SimRobot(
            name, robot_type, model, x=start.x, y=start.y, yaw=start.yaw, battery=start.battery
        )
        if model.kind == "static":
            robot.battery = 1.0
        # every robot starts knowing the lander's boxes (it is the shared landmark)
        robot.knowledge.boxes = {
            n: b.public() for n, b in self.boxes.items() if b.where in ("shelf", "ground")
        }
        self.robots[name] = robot
        return robot

    def _spawn(self, index: int) -> RobotStart:
        """Start poses for robots the world file does not place: rings around the lander."""
        lx, ly = self.spec.lander.x, self.spec.lander.y
        ring, k = 0, index
        while k >= 8 * (ring + 1):
            k -= 8 * (ring + 1)
            ring += 1
        n = 8 * (ring + 1)
        r = 8.0 + 3.0 * ring
        ang = 2 * math.pi * k / n
        x, y = lx + r * math.cos(ang), ly + r * math.sin(ang)
        return RobotStart(x=round(x, 2), y=round(y, 2), yaw=round(ang, 3))

    def now(self) -> float:
        """Sim seconds since the start (the fleet's clock, exact between its updates)."""
        return self.clock_source() if self.clock_source is not None else self.clock

    def log(self, text: str) -> None:
        self.events.append(f"[{self.now():7.0f} s] {text}")

    # ------------------------------------------------------------ queries

    def dist_to_lander(self, x: float, y: float) -> float:
        return math.hypot(x - self.spec.lander.x, y - self.spec.lander.y)

    def at_lander(self, robot: SimRobot, margin: float = 0.0) -> bool:
        return self.dist_to_lander(robot.x, robot.y) <= self.spec.lander.pad_radius + margin

    def docked(self, robot: SimRobot) -> bool:
        """Charging position: at the lander (a drone: landed on the pad)."""
        if robot.kind == "static":
            return False
        if robot.kind == "drone" and robot.airborne:
            return False
        return self.at_lander(robot)

    def link_quality(self, x: float, y: float) -> float:
        if not self.geom.inside(x, y):
            return 0.0
        return float(self.coverage[self.geom.cell_of(x, y)])

    def in_range(self, robot: SimRobot) -> bool:
        return self.link_quality(robot.x, robot.y) > 0.0

    def can_talk(self, a: SimRobot, b: SimRobot) -> bool:
        """Robots talk through the network when both are covered, or directly when close."""
        if self.in_range(a) and self.in_range(b):
            return True
        return math.hypot(a.x - b.x, a.y - b.y) <= self.spec.comms.direct_range

    def rss_near(self, x: float, y: float, margin: float) -> RssState | None:
        best, best_d = None, math.inf
        for r in self.rss.values():
            d = math.hypot(x - r.x, y - r.y) - r.radius
            if d <= margin and d < best_d:
                best, best_d = r, d
        return best

    def explored_fraction(self, mask: np.ndarray | None = None, *, ground: bool = False) -> float:
        grid = self.ground.explored if ground else self.explored
        if mask is None:
            return float(grid.mean())
        total = int(mask.sum())
        return float((grid & mask).sum()) / total if total else 1.0

    # ------------------------------------------------------------ coverage

    def recompute_coverage(self) -> None:
        """Quality = 1 - 0.8 (d/R)^2 inside each source's radius. A Wi-Fi box
        relays only when it stands inside coverage already (a chain from the lander)."""
        g = self.geom
        cov = np.zeros(g.shape, dtype=np.float32)
        lander = self.spec.lander

        def add(x: float, y: float, r: float) -> None:
            rows, cols = g.window(x, y, r)
            dx = g.xs[cols] - x
            dy = g.ys[rows] - y
            d2 = dy[:, None] ** 2 + dx[None, :] ** 2
            q = np.where(d2 <= r * r, 1.0 - 0.8 * d2 / (r * r), 0.0).astype(np.float32)
            np.maximum(cov[rows, cols], q, out=cov[rows, cols])

        add(lander.x, lander.y, lander.comm_radius)
        pending = [b for b in self.boxes.values() if b.on and b.where == "ground"]
        linked = True
        while pending and linked:
            linked = False
            for b in list(pending):
                if g.inside(b.x, b.y) and cov[g.cell_of(b.x, b.y)] > 0:
                    add(b.x, b.y, self.spec.comms.wifi_range)
                    pending.remove(b)
                    linked = True
        self.coverage = cov

    # ------------------------------------------------------------ downlink (robot -> ground)

    def tell_ground(self, robot: SimRobot, news: News) -> None:
        """It reaches the ground once the robot can send (sim/downlink.py)."""
        self.downlink.send(robot, news)

    def pump_downlink(self, now: float, delay: float, ground_open: bool = True) -> bool:
        """Every robot's downlink (`DownlinkPump.pump`); True if anything arrived."""
        return self.downlink.pump(
            self.robots.values(),
            now,
            delay,
            ground_open=ground_open,
            in_range=self.in_range,
            state_of=self.robot_state,
        )

    def robot_state(self, robot: SimRobot) -> RobotState:
        """What a robot reports about itself (the ground's record of it, once heard)."""
        return RobotState(
            x=round(robot.x, 2),
            y=round(robot.y, 2),
            z=round(robot.z, 2),
            yaw=round(robot.yaw, 3),
            battery=round(min(1.0, max(0.0, robot.battery)), 4),
            link=round(self.link_quality(robot.x, robot.y), 3),
            airborne=robot.airborne,
            docked=self.docked(robot),
            box=robot.box,
            stones=list(robot.stones),
            activity=robot.activity,
            result=robot.result,
            odometer_m=round(robot.odometer, 1),
            sim_seconds=round(robot.sim_seconds, 1),
            heard_at=round(self.now(), 1),
        )

    # ------------------------------------------------------------ sensing

    def reveal(self, robot: SimRobot, r: float) -> int:
        """Map the cells within r of the robot; returns how many were new (truth)."""
        if r <= 0:
            return 0
        rows, cols, mask = self.geom.disk(robot.x, robot.y, r)
        sub = self.explored[rows, cols]
        new = int((mask & ~sub).sum())
        sub |= mask
        self.downlink.explored(robot, rows, cols, mask & ~self.ground.explored[rows, cols])
        return new

    def discover(self, robot: SimRobot, r: float) -> list[str]:
        """RSSs the robot's sensors reach (within r of any part of the region)."""
        found = []
        for rss in self.rss.values():
            if robot.name in rss.found_by:
                continue
            if math.hypot(robot.x - rss.x, robot.y - rss.y) <= r + rss.radius * 0.5:
                rss.found_by.add(robot.name)
                info = robot.knowledge.learn_rss(rss.sighting())
                self.tell_ground(robot, RegionSeen(rss_item(info)))
                self.log(f"{robot.name} discovered {rss.name} at {_fmt(rss.x, rss.y)}")
                found.append(rss.name)
        return found
