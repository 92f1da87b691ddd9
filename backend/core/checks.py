"""Semantic checks of libraries and missions, shared by the files and the rules.

A file is checked with them when it is loaded (`backend.files`) and a mission
replaced live with them too (`LoadMission` in the rules), so both refuse the
same things with the same sentences. Each problem is a (field path, message).
"""

from __future__ import annotations

from backend.core.library import Library, check_params
from backend.core.model import Mission, Status, format_path, section_problems

Path = tuple[str | int, ...]


def check_library(lib: Library) -> list[tuple[Path, str]]:
    out: list[tuple[Path, str]] = []
    for tname, rt in lib.robot_types.items():
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
    for sname, spec in lib.skills.items():
        for pname, pspec in spec.params.items():
            why = pspec.default_problem()
            if why:
                out.append((("skills", sname, "params", pname, "default"), why))
        d = spec.duration
        if d.goal_param is not None:
            p = spec.params.get(d.goal_param)
            if p is None or p.type not in ("pose", "position"):
                out.append(
                    (
                        ("skills", sname, "duration", "goal_param"),
                        f"'{d.goal_param}' is not a pose or position parameter of '{sname}'",
                    )
                )
        for pname in d.per_param_s:
            p = spec.params.get(pname)
            if p is None or p.type not in ("int", "float"):
                out.append(
                    (
                        ("skills", sname, "duration", "per_param_s", pname),
                        f"'{pname}' is not a numeric parameter of '{sname}'",
                    )
                )
    return out


def resolve_shorthands(m: Mission, lib: Library) -> None:
    """`goal: "@POI-A"` in a file binds the parameter to marker POI-A."""
    for robot, task in m.tasks.items():
        rtype = m.robots[robot].type if robot in m.robots else None
        for s in task:
            spec = lib.skill_for(rtype, s.skill) if rtype else None
            for name, v in list(s.params.items()):
                if not (isinstance(v, str) and v.startswith("@")):
                    continue
                pspec = spec.params.get(name) if spec else None
                if pspec is not None and pspec.type == "marker":
                    s.params[name] = v[1:]
                elif pspec is not None and pspec.type in ("pose", "position", "area"):
                    s.bindings[name] = v[1:]
                    del s.params[name]


def check_mission(m: Mission, lib: Library, *, fill: bool = True) -> list[tuple[Path, str]]:
    """Every rule a mission must satisfy against its library. With `fill`,
    parameters are normalized and defaults filled in place."""
    out: list[tuple[Path, str]] = []
    robots = set(m.robots)
    for name, spec in m.robots.items():
        if spec.type not in lib.robot_types:
            known = ", ".join(lib.robot_types) or "none"
            out.append(
                (
                    ("robots", name, "type"),
                    f"unknown robot type '{spec.type}' (library types: {known})",
                )
            )
    ids: dict[str, Path] = {}
    for robot, task in m.tasks.items():
        if robot not in m.robots:
            out.append(
                (
                    ("tasks", robot),
                    f"tasks for unknown robot '{robot}' (robots: {', '.join(sorted(robots)) or 'none'})",
                )
            )
            continue
        rtype = m.robots[robot].type
        for i, s in enumerate(task):
            here: Path = ("tasks", robot, i)
            if s.id in ids:
                out.append(
                    (
                        (*here, "id"),
                        f"duplicate skill id '{s.id}' (first used at {format_path(ids[s.id])})",
                    )
                )
            else:
                ids[s.id] = here
            if rtype not in lib.robot_types:
                continue
            if lib.skill_for(rtype, s.skill) is None:
                offered = ", ".join(lib.skills_of(rtype)) or "none"
                out.append(
                    (
                        (*here, "skill"),
                        f"robot '{robot}' ({rtype}) has no skill '{s.skill}' (it offers: {offered})",
                    )
                )
                continue
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
            for p in problems:
                base = (
                    "bindings"
                    if p.path and p.path[0] in s.bindings and p.path[0] not in s.params
                    else "params"
                )
                out.append(((*here, base, *p.path), p.message))
            if not problems and fill:
                s.params = params
        for i, why in section_problems(task):
            out.append((("tasks", robot, i, "status"), why))
    owner: dict[str, str] = {}
    for bid, b in m.barriers.items():
        robots_in: dict[str, str] = {}
        for j, sid in enumerate(b.skills):
            where: Path = ("barriers", bid, "skills", j)
            if sid in b.skills[:j]:
                out.append((where, f"skill '{sid}' is listed twice"))
                continue
            found = m.find(sid)
            if found is None:
                out.append((where, f"unknown skill id '{sid}'"))
                continue
            robot = found[0]
            if robot in robots_in:
                out.append(
                    (
                        where,
                        f"skills '{robots_in[robot]}' and '{sid}' both belong to robot '{robot}'; a barrier has one skill per robot",
                    )
                )
            robots_in[robot] = sid
            if sid in owner:
                out.append((where, f"skill '{sid}' is already in barrier '{owner[sid]}'"))
            owner[sid] = bid
        if len(robots_in) < 2 and len(b.skills) >= 2 and all(m.find(s) for s in b.skills):
            out.append((("barriers", bid), "a barrier needs skills of at least two robots"))
    return out


# -- loading ------------------------------------------------------------------
