"""What the server says about a robot that asks to join the mission
(issue 30): its manifest checked against the library, in one sentence."""

from __future__ import annotations

from backend.core.library import Library
from backend.core.rules.team import unknown_type
from backend.core.rules.uplink import incompatible
from backend.protocol.messages import Manifest

__all__ = ["announcement", "unknown_type"]


def announcement(library: Library, m: Manifest) -> str:
    """'robot lru3 (lru_science) asks to join...', with what its manifest
    lacks or offers at another major version than the library's."""
    problems = [
        why
        for skill in library.skills_of(m.type)
        if skill in library.skills
        and (why := incompatible(m.skills, skill, library.skills[skill].version)) is not None
    ]
    said = f"robot {m.name} ({m.type}) asks to join the mission: add it with "
    said += f"`missionctl ctl robots add {m.name}` or from the fleet screen"
    if problems:
        said += f"; it {'; it '.join(problems)} (those skills cannot go to it)"
    return said
