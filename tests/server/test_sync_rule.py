"""Which skills a sync carries is decided by the rule (backend.core.rules.uplink):
the check of a sync against the robot's manifest (what the robot link says it
offers) judges the skills the rule chose, so the two cannot name different
skills. In process: the robot link, an engine, no Zenoh."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from backend.core.ops import Sync
from backend.core.rules.engine import Applied, Engine, Refusal
from backend.files.missions import load_mission
from backend.protocol.messages import Manifest, RobotInfo
from backend.server.robots import RobotLink

ROOT = Path(__file__).resolve().parents[2]


class Server:
    """The little a robot link asks of its server here."""

    def __init__(self) -> None:
        self.engine: Engine | None = None
        self.alerts: list[str] = []

    def submit(self, op: Any, *, client: str = "", request_id: Any = None, actor: str = "") -> Any:
        assert self.engine is not None
        return self.engine.submit(op, client=client, request_id=request_id, actor=actor)

    def alert(self, message: str, **_: Any) -> None:
        self.alerts.append(message)

    def publish_fleet(self, info: RobotInfo) -> None:
        pass


@pytest.fixture
def link() -> RobotLink:
    mission, library = load_mission(ROOT / "missions" / "tutorial.yaml")
    server = Server()
    link = RobotLink(server)
    server.engine = Engine(mission, library, offers=link)  # as MissionServer builds it
    return link


def offers(link: RobotLink, robot: str, **skills: str) -> None:
    """The robot registered once, with a manifest offering `skills` (name -> version)."""
    rtype = link.engine.mission.robots[robot].type
    manifest = Manifest(name=robot, type=rtype, skills=skills)
    link.robots[robot] = RobotInfo(name=robot, online=True, manifest=manifest)


def submit(link: RobotLink, op: Sync) -> Applied:
    return link.engine.submit(op)


def test_a_sync_is_checked_for_the_skills_it_sends_not_those_sent_already(link):
    # lru1-1 (drive_to) leaves with a first sync before lru1 ever registered
    first = submit(link, Sync(robot="lru1", through="lru1-1"))
    assert first.value["skills"] == ["lru1-1"]
    # then lru1 registers offering take_science_image only: the next sync
    # sends lru1-2 alone (lru1-1 is on its way already), which it offers
    offers(link, "lru1", take_science_image="1.0.0")
    second = submit(link, Sync(robot="lru1"))
    assert second.value["skills"] == ["lru1-2"]


def test_a_sync_of_a_skill_the_robot_does_not_offer_is_refused_naming_it(link):
    offers(link, "lru1", drive_to="1.0.0")
    with pytest.raises(Refusal) as refused:
        submit(link, Sync(robot="lru1"))
    assert refused.value.code == "incompatible" and refused.value.skill == "lru1-2"
    assert link.engine.mission.pending_commands() == []
