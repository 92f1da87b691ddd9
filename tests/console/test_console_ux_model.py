"""The rules behind what an operator trips over at 80x24 (no terminal): the
context footer per selection, finding a skill, how fresh a robot's state
is, unsaved plans, labels naming markers, notification text, escape split
from the next key, fleet-filter examples."""

from __future__ import annotations

from datetime import timedelta

import pytest
from console_state import (
    MARS,
    MARS_FLEET,
    T0,
    Builder,
    fleet,
    mars_fleet_with_manifests,
    mars_mid_execution,
    mars_telemetry,
)
from textual import events

from backend.core.model import Run, UplinkCommand
from backend.core.ops import EditSkill
from backend.protocol.messages import Alert, RobotInfo
from console.escape import split_escape
from console.state.capability import filter_examples, filter_robots
from console.state.context import context_keys, fit_footer, tail_keys
from console.state.eventlog import AlertBook, toast_text
from console.state.freshness import SILENT_AFTER_S, EtaTicks
from console.state.keys import KeyNames, key_text
from console.state.markers import relabel
from console.state.model import CONNECTED, ConsoleModel
from console.state.search import search_skills
from console.state.text import without_paths


def model_of(b: Builder, online=MARS_FLEET, telemetry=(), at=T0) -> ConsoleModel:
    m = ConsoleModel(connection=CONNECTED)
    m.clock.wall = lambda: at
    m.load(b.snapshot(), b.library, fleet(online))
    for t in telemetry:
        m.set_telemetry(t)
    return m


def keys_for(m: ConsoleModel, skill: str | None, robot: str | None = None) -> list[str]:
    robot = robot or (m.owner(skill) if skill else None)
    return [k.action for k in context_keys(m, robot, skill, [])]


# -- the context footer --------------------------------------------------------------


def test_the_footer_puts_what_applies_to_the_selection_first():
    m = model_of(mars_mid_execution(), telemetry=mars_telemetry())
    # an idle skill: edit it, sync it, then the plan's keys
    assert keys_for(m, "lru1-4")[:3] == ["edit", "sync", "add"]
    # a running one: pause and stop first; nothing that cannot apply
    running = keys_for(m, "lru1-2")
    assert running[:2] == ["pause", "stop"] and "delete" not in running and "sync" not in running
    # queued: unsync (its robot runs already: no run)
    assert keys_for(m, "lru1-3")[0] == "unsync" and "run" not in keys_for(m, "lru1-3")
    # waiting at a barrier: stop
    assert keys_for(m, "lru2-3")[0] == "stop"
    # a failure on a robot still busy elsewhere: edit and retry, not the robot's retry
    failed = keys_for(m, "ardea-2")
    assert failed[0] == "retry_edit" and "retry" not in failed
    # no skill: add
    assert keys_for(m, None, "ardea")[0] == "add"


def test_a_halted_failure_offers_both_retries_and_run_first():
    b = Builder(MARS)
    b.sync("lru1", "lru1-2")
    b.report("lru1", "lru1-1", "running")
    b.report("lru1", "lru1-1", "failure", "wheel stuck")
    m = model_of(b)
    assert keys_for(m, "lru1-1")[:3] == ["retry", "retry_edit", "run"]


def test_the_footer_fits_80_columns_and_keeps_its_tail():
    m = model_of(mars_mid_execution(), telemetry=mars_telemetry())
    tail = tail_keys(KeyNames())
    shown = fit_footer(context_keys(m, "lru1", "lru1-4", []), 80, tail)
    text = " ".join(f"{k.key} {k.label}" for k in shown)
    assert len(text) <= 80
    assert shown[-len(tail) :] == tail  # find, save, all keys (the palette), quit
    assert text.startswith("⏎ Edit s Sync a Add") and text.endswith("^p All keys ^q Quit")
    assert [k.action for k in fit_footer(context_keys(m, "lru1", "lru1-4", []), 30, tail)] == [
        k.action for k in tail
    ]  # too narrow for more: the tail still says where the rest is


def test_key_text_is_the_shortest_way_to_show_a_key():
    assert key_text("enter,e") == "⏎"
    assert key_text("shift+up,K") == "K"
    assert key_text("ctrl+s") == "^s"
    assert key_text("space") == "␣"
    assert key_text("slash") == "/"


def test_a_remapped_key_shows_in_the_footer():
    m = model_of(mars_mid_execution(), telemetry=mars_telemetry())
    keys = context_keys(m, "lru1", "lru1-4", [], KeyNames({"mission.sync": "S"}))
    assert next(k.key for k in keys if k.action == "sync") == "S"


# -- finding a skill ---------------------------------------------------------------------


def test_search_matches_every_word_in_id_label_skill_robot_status_and_parameters():
    m = model_of(mars_mid_execution())
    assert search_skills(m, "lru2-4")[0].skill_id == "lru2-4"  # an exact id first
    # every word, anywhere: lru2's stone skills, and lru1's "identify stone with LRU2"
    assert {x.skill_id for x in search_skills(m, "stone lru2")} >= {"lru1-3", "lru2-3", "lru2-4"}
    assert all("stone" in x.text.lower() for x in search_skills(m, "stone lru2"))
    assert search_skills(m, "identify")[0].score > 0  # a label that starts so ranks first
    assert {x.skill_id for x in search_skills(m, "failure")} == {"ardea-2"}
    assert any(x.skill_id == "lru1-1" for x in search_skills(m, "POI-A"))  # a binding
    assert search_skills(m, "no such thing") == []
    everything = search_skills(m, "")
    assert len(everything) == sum(len(t) for t in m.mission.tasks.values())
    assert everything[0].text.startswith("✓ lru1-1  drive to POI-A (drive_to)  — lru1, success")


# -- how fresh a robot's state is ------------------------------------------------------


def test_an_offline_robot_is_its_last_known_state_as_of_when_it_was_heard():
    m = model_of(mars_mid_execution(), telemetry=mars_telemetry())
    assert not m.freshness("lru1").stale  # just heard
    m.set_robot(RobotInfo(name="lru1", online=False, since=T0 + timedelta(seconds=3)))
    m.clock.wall = lambda: T0 + timedelta(seconds=25)
    f = m.freshness("lru1")
    assert (f.stale, f.why, f.age_s) == (True, "offline", 25.0)
    assert f.as_of() == "as of 25s ago" and f.ago() == "25s ago"
    # never heard by this console: as of when it went offline
    assert m.freshness("ardea").as_of() == "as of 25s ago"


def test_a_robot_that_stops_sending_telemetry_turns_stale():
    m = model_of(mars_mid_execution(), telemetry=mars_telemetry())
    m.clock.wall = lambda: T0 + timedelta(seconds=SILENT_AFTER_S - 1)
    assert not m.freshness("lru2").stale
    m.clock.wall = lambda: T0 + timedelta(seconds=SILENT_AFTER_S + 5)
    f = m.freshness("lru2")
    assert (f.stale, f.why) == (True, "silent")
    # a robot that never sent telemetry is not expected to (presence says it is there)
    b = Builder(MARS)
    quiet = model_of(b, at=T0 + timedelta(minutes=5))
    assert not quiet.freshness("lru1").stale


def test_a_running_skills_eta_counts_down_between_samples():
    """Telemetry comes on change: lru1's ETA (132 s at T0) ticks each second."""
    m = model_of(mars_mid_execution(), telemetry=mars_telemetry())
    etas = EtaTicks()
    assert etas.ticked(m) == set()  # the first look: as drawn
    m.clock.wall = lambda: T0 + timedelta(seconds=0.4)
    assert etas.ticked(m) == set()  # the same second
    m.clock.wall = lambda: T0 + timedelta(seconds=2)
    assert etas.ticked(m) == {"lru1"}  # lru2 is at a barrier: no ETA
    assert etas.shown["lru1"] == 130


# -- unsaved plans -----------------------------------------------------------------------


def test_unsaved_means_the_plan_differs_from_what_was_saved_or_loaded():
    b = Builder(MARS)
    m = model_of(b)
    assert not m.unsaved and m.quit_risks() == []
    m.mission.tasks["lru1"][0].label = "changed"
    assert m.unsaved and "the plan has changes not saved to a file" in m.quit_risks()
    m.mark_saved()
    assert not m.unsaved
    # statuses are no plan change
    b2 = mars_mid_execution()
    m2 = model_of(b2)
    m2.mission.tasks["lru1"][1].status_info = "moving"
    assert not m2.unsaved
    assert m2.quit_risks()[0].startswith("lru1 is running (lru1-2); lru2 is waiting at barrier")
    m2.clock.wall = lambda: T0 + timedelta(minutes=2)
    m2.mission.uplink["lru1"] = [
        UplinkCommand(
            id=7, robot="lru1", seq=1, op="sync", command=Run(), skills=["lru1-4"], created=T0
        )
    ]
    assert "commands not yet acknowledged — lru1: sync #7 queued 2m00s ago" in m2.quit_risks()


# -- small things ----------------------------------------------------------------------------


def test_a_label_naming_the_old_marker_names_the_new_one():
    assert relabel("drive to POI-A", "POI-A", "POI-B") == "drive to POI-B"
    assert relabel("POI-A then back", "POI-A", "ROI-1") == "ROI-1 then back"
    assert relabel("drive to POI-AB", "POI-A", "POI-B") is None  # another name
    assert relabel("drive", "POI-A", "POI-B") is None
    assert relabel("drive to POI-A", None, "POI-B") is None


def test_notifications_carry_no_absolute_paths():
    text = 'sim stopped: File "/work/x/sim/fleet.py", line 3; log /tmp/demo-1/sim.log'
    assert without_paths(text) == 'sim stopped: File "…/fleet.py", line 3; log …/sim.log'
    kept = "tcp/127.0.0.1:7447 1/2 ~/missions/plan.yaml"
    assert without_paths(kept) == kept


def test_robots_going_offline_together_are_one_notification():
    book = AlertBook()
    for i, r in enumerate(("lru1", "lru2", "ardea")):
        at = T0 + timedelta(seconds=i)
        msg = f"robot {r} went offline"
        book.from_server(Alert(id=i + 1, kind="offline", robot=r, message=msg, at=at), "s")
    title, text = toast_text(book, book.alerts[-1])
    assert (title, text) == ("Robots offline", "lru1, lru2 and ardea went offline")
    failure = Alert(
        id=9,
        level="error",
        kind="failure",
        robot="lru1",
        skill="lru1-2",
        message="lru1: lru1-2 failure",
        at=T0,
    )
    book.from_server(failure, "s")
    assert toast_text(book, book.alerts[-1]) == ("lru1 · lru1-2", "lru1: lru1-2 failure")


@pytest.mark.parametrize(
    ("key", "char", "split"),
    [
        ("alt+d", "d", ("escape", "d")),
        ("alt+shift+k", "K", ("escape", "K")),
        ("d", "d", None),
        ("alt+up", None, None),
    ],
)
def test_alt_key_is_read_as_escape_then_the_key(key, char, split):
    got = split_escape(events.Key(key, char))
    assert (tuple(k.key for k in got) if got else None) == split


def test_fleet_filter_examples_match_robots_of_this_fleet():
    b = Builder(MARS)
    m = ConsoleModel()
    m.load(b.snapshot(), b.library, mars_fleet_with_manifests())
    examples = filter_examples(m).split(" · ")
    assert [e.partition(":")[0] for e in examples[1:]] == ["type", "module", "prop"]
    for example in examples:
        assert filter_robots(m, example), example  # each finds a robot...
        assert len(filter_robots(m, example)) < 4, example  # ...and tells them apart


def test_editing_a_label_is_a_plan_change_a_status_is_not():
    b = Builder(MARS)
    m = model_of(b)
    applied = b.engine.submit(EditSkill(id="lru1-1", label="go"))
    m.apply(applied.batch())
    assert m.unsaved
