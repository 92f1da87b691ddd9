"""Console states for the plan's timeline and checks: the Mars mission mid-way
with telemetry, the map feed and a link delay; a crossed-barrier plan."""

from __future__ import annotations

from typing import Any

from console_state import (
    Builder,
    engine_app,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    pin_clock,
)
from map_state import map_message

from backend.core.ops import AddBarrier, AddSkill
from backend.protocol.mapfeed import SimStatus

ONLINE = {"lru1": True, "lru2": True, "ardea": True, "lander": True}


def sim_status(delay: float = 90.0) -> SimStatus:
    return SimStatus(world="test", seed=1, speed=1.0, link_delay_s=delay, sim_time=0, score=0)


async def show_plan(app: Any, pilot: Any, builder: Builder, *, telemetry=None, site=True) -> None:
    """Inject the state (and the map, the sim's status), refresh the plan at once."""
    pin_clock(app)
    app.model.plan.status = sim_status()
    await inject(app, pilot, builder, online=ONLINE, telemetry=telemetry)
    if site:
        app.post_message(map_message())
    await pilot.pause()
    app.refresh_plan(force=True)
    await pilot.pause()


def risky_mars() -> Builder:
    """The mid-execution Mars mission plus a plan with findings: ardea explores
    far too long (its battery empties), lru2 ends out of coverage."""
    b = mars_mid_execution()
    e = b.engine
    big = [{"x": x, "y": y} for x, y in ((-150, 20), (150, 20), (150, 160), (-150, 160))]
    e.submit(AddSkill(robot="ardea", skill="takeoff", label="off again"))
    e.submit(
        AddSkill(
            robot="ardea",
            skill="explore",
            label="survey the north",
            params={"area": big, "max_duration": 900},
        )
    )
    e.submit(
        AddSkill(
            robot="lru2",
            skill="drive_to",
            label="far east",
            params={"goal": {"x": 120.0, "y": -40.0}},
        )
    )
    return b


def crossed() -> Builder:
    """The Mars mission with a deadlock: lru1-5 + ardea-1 (b2), lru1-1 + ardea-4 (b3)."""
    b = Builder()
    b.engine.submit(AddBarrier(ids=["lru1-5", "ardea-1"]))
    b.engine.submit(AddBarrier(ids=["lru1-1", "ardea-4"]))
    return b


def plan_app(builder: Builder | None = None):
    """An app whose operations go to the builder's engine."""
    if builder is None:
        return make_app(), None
    return engine_app(builder)


__all__ = ["mars_telemetry", "plan_app", "risky_mars", "crossed", "show_plan", "sim_status"]
