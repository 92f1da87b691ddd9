"""World files (`missions/worlds/*.yaml`): the simulated site, validated by pydantic.

A world file describes a site: its extent and grid, the lander, generated and
hand-placed terrain, regions ideal for sampling stones (RSSs, with a hidden
maximum score), payload boxes, robot models per skill-library robot type and
robot start poses. Everything random (rock fields, sand, stone positions) is
drawn from `seed`, so a world is the same for the same file and seed.

Problems are reported like the mission files': `file:line:col: path: message`
(`FileProblems` with `Issue`s from backend.files.missions).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Final, Literal

from pydantic import Field, ValidationError, model_validator

from backend.core.model import Name, Strict
from backend.files import yamlio
from backend.files.diagnostics import FileProblems, Issue, duplicate_issues, pydantic_issues

WORLD_FORMAT: Final = "missionctl/world@1"
RobotKind = Literal["rover", "drone", "static"]

BoxName = Name


class Site(Strict):
    x_min: float = -160.0
    x_max: float = 160.0
    y_min: float = -160.0
    y_max: float = 160.0
    cell: float = Field(2.0, gt=0.1, le=10.0, description="grid cell size in metres")

    @model_validator(mode="after")
    def _extent(self) -> Site:
        if self.x_max <= self.x_min or self.y_max <= self.y_min:
            raise ValueError("the site is empty: x_max/y_max must be greater than x_min/y_min")
        cells = ((self.x_max - self.x_min) / self.cell) * ((self.y_max - self.y_min) / self.cell)
        if cells > 4_000_000:
            raise ValueError(
                f"the grid would have {cells:,.0f} cells (at most 4,000,000): use a larger cell"
            )
        return self


class Lander(Strict):
    x: float = 0.0
    y: float = 0.0
    pad_radius: float = Field(
        5.0, gt=0, description="robots this close are at the lander (dock, shelf, pad)"
    )
    comm_radius: float = Field(60.0, gt=0, description="radius of the lander's Wi-Fi coverage")
    shelf_slots: int = Field(4, ge=1, le=16)


class Circle(Strict):
    x: float
    y: float
    r: float = Field(gt=0)


class Point(Strict):
    x: float
    y: float


class Feature(Strict):
    """A hand-placed terrain feature: a circle or a polygon of slow/impassable/free ground."""

    name: str = ""
    kind: Literal["slow", "impassable", "free"]
    circle: Circle | None = None
    polygon: list[Point] | None = Field(None, min_length=3)

    @model_validator(mode="after")
    def _one_shape(self) -> Feature:
        if (self.circle is None) == (self.polygon is None):
            raise ValueError("give exactly one of 'circle' or 'polygon'")
        return self


class Scatter(Strict):
    """Seeded random blobs (rock fields or sand patches)."""

    count: int = Field(0, ge=0, le=10_000)
    radius: tuple[float, float] = (3.0, 8.0)

    @model_validator(mode="after")
    def _radius(self) -> Scatter:
        lo, hi = self.radius
        if lo <= 0 or hi < lo:
            raise ValueError("radius must be [min, max] with 0 < min <= max")
        return self


class TerrainSpec(Strict):
    rock_fields: Scatter = Field(default_factory=lambda: Scatter(count=30, radius=(3.0, 8.0)))
    sand_patches: Scatter = Field(default_factory=lambda: Scatter(count=25, radius=(6.0, 16.0)))
    slow_factor: float = Field(
        0.4, gt=0.0, le=1.0, description="speed factor on slow (sandy) cells"
    )
    slow_energy: float = Field(
        1.8, ge=1.0, le=10.0, description="energy factor per metre on slow cells"
    )
    features: list[Feature] = Field(default_factory=list)
    keep_clear: list[Circle] = Field(
        default_factory=list,
        description=(
            "never covered by random rocks or sand (RSSs, the lander and start poses are added)"
        ),
    )


class RSS(Strict):
    """A region ideal for sampling stones; unknown until explored."""

    name: Name
    x: float
    y: float
    radius: float = Field(8.0, gt=0.5, le=100.0)
    max_score: float = Field(gt=0.0, le=100.0, description="hidden: the best stone's score")
    stones: int = Field(5, ge=1, le=100)


class Box(Strict):
    kind: Literal["sample", "wifi", "lofar", "power"]
    at: Literal["shelf", "storage", "ground"] = "storage"
    slot: int | None = Field(None, ge=1, le=16, description="shelf slot (at: shelf)")
    x: float | None = None
    y: float | None = None

    @model_validator(mode="after")
    def _place(self) -> Box:
        if self.at == "shelf" and self.slot is None:
            raise ValueError("a box on the shelf needs a 'slot'")
        if self.at == "ground" and (self.x is None or self.y is None):
            raise ValueError("a box on the ground needs 'x' and 'y'")
        return self


class RobotModel(Strict):
    """Physical model of a robot type (by skill-library type name)."""

    kind: RobotKind
    description: str = ""
    capabilities: list[str] = Field(
        default_factory=list, description="science_camera, manipulator, ..."
    )
    speed: float = Field(0.5, gt=0, le=30, description="default cruise speed, m/s")
    max_speed: float = Field(1.0, gt=0, le=30)
    sensor_range: float = Field(
        10.0,
        gt=0,
        le=200,
        description="explore sensor range, m (drone: per m of altitude x 4, capped)",
    )
    nav_range: float = Field(4.0, ge=0, le=50, description="terrain mapped while driving, m")
    metres_per_battery: float = Field(
        1000.0, gt=0, description="rover: metres on free ground per full battery"
    )
    flight_s_per_battery: float = Field(
        600.0, gt=0, description="drone: seconds airborne per full battery"
    )
    work_per_hour: float = Field(
        0.3, ge=0, le=10, description="battery fraction per hour of work (arm, camera, computing)"
    )
    charge_per_minute: float = Field(
        0.25, gt=0, le=10, description="battery fraction per minute at the lander"
    )
    reserve: float = Field(
        0.05, ge=0, lt=0.5, description="battery kept back: 'empty' means down to this"
    )
    carry_stones: int = Field(0, ge=0, le=10, description="stones held without a sample box")
    carry_stones_in_box: int = Field(
        0, ge=0, le=50, description="stones held in a carried sample box"
    )


class RobotStart(Strict):
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    battery: float = Field(1.0, ge=0.0, le=1.0)


class Comms(Strict):
    wifi_range: float = Field(45.0, gt=0, description="coverage radius of a deployed Wi-Fi box")
    direct_range: float = Field(
        30.0, ge=0, description="robots this close talk to each other without coverage"
    )


class Scoring(Strict):
    min_score: float = Field(
        0.1, gt=0, description="score of a stone identified without LRU1 and LRU2 together"
    )
    collab_range: float = Field(
        12.0, gt=0, description="both identifiers within this distance of the target"
    )


class WorldFile(Strict):
    format: Literal["missionctl/world@1"] = WORLD_FORMAT
    name: str = "world"
    description: str = ""
    seed: int = Field(1, ge=0)
    site: Site = Field(default_factory=Site)
    lander: Lander = Field(default_factory=Lander)
    terrain: TerrainSpec = Field(default_factory=TerrainSpec)
    comms: Comms = Field(default_factory=Comms)
    scoring: Scoring = Field(default_factory=Scoring)
    rss: list[RSS] = Field(default_factory=list)
    boxes: dict[BoxName, Box] = Field(default_factory=dict)
    models: dict[Name, RobotModel] = Field(default_factory=dict)
    robots: dict[Name, RobotStart] = Field(default_factory=dict)


def _inside(site: Site, x: float, y: float) -> bool:
    return site.x_min <= x <= site.x_max and site.y_min <= y <= site.y_max


Problem = tuple[tuple[str | int, ...], str]  # (field path, sentence)


def check_world(w: WorldFile) -> list[Problem]:
    """Semantic problems: (field path, sentence)."""
    return [problem for check in _CHECKS for problem in check(w)]


def _lander_problems(w: WorldFile) -> list[Problem]:
    if _inside(w.site, w.lander.x, w.lander.y):
        return []
    return [(("lander",), f"the lander ({w.lander.x:g}, {w.lander.y:g}) is outside the site")]


def _region_problems(w: WorldFile) -> list[Problem]:
    out: list[Problem] = []
    names: set[str] = set()
    for i, r in enumerate(w.rss):
        if r.name in names:
            out.append((("rss", i, "name"), f"duplicate region name '{r.name}'"))
        names.add(r.name)
        if not _inside(w.site, r.x, r.y):
            out.append((("rss", i), f"region {r.name} ({r.x:g}, {r.y:g}) is outside the site"))
    return out


def _box_problems(w: WorldFile) -> list[Problem]:
    out: list[Problem] = []
    slots: dict[int, str] = {}  # slot -> the box in it
    for name, b in w.boxes.items():
        if b.at == "shelf" and b.slot is not None:
            out += _slot_problems(w, name, b.slot, slots)
            slots[b.slot] = name
        if (
            b.at == "ground"
            and b.x is not None
            and b.y is not None
            and not _inside(w.site, b.x, b.y)
        ):
            out.append((("boxes", name), "the box lies outside the site"))
    return out


def _slot_problems(w: WorldFile, name: str, slot: int, slots: dict[int, str]) -> list[Problem]:
    where = ("boxes", name, "slot")
    if slot > w.lander.shelf_slots:
        return [(where, f"slot {slot} does not exist (the shelf has {w.lander.shelf_slots})")]
    if slot in slots:
        return [(where, f"slot {slot} already holds {slots[slot]}")]
    return []


def _model_problems(w: WorldFile) -> list[Problem]:
    return [
        (("models", name, "speed"), f"cruise speed {m.speed:g} is above max_speed {m.max_speed:g}")
        for name, m in w.models.items()
        if m.speed > m.max_speed
    ]


def _start_problems(w: WorldFile) -> list[Problem]:
    return [
        (("robots", name), f"start ({start.x:g}, {start.y:g}) is outside the site")
        for name, start in w.robots.items()
        if not _inside(w.site, start.x, start.y)
    ]


# in the order a world file is written
_CHECKS: tuple[Callable[[WorldFile], list[Problem]], ...] = (
    _lander_problems,
    _region_problems,
    _box_problems,
    _model_problems,
    _start_problems,
)


def parse_world(text: str, file: str = "<world>") -> WorldFile:
    """Validate a world file's text; raises FileProblems with every issue."""
    try:
        doc = yamlio.load(text)
    except yamlio.YamlSyntaxError as e:
        raise FileProblems([Issue(file, e.path, e.message, e.line, e.col)]) from None
    if not isinstance(doc.data, dict):
        raise FileProblems(
            [Issue(file, (), "expected a YAML mapping at the top of the file", 1, 1)]
        )
    issues = duplicate_issues(file, doc)
    try:
        world = WorldFile.model_validate(doc.data)
    except ValidationError as exc:
        raise FileProblems(issues + pydantic_issues(file, doc, exc)) from None
    for path, message in check_world(world):
        line, col = doc.mark(path)
        issues.append(Issue(file, path, message, line, col))
    if issues:
        raise FileProblems(sorted(issues, key=lambda i: (i.line, i.col)))
    return world


def load_world(path: str | Path) -> WorldFile:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileProblems([Issue(str(p), (), "no such file")]) from None
    except IsADirectoryError:
        raise FileProblems([Issue(str(p), (), "is a directory, not a file")]) from None
    except UnicodeDecodeError as e:
        raise FileProblems(
            [Issue(str(p), (), f"not UTF-8 text ({e.reason} at byte {e.start})")]
        ) from None
    except OSError as e:
        raise FileProblems([Issue(str(p), (), f"cannot read: {e.strerror}")]) from None
    return parse_world(text, str(p))


DEFAULT_WORLD = Path(__file__).resolve().parents[1] / "missions" / "worlds" / "mars.yaml"


def default_world_for(mission_file: str | Path | None) -> Path:
    """`worlds/mars.yaml` next to the mission file, else the repository's."""
    if mission_file is not None:
        candidate = Path(mission_file).resolve().parent / "worlds" / "mars.yaml"
        if candidate.exists():
            return candidate
    return DEFAULT_WORLD
