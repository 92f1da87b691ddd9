"""A simulated robot: its model, where it is, its battery, what it carries and
knows (what it has to tell the ground waits in sim/downlink.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from sim.objects import Knowledge
from sim.worldfile import RobotKind, RobotModel

DEFAULT_MODELS: dict[str, RobotModel] = {
    "lru_science": RobotModel(kind="rover", capabilities=["science_camera", "stereo_camera"]),
    "lru_manipulator": RobotModel(
        kind="rover",
        capabilities=["manipulator", "stereo_camera"],
        carry_stones=1,
        carry_stones_in_box=4,
    ),
    "drone": RobotModel(
        kind="drone",
        capabilities=["stereo_camera"],
        speed=2.0,
        max_speed=5.0,
        sensor_range=20.0,
        nav_range=8.0,
        charge_per_minute=0.5,
    ),
    "lander": RobotModel(kind="static"),
}


@dataclass
class SimRobot:
    name: str
    type: str
    model: RobotModel
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    battery: float = 1.0
    airborne: bool = False
    activity: str | None = None  # skill being executed
    paused: Callable[[], bool] = lambda: False
    box: str | None = None  # carried payload box
    stones: list[str] = field(default_factory=list)  # carried stones
    knowledge: Knowledge = field(default_factory=Knowledge)
    odometer: float = 0.0
    sim_seconds: float = 0.0  # robot time stepped by skills
    result: str = ""  # the outcome of its last skill (reported with its state)
    paused_s: float = 0.0  # sim seconds its skills spent paused (the fleet counts them)

    @property
    def kind(self) -> RobotKind:
        return self.model.kind

    def has(self, capability: str) -> bool:
        return capability in self.model.capabilities

    @property
    def usable(self) -> float:
        return max(0.0, self.battery - self.model.reserve)

    # energy, as fractions of a full battery (the model's rates)

    def drive_energy(self, distance: float, factor: float = 1.0) -> float:
        """Driving `distance` metres; `factor`: the ground's (sand costs more)."""
        return distance * factor / self.model.metres_per_battery

    def work_energy(self, dt: float, load: float = 1.0) -> float:
        return dt * self.model.work_per_hour * load / 3600.0

    def flight_energy(self, dt: float) -> float:
        return dt / self.model.flight_s_per_battery

    def charge(self, dt: float, up_to: float = 1.0) -> None:
        if self.battery < up_to:
            self.battery = min(up_to, self.battery + dt * self.model.charge_per_minute / 60.0)

    def pose_tuple(self) -> tuple[float, float]:
        return self.x, self.y
