"""The console's plan state and the timeline's cells, without a terminal."""

from __future__ import annotations

from datetime import UTC, datetime

from console_state import Builder, mars_mid_execution, mars_telemetry
from map_state import mars_snapshot, mirror_of
from plan_state import crossed, risky_mars, sim_status

from backend.core.model import Status, Waiver
from console.state import timeline as tl
from console.state.clock import MissionClock
from console.state.plan import CHECKS_EVERY_S, MAP_EVERY_S, PlanView

NOW = datetime(2026, 3, 14, 10, 42, 7, tzinfo=UTC).timestamp()
WALL = MissionClock(lambda: datetime.fromtimestamp(NOW, UTC))  # no sim: mission time is wall time


def refreshed(b: Builder, now: float = NOW, **kw) -> PlanView:
    p = PlanView()
    p.status = sim_status()
    assert p.refresh(b.mission, b.library, kw.get("telemetry", {}), now)
    return p


# -- PlanView ---------------------------------------------------------------------------


def test_the_plan_recomputes_only_what_changed():
    b = mars_mid_execution()
    tele = {t.robot: t for t in mars_telemetry()}
    p = refreshed(b, telemetry=tele)
    assert not p.refresh(b.mission, b.library, tele, NOW + 0.4)  # same second, same inputs
    assert p.refresh(b.mission, b.library, tele, NOW + 1)  # the clock moved: a new forecast
    checks = p.findings_generation
    b.engine.submit(_far_drive())  # an edit: checks run again at once
    assert p.refresh(b.mission, b.library, tele, NOW + 1.5)
    assert p.findings_generation > checks


def _far_drive():
    from backend.core.ops import AddSkill

    return AddSkill(robot="lru2", skill="drive_to", params={"goal": {"x": 300.0, "y": 0.0}})


def test_telemetry_alone_reruns_the_checks_at_most_every_few_seconds():
    b = mars_mid_execution()
    tele = {t.robot: t for t in mars_telemetry()}
    p = refreshed(b, telemetry=tele)
    seen = p._checked_at
    low = tele["lru1"].model_copy(update={"battery": 0.1})
    p.refresh(b.mission, b.library, {**tele, "lru1": low}, NOW + 1)
    assert p._checked_at == seen
    p.refresh(b.mission, b.library, {**tele, "lru1": low}, NOW + CHECKS_EVERY_S + 1)
    assert p._checked_at > seen


def test_a_map_update_counts_at_most_every_few_seconds():
    b = risky_mars()
    p = PlanView()
    p.mirror = mirror_of(mars_snapshot())
    p.refresh(b.mission, b.library, {}, NOW)
    first = p._map_key
    assert first is not None and any(f.rule.startswith("coverage") for f in p.findings)
    p.mirror.seq += 1  # a delta that changed the coverage...
    p.mirror.layers["coverage"][:] = 200
    p.refresh(b.mission, b.library, {}, NOW + 1)
    assert p._map_key == first  # ...waits for its turn
    p.refresh(b.mission, b.library, {}, NOW + MAP_EVERY_S + 1)
    assert p._map_key != first
    assert not any(f.rule.startswith("coverage") for f in p.findings)


def test_sync_is_blocked_by_unwaived_errors_naming_a_skill_it_would_send():
    b = crossed()
    p = refreshed(b)
    task = b.mission.tasks["lru1"]
    assert [f.id for f in p.blocking(task, "lru1-1")] == ["barrier.deadlock:b2+b3"]
    assert p.mark("lru1-1").severity == "error"
    b.mission.waivers["barrier.deadlock:b2+b3"] = Waiver(reason="ok")
    p.refresh(b.mission, b.library, {}, NOW, force=True)
    assert p.blocking(task, "lru1-1") == []
    assert p.mark("lru1-1").waiver is not None
    assert p.counts() == (0, 0, 1)


def test_no_mission_no_plan():
    p = PlanView()
    assert not p.refresh(None, None, {}, NOW)
    assert p.forecast is None and p.findings == []


# -- the timeline's cells -----------------------------------------------------------------


def bar(sid, a, b, status=Status.IDLE, ready=None, barrier=None, out=()):
    return tl.Bar(sid, a, b, status, f"○ {sid}", a if ready is None else ready, barrier, out)


def test_a_lane_draws_bars_hatching_the_delay_band_and_now():
    win = tl.Window(0.0, 10.0, 20)  # 10 s per cell, 200 s
    cells = tl.lane(
        [
            bar("a", 0, 20, Status.RUNNING),
            bar("b", 80, 150, barrier="b1", out=((120.0, 150.0),)),
        ],
        win,
        now=30,
        reach=70,
        selected="b",
    )
    text = "".join(c for c, _ in cells)
    assert text.startswith("○ ") and cells[0][1] == ("running",)
    assert cells[3] == ("│", ("now",))
    assert cells[4:7] == [("·", ("delay",))] * 3
    assert text[8:12] == "○ b " and cells[8][1] == ("cursor",)  # selected: the cursor's look
    assert cells[12] == ("╱", ("cursor", "hatch"))  # out of coverage from 120 s
    assert text[15:] == " " * 5


def test_a_barrier_wait_is_dotted_and_partners_are_linked():
    win = tl.Window(0.0, 10.0, 30)
    lanes = {
        "r1": [bar("r1-1", 100, 150, ready=20, barrier="b1")],
        "r2": [],
        "r3": [bar("r3-1", 100, 200, barrier="b1")],
    }
    cells = tl.lane(lanes["r1"], win, now=0, reach=0)
    assert [c for c, _ in cells[2:10]] == ["┄"] * 8
    links = tl.links(lanes, ["r1", "r2", "r3"], win)
    assert links == {0: {10}, 1: {10}}  # the spacers below r1 and r2
    assert tl.spacer(links[0], 30)[10] == ("┆", ("link",))


def test_the_axis_labels_ticks_that_fit_and_marks_now():
    win = tl.Window(NOW, 15.0, 60)
    labels, marks = tl.axis(win, NOW + 150, WALL)
    text = "".join(c for c, _ in labels)
    assert "10:45" in text and "10:50" in text
    assert marks[10] == ("▼", ("now",))


def test_with_a_sim_the_axis_reads_sim_time():
    clock = MissionClock(lambda: datetime.fromtimestamp(NOW, UTC))
    clock.heard(sim_time=1500.0, speed=10.0)  # sim 0:25:00 now, 10 sim seconds per wall second
    win = tl.Window(1500.0, 15.0, 60)  # mission time: 15 sim seconds per column
    labels, marks = tl.axis(win, clock.now(), clock)
    text = "".join(c for c, _ in labels)
    assert "25:00" in text and "30:00" in text and "10:4" not in text, text
    assert marks[0] == ("▼", ("now",))


def test_fit_zoom_and_scroll():
    win = tl.fit(NOW, NOW + 3600, 60)
    assert win.dt == 120 and win.t0 < NOW and win.t1 > NOW + 3600
    closer = win.zoomed(-1, NOW + 600)
    assert closer.dt == 60 and abs(closer.col(NOW + 600) - win.col(NOW + 600)) <= 1
    assert tl.Window(0, 10, 10).showing(500, 520).t0 == 500 - 25
    assert tl.fmt_step(15) == "15 s" and tl.fmt_step(120) == "2 min"


def test_bars_take_the_log_at_its_times_and_the_rest_from_the_forecast():
    b = mars_mid_execution()
    p = refreshed(b, telemetry={t.robot: t for t in mars_telemetry()})
    fc = p.forecast
    shown = tl.bars(b.mission, fc, "lru1", WALL, NOW - 60, NOW + 3600)
    assert [x.id for x in shown][:3] == ["lru1-1", "lru1-2", "lru1-3"]
    assert shown[0].status == Status.SUCCESS
    assert "waits" not in tl.details(b.mission, fc, "lru1-3", WALL)
    assert "waits" in tl.details(b.mission, fc, "lru2-3", WALL)
    assert tl.nearest(b.mission, fc, b.mission.tasks["lru2"], shown[2].start, WALL) == "lru2-3"


def test_at_a_sims_speed_bars_and_spans_are_in_sim_time():
    b = mars_mid_execution()
    fc = refreshed(b, telemetry={t.robot: t for t in mars_telemetry()}).forecast
    sim = MissionClock(lambda: datetime.fromtimestamp(NOW, UTC))
    sim.heard(sim_time=0.0, speed=10.0)
    wall = tl.bars(b.mission, fc, "lru2", WALL, NOW - 60, NOW + 3600)
    fast = tl.bars(b.mission, fc, "lru2", sim, -600, 36000)
    assert [x.id for x in fast] == [x.id for x in wall]
    for w, s in zip(wall, fast, strict=True):  # ten times as long, counted from sim 0:00:00
        assert abs((s.end - s.start) - 10 * (w.end - w.start)) < 1e-6
        assert abs(s.start - 10 * (w.start - NOW)) < 1e-6
    said = tl.details(b.mission, fc, "lru2-3", sim)
    assert "sim " in said and "10:4" not in said, said
