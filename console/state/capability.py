"""What robots can do, from their manifests — no Textual here.

One matching rule serves the fleet screen's filter and the skill picker's
"also offered by": a robot offers a skill when its manifest lists it; a robot
that never registered (no manifest) is judged by its mission type's skills in
the library, which is what the server would check too.

Filter syntax: words separated by spaces, all must match (AND). A bare word
matches a skill, the type, a module, a property name or the robot's name
(substring, case-insensitive); `skill:`, `type:`, `module:`, `prop:` and
`name:` restrict a word to one of them, e.g. `pick_stone type:lru`.
"""

from __future__ import annotations

from datetime import datetime

from backend.core.model import SkillInstance, Status
from console.state.model import ConsoleModel
from console.state.team import retired
from console.state.text import GLYPHS, STATUS_WORDS

FIELDS = ("skill", "type", "module", "prop", "name")
SPARKS = "▁▂▃▄▅▆▇█"


def offered_skills(model: ConsoleModel, robot: str) -> dict[str, str]:
    """skill -> version ('' when only the library says so)."""
    info = model.robots.get(robot)
    if info is not None and info.manifest is not None:
        return dict(info.manifest.skills)
    return dict.fromkeys(model.skills_of(robot), "")


def robot_type(model: ConsoleModel, robot: str) -> str:
    info = model.robots.get(robot)
    if info is not None and info.manifest is not None:
        return info.manifest.type
    spec = model.mission.robots.get(robot) if model.mission else None
    return spec.type if spec else ""


def _facets(model: ConsoleModel, robot: str) -> dict[str, list[str]]:
    info = model.robots.get(robot)
    man = info.manifest if info else None
    return {
        "skill": list(offered_skills(model, robot)),
        "type": [robot_type(model, robot)],
        "module": [m.name for m in man.modules] if man else [],
        "prop": [f"{k}={v}" for k, v in man.properties.items()] if man else [],
        "name": [robot],
    }


def matches(model: ConsoleModel, robot: str, query: str) -> bool:
    """Every word of `query` is in one of the robot's facets (`field:value`: in that one)."""
    facets = _facets(model, robot)
    return all(_word_matches(facets, word) for word in query.lower().split())


def _word_matches(facets: dict[str, list[str]], word: str) -> bool:
    field, sep, value = word.partition(":")
    if sep and field in FIELDS:
        pools = facets[field]
    else:
        value, pools = word, [x for vals in facets.values() for x in vals]
    return any(value in x.lower() for x in pools)


def filter_examples(model: ConsoleModel) -> str:
    """Filter examples that match robots of this fleet (and not all of them,
    where possible): what the filter's placeholder shows."""
    robots = fleet_order(model)
    facets = [_facets(model, r) for r in robots]

    def pick(field: str) -> str | None:
        values = [v for f in facets for v in f[field]]
        telling = [v for v in values if sum(v in f[field] for f in facets) < len(facets)]
        first = telling or values
        return first[0] if first else None

    examples = []
    for field, prefix in (
        ("skill", ""),
        ("type", "type:"),
        ("module", "module:"),
        ("prop", "prop:"),
    ):
        value = pick(field)
        if value:
            examples.append(prefix + value)
    return " · ".join(examples) if examples else "skill · type:… · module:… · prop:…"


def filter_robots(model: ConsoleModel, query: str) -> list[str]:
    return [r for r in fleet_order(model) if matches(model, r, query)]


def fleet_order(model: ConsoleModel) -> list[str]:
    """The mission's robots (dynamic first), then any other robot the server knows."""
    order = model.robot_order()
    return order + sorted(r for r in model.robots if r not in order)


def robots_offering(model: ConsoleModel, skill: str) -> list[str]:
    return [r for r in fleet_order(model) if skill in offered_skills(model, r)]


def also_offered_by(model: ConsoleModel, skill: str, robot: str) -> str:
    """For the skill picker: 'also offered by: lru2' / 'only lru1 offers it'
    (a retired robot offers nothing: it gets no new syncs)."""
    others = [r for r in robots_offering(model, skill) if r != robot and not retired(model, r)]
    return f"also offered by: {', '.join(others)}" if others else f"only {robot} offers it"


# -- what the fleet screen shows per robot ------------------------------------------


def sparkline(values: list[float], width: int) -> str:
    """The last `width` values (0..1) as block characters, padded left."""
    vals = values[-width:]
    line = "".join(SPARKS[min(len(SPARKS) - 1, max(0, int(v * len(SPARKS))))] for v in vals)
    return line.rjust(width)


def last_report(model: ConsoleModel, robot: str) -> str:
    """The robot's last status change: the skill that started or finished last."""
    reported = [(t, s) for s in model.task(robot) if (t := _reported_at(s)) is not None]
    if not reported:
        return "no report yet"
    t, s = max(reversed(reported), key=lambda x: x[0])  # of equal times, the lowest row
    return f"{GLYPHS[s.status]} {s.id} {STATUS_WORDS[s.status]} {model.clock.stamp_text(t)}"


def _reported_at(s: SkillInstance) -> datetime | None:
    """When the robot last said something of the skill (started, finished)."""
    if s.status in (Status.IDLE, Status.IDLE_SYNCHRONIZED):
        return None
    return s.finished_at or s.started_at
