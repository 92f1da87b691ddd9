"""`ctl state --nowcast`: each robot's probable present, live (trivial robots)."""

from __future__ import annotations

import pytest

from .helpers import Robots, Server, ok, ok_json, until


@pytest.fixture
def endpoint(tmp_path):
    s = Server(tmp_path)
    robots = None
    try:
        robots = Robots(s.endpoint, "lru1:lru_science", "lru2:lru_manipulator")
        until(
            s.endpoint,
            lambda st: all(x["online"] for x in st["robots"].values()),
            what="robots online",
        )
        yield s.endpoint
    finally:
        if robots is not None:
            robots.stop()
        s.stop()


def test_state_nowcast_predicts_each_robots_present_from_its_last_report(endpoint):
    st = ok_json(endpoint, "state", "--nowcast")
    assert set(st["nowcast"]) == {"lru1", "lru2"}
    lru1 = st["nowcast"]["lru1"]
    assert lru1 is not None, st["nowcast"]
    assert lru1["age_s"] >= 0 and lru1["basis"] <= lru1["at"]
    assert lru1["held"] == "queue end" and lru1["skill"] is None  # nothing synchronized
    assert 0.0 <= lru1["battery"] <= 1.0
    assert "tasks" in st  # the state itself is all there
    text = ok(endpoint, "state", "lru1", "--nowcast").stdout
    assert "≈ lru1 now: no skill, waiting (queue end)" in text and "old)" in text, text
