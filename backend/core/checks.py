"""Semantic checks of libraries and missions, shared by the files and the rules.

A file is checked with them when it is loaded (`backend.files`) and a mission
replaced live with them too (`LoadMission` in the rules), so both refuse the
same things with the same sentences. Each problem is a (field path, message).
"""

from __future__ import annotations

from collections.abc import Callable

from backend.core.contingency import after_problems, contingency_problems
from backend.core.library import Library, RobotType, SkillSpec, check_params
from backend.core.model import Mission, SkillInstance, Status, format_path, section_problems
from backend.core.params import ParamSpec

Path = tuple[str | int, ...]
Problem = tuple[Path, str]


def check_library(lib: Library) -> list[Problem]:
    out: list[Problem] = []
    for tname, rt in lib.robot_types.items():
        out += _robot_type_problems(lib, tname, rt)
    for sname, spec in lib.skills.items():
        out += _skill_spec_problems(sname, spec)
        out += _energy_problems(lib, sname, spec)
    return out


def _robot_type_problems(lib: Library, tname: str, rt: RobotType) -> list[Problem]:
    out: list[Problem] = []
    seen = set()
    for i, s in enumerate(rt.skills):
        if s not in lib.skills:
            out.append(
                (
                    ("robot_types", tname, "skills", i),
                    f"unknown skill '{s}' (not defined under 'skills')",
                )
            )
        if s in seen:
            out.append((("robot_types", tname, "skills", i), f"skill '{s}' is listed twice"))
        seen.add(s)
    return out


def _skill_spec_problems(sname: str, spec: SkillSpec) -> list[Problem]:
    """A skill's parameter defaults valid, and every parameter its spec names
    one of the kind it needs."""
    out: list[Problem] = [
        (("skills", sname, "params", pname, "default"), why)
        for pname, pspec in spec.params.items()
        if (why := pspec.default_problem())
    ]
    for path, pname, kind in _references(spec):
        what, fits = _KINDS[kind]
        p = spec.params.get(pname)
        if p is None or not fits(p):
            out.append((("skills", sname, *path), f"'{pname}' is not {what} of '{sname}'"))
    return out


# The kind of parameter a reference needs: how a sentence names it, and the test.
_KINDS: dict[str, tuple[str, Callable[[ParamSpec], bool]]] = {
    "goal": ("a pose or position parameter", lambda p: p.kind.goal),
    "robot": ("a robot parameter", lambda p: p.type == "robot"),
    "numeric": ("a numeric parameter", lambda p: p.kind.numeric),
    "area": ("an area parameter", lambda p: p.type == "area"),
    "any": ("a parameter", lambda p: True),
}


def _references(spec: SkillSpec) -> list[tuple[Path, str, str]]:
    """Where a skill's spec names one of its parameters, in the order the
    problems are told: (path under the skill, the name, its kind in _KINDS)."""
    d = spec.duration
    refs: list[tuple[Path, str | None, str]] = [
        (("duration", "goal_param"), d.goal_param, "goal"),
        (("talks_to",), spec.talks_to, "robot"),
    ]
    refs += [(("duration", "per_param_s", p), p, "numeric") for p in d.per_param_s]
    refs += [
        (("duration", "speed_param"), d.speed_param, "numeric"),
        (("duration", "charge_param"), d.charge_param, "numeric"),
        (("duration", "area_param"), d.area_param, "area"),
    ]
    if isinstance(d.to_home, dict):
        refs += [(("duration", "to_home", p), p, "any") for p in d.to_home]
    return [(path, name, kind) for path, name, kind in refs if name is not None]


def _energy_problems(lib: Library, sname: str, spec: SkillSpec) -> list[Problem]:
    """The energy model names robot types that exist."""
    known = ", ".join(lib.robot_types) or "none"
    return [
        (
            ("skills", sname, "energy", "by_type", tname),
            f"unknown robot type '{tname}' (library types: {known})",
        )
        for tname in spec.energy.by_type
        if tname not in lib.robot_types
    ]


def resolve_shorthands(m: Mission, lib: Library) -> None:
    """`goal: "@POI-A"` in a file binds the parameter to marker POI-A (or,
    for a marker parameter, names it)."""
    for robot, task in m.tasks.items():
        spec = m.robots.get(robot)
        if spec is None or not spec.type:
            continue
        for s in task:
            skill = lib.skill_for(spec.type, s.skill)
            if skill is not None:
                _resolve(s, skill)


def _resolve(s: SkillInstance, spec: SkillSpec) -> None:
    """The `@NAME` values of a skill's parameters that take a marker: the
    marker's name, or a binding to it (the checks refuse the others)."""
    for name, v in list(s.params.items()):
        pspec = spec.params.get(name)
        if pspec is None or not (isinstance(v, str) and v.startswith("@")):
            continue
        if pspec.kind.names_marker:
            s.params[name] = v[1:]
        elif pspec.kind.bindable_to:
            s.bindings[name] = v[1:]
            del s.params[name]


def check_mission(m: Mission, lib: Library, *, fill: bool = True) -> list[Problem]:
    """Every rule a mission must satisfy against its library. With `fill`,
    parameters are normalized and defaults filled in place."""
    out = _robot_problems(m, lib)
    ids: dict[str, Path] = {}  # skill id -> where it is first used
    for robot, task in m.tasks.items():
        out += _task_problems(m, lib, robot, task, ids, fill)
    out += _barrier_problems(m)
    return out


def _robot_problems(m: Mission, lib: Library) -> list[Problem]:
    known = ", ".join(lib.robot_types) or "none"
    return [
        (
            ("robots", name, "type"),
            f"unknown robot type '{spec.type}' (library types: {known})",
        )
        for name, spec in m.robots.items()
        if spec.type not in lib.robot_types
    ]


def _task_problems(
    m: Mission,
    lib: Library,
    robot: str,
    task: list[SkillInstance],
    ids: dict[str, Path],
    fill: bool,
) -> list[Problem]:
    if robot not in m.robots:
        known = ", ".join(sorted(m.robots)) or "none"
        return [(("tasks", robot), f"tasks for unknown robot '{robot}' (robots: {known})")]
    rtype = m.robots[robot].type
    robots = set(m.robots)
    out: list[Problem] = []
    for i, s in enumerate(task):
        here: Path = ("tasks", robot, i)
        out += _first_use(ids, s.id, here)
        if rtype in lib.robot_types:
            out += _skill_problems(m, lib, robot, s, here, robots=robots, fill=fill)
    for i, why in section_problems(task):
        out.append((("tasks", robot, i, "status"), why))
    return out


def _first_use(ids: dict[str, Path], sid: str, here: Path) -> list[Problem]:
    """A skill id used before is a duplicate (said with where it was first);
    else it is noted as first used `here`."""
    if sid in ids:
        return [
            ((*here, "id"), f"duplicate skill id '{sid}' (first used at {format_path(ids[sid])})")
        ]
    ids[sid] = here
    return []


def _skill_problems(
    m: Mission,
    lib: Library,
    robot: str,
    s: SkillInstance,
    here: Path,
    *,
    robots: set[str],
    fill: bool,
) -> list[Problem]:
    """A skill against its robot's type: offered, and its parameters valid."""
    rtype = m.robots[robot].type
    if lib.skill_for(rtype, s.skill) is None:
        offered = ", ".join(lib.skills_of(rtype)) or "none"
        return [
            (
                (*here, "skill"),
                f"robot '{robot}' ({rtype}) has no skill '{s.skill}' (it offers: {offered})",
            )
        ]
    out = _param_problems(m, lib, rtype, s, here, robots=robots, fill=fill)
    if s.status == Status.IDLE:  # a skill sent already keeps the contingencies it was sent with
        out += [
            ((*here, *path), why)
            for path, why in contingency_problems(s.policies, lib, rtype, m.markers, robots)
            + after_problems(m, robot, s.policies)
        ]
    return out


def _param_problems(
    m: Mission,
    lib: Library,
    rtype: str,
    s: SkillInstance,
    here: Path,
    *,
    robots: set[str],
    fill: bool,
) -> list[Problem]:
    """A skill's parameters and bindings checked; with `fill`, its parameters
    normalized (defaults filled in) when they are all valid."""
    # a skill on a robot (or in the log) keeps the values it was sent
    # with: its bindings are history, never re-applied
    idle = s.status == Status.IDLE
    params, problems = check_params(
        lib,
        rtype,
        s.skill,
        s.params,
        s.bindings if idle else {},
        markers=m.markers,
        robots=robots,
        fill_defaults=idle,
    )
    out = [((*here, _field_of(s, p.path), *p.path), p.message) for p in problems]
    if not problems and fill:
        s.params = params
    return out


def _field_of(s: SkillInstance, path: tuple[str | int, ...]) -> str:
    """Where a parameter's problem is in the file: under `bindings` if the
    parameter is bound (and not given), else under `params`."""
    bound = bool(path) and path[0] in s.bindings and path[0] not in s.params
    return "bindings" if bound else "params"


def _barrier_problems(m: Mission) -> list[Problem]:
    out: list[Problem] = []
    owner: dict[str, str] = {}  # skill id -> its barrier
    for bid, b in m.barriers.items():
        out += _one_barrier_problems(m, bid, b.skills, owner)
    return out


def _one_barrier_problems(
    m: Mission, bid: str, ids: list[str], owner: dict[str, str]
) -> list[Problem]:
    """Barrier `bid`'s problems: its members' (noted in `owner`), too few
    robots, members that would wait forever."""
    out: list[Problem] = []
    robots_in: dict[str, str] = {}  # robot -> its skill in this barrier
    for j, sid in enumerate(ids):
        found = _member_problems(m, bid, ids[:j], sid, robots_in, owner)
        out += [(("barriers", bid, "skills", j), why) for why in found]
    if len(robots_in) < 2 and len(ids) >= 2 and all(m.find(s) for s in ids):
        out.append((("barriers", bid), "a barrier needs skills of at least two robots"))
    return out + _stranded(m, bid, ids)


# Where a barrier's skills can be: `ctl barrier` joins idle skills, which are
# then synchronized and wait at the barrier; all start together and finish.
_BEFORE = frozenset({Status.IDLE, Status.IDLE_SYNCHRONIZED, Status.SYNCHWAITING})


def _stranded(m: Mission, bid: str, ids: list[str]) -> list[Problem]:
    """Skills of barrier `bid` still to start while a partner has started or
    finished: they would wait for it forever (the live rules never make such
    a barrier; a file must not either)."""
    found = [(j, f[2]) for j, sid in enumerate(ids) if (f := m.find(sid)) is not None]
    past = ", ".join(f"'{s.id}' is {s.status.value}" for _, s in found if s.status not in _BEFORE)
    if not past:  # no partner started
        return []
    return [
        (
            ("barriers", bid, "skills", j),
            f"'{s.id}' ({s.status.value}) would wait forever: its partner {past}; "
            "a barrier joins skills that start together (idle ones, as `ctl barrier` does)",
        )
        for j, s in found
        if s.status in _BEFORE
    ]


def _member_problems(
    m: Mission,
    bid: str,
    before: list[str],
    sid: str,
    robots_in: dict[str, str],
    owner: dict[str, str],
) -> list[str]:
    """What is wrong with skill `sid` in barrier `bid`, after the skills
    `before` it; notes its robot in `robots_in` and its barrier in `owner`."""
    if sid in before:
        return [f"skill '{sid}' is listed twice"]
    found = m.find(sid)
    if found is None:
        return [f"unknown skill id '{sid}'"]
    out: list[str] = []
    robot = found[0]
    if robot in robots_in:
        out.append(
            f"skills '{robots_in[robot]}' and '{sid}' both belong to robot '{robot}'; "
            "a barrier has one skill per robot"
        )
    robots_in[robot] = sid
    if sid in owner:
        out.append(f"skill '{sid}' is already in barrier '{owner[sid]}'")
    owner[sid] = bid
    return out
