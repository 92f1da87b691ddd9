"""What the fleet says a robot is doing, word for word: from its active
skill (with the progress its telemetry reports) or its mode and queue."""

from __future__ import annotations

from console_state import MARS_FLEET, T0, fleet, mars_mid_execution

from backend.protocol.messages import Telemetry
from console.state.model import ConsoleModel


def _model() -> ConsoleModel:
    b = mars_mid_execution()
    m = ConsoleModel()
    m.load(b.snapshot(), b.library, fleet(MARS_FLEET))
    return m


def _heard(m: ConsoleModel, robot: str, **fields: object) -> str:
    m.set_telemetry(Telemetry(robot=robot, at=T0, **fields))  # type: ignore[arg-type]
    return m.activity_text(robot)


def test_a_running_skill_shows_the_progress_its_telemetry_reports():
    m = _model()
    assert m.activity_text("lru1") == "▶ lru1-2 running"
    assert _heard(m, "lru1", skill="lru1-2", progress=0.42) == "▶ lru1-2 running 42%"
    assert _heard(m, "lru1", skill="lru1-9", progress=0.42) == "▶ lru1-2 running"
    assert _heard(m, "lru1", skill="lru1-2") == "▶ lru1-2 running"
    assert _heard(m, "ardea", skill="ardea-3", progress=0.5) == "‖ ardea-3 paused"


def test_a_robot_without_an_active_skill_says_its_mode_and_queue():
    m = _model()
    assert m.activity_text("lander") == "idle"
    assert _heard(m, "lander", mode="charging") == "charging"
    assert _heard(m, "lander", mode="") == "idle"
    m._robot_state["lander"] = (None, 2)
    assert m.activity_text("lander") == "halted · 2 queued"
    assert _heard(m, "lander", mode="idle") == "halted · 2 queued"
    assert _heard(m, "lander", mode="drilling") == "drilling · 2 queued"
