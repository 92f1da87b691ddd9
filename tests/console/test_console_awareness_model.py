"""Fleet capabilities, telemetry history, the event log, alerts, theme files
and the config file's theme — the parts without a terminal."""

from __future__ import annotations

from datetime import timedelta

from console_state import MARS, T0, Builder, mars_fleet_with_manifests

from backend.core.ops import Sync, SyncAck
from backend.protocol.messages import Alert, Telemetry
from console.config import load_config, save_theme
from console.state.capability import also_offered_by, filter_robots, robots_offering, sparkline
from console.state.eventlog import AlertBook, EventLog, read_jsonl, split_actor
from console.state.model import HISTORY, ConsoleModel
from console.themes.loader import SHIPPED_DIR, load_theme_file, load_themes
from console.themes.variables import STATUS_DEFAULTS


def mars_model() -> ConsoleModel:
    b = Builder(MARS)
    m = ConsoleModel()
    m.load(b.snapshot(), b.library, mars_fleet_with_manifests())
    return m


# -- capabilities --------------------------------------------------------------------


def test_filter_by_capability_type_module_property_and_combined():
    m = mars_model()
    assert filter_robots(m, "pick_stone") == ["lru2"]
    assert filter_robots(m, "skill:explore") == ["lru1", "lru2", "ardea"]
    assert filter_robots(m, "type:lru") == ["lru1", "lru2"]
    assert filter_robots(m, "module:arm") == ["lru2"]
    assert filter_robots(m, "prop:payload") == ["lru2"]
    assert filter_robots(m, "explore type:drone") == ["ardea"]  # words AND
    assert filter_robots(m, "") == ["lru1", "lru2", "ardea", "lander"]
    assert filter_robots(m, "teleport") == []


def test_a_manifest_decides_over_the_library():
    m = mars_model()
    info = m.robots["lru1"]
    # lru1 registered with a manifest without take_science_image (its camera module is missing)
    skills = {k: v for k, v in info.manifest.skills.items() if k != "take_science_image"}
    m.set_robot(
        info.model_copy(update={"manifest": info.manifest.model_copy(update={"skills": skills})})
    )
    assert robots_offering(m, "take_science_image") == []
    # ardea never registered: the library's drone type says what it can do
    assert robots_offering(m, "fly_to") == ["ardea"]


def test_picker_says_who_else_offers_a_skill():
    m = mars_model()
    assert also_offered_by(m, "identify_stone", "lru1") == "also offered by: lru2"
    assert also_offered_by(m, "recharge", "lru1") == "also offered by: lru2, ardea"
    assert also_offered_by(m, "pick_stone", "lru2") == "only lru2 offers it"


def test_sparkline_scales_and_pads():
    assert sparkline([0.0, 0.5, 1.0], 3) == "▁▅█"
    assert sparkline([1.0], 4) == "   █"
    assert sparkline([0.1] * 20, 5) == "▁▁▁▁▁"


def test_telemetry_history_is_bounded_per_robot():
    m = ConsoleModel()
    for i in range(HISTORY + 30):
        m.set_telemetry(Telemetry(robot="lru1", battery=(i % 100) / 100, link=1.0, at=T0))
    assert len(m.history["lru1"]) == HISTORY
    assert m.history["lru1"][-1] == (((HISTORY + 29) % 100) / 100, 1.0)


# -- the event log ---------------------------------------------------------------------------


def test_actor_names_user_and_client():
    assert split_actor("ada@host-1-abc") == ("ada", "host-1-abc")
    assert split_actor("ada@example.org@host-1-abc") == ("ada@example.org", "host-1-abc")
    assert split_actor("host-1-abc") == ("", "host-1-abc")
    assert split_actor("lru1") == ("", "lru1")


def test_log_turns_batches_into_operations_and_reports():
    b = Builder(MARS)
    m = ConsoleModel()
    m.load(b.snapshot(), b.library)
    log = EventLog()
    ids = [s.id for s in b.engine.plan_sync(Sync(robot="lru1", through="lru1-1"))]
    applied = b.engine.submit(SyncAck(robot="lru1", ids=ids))
    b.engine.release("lru1", ids)
    batch = applied.batch("ada@host-1-abc", "sync_ack")
    m.apply(batch)
    (op,) = log.add_batch(batch, m.owner, T0)
    assert (op.kind, op.user, op.client, op.robots, op.revision) == (
        "operation",
        "ada",
        "host-1-abc",
        ["lru1"],
        batch.revision,
    )
    assert "lru1-1 idle_synchronized" in op.text
    b.report("lru1", "lru1-1", "running")
    b.report("lru1", "lru1-1", "failure", "wheel stuck")
    # the two reports as the server would publish them
    from backend.core import events as ev

    fail = ev.EventBatch(
        revision=m.mission.revision + 1,
        events=[ev.SkillStatusChanged(id="lru1-1", status="failure", info="wheel stuck")],
        actor="lru1",
        op="report",
    )
    m.apply(fail)
    (rep,) = log.add_batch(fail, m.owner, T0)
    assert (rep.kind, rep.robots, rep.skill, rep.client) == ("failure", ["lru1"], "lru1-1", "lru1")
    assert rep.text == "✗ lru1-1 failure: wheel stuck"
    assert [e.seq for e in log.select("kind:fail")] == [rep.seq]
    assert [e.seq for e in log.select("robot:lru1 ada")] == [op.seq]
    assert log.select("robot:lru2") == []


def test_log_is_bounded_and_exports_json_lines(tmp_path):
    log = EventLog(limit=5)
    for i in range(8):
        log.add("refusal", f"refused {i}", T0 + timedelta(seconds=i), robots=["lru1"])
    assert [e.seq for e in log.entries] == [4, 5, 6, 7, 8]
    path = tmp_path / "log.jsonl"
    assert log.export(path) == 5
    back = read_jsonl(path)
    assert back == list(log.entries)
    assert len(path.read_text().splitlines()) == 5


# -- alerts --------------------------------------------------------------------------------------


def test_server_alerts_are_taken_once_per_run_and_acknowledged():
    """Only the server raises alerts about robots; a console takes each once
    (live, or again in a state snapshot), per server run."""
    book = AlertBook()
    failure = Alert(
        id=1,
        level="error",
        kind="failure",
        robot="lru1",
        skill="lru1-1",
        message="lru1: lru1-1 failed: wheel stuck",
        at=T0,
    )
    mine = book.from_server(failure, "run-a")
    assert mine is not None and (mine.kind, mine.source, mine.level) == (
        "failure",
        "server",
        "error",
    )
    assert book.from_server(failure, "run-a") is None  # the snapshot repeats it: taken already
    # another server run numbers from 1 again: a new alert
    assert book.from_server(failure.model_copy(update={"at": T0}), "run-b") is not None
    # alerts from before the console first looked are not news
    old = Alert(id=2, kind="offline", robot="lru2", message="robot lru2 went offline", at=T0)
    book.seen([old], "run-b")
    assert book.from_server(old, "run-b") is None
    other = Alert(id=9, kind="robot_error", robot="lru1", message="something else", at=T0)
    assert book.from_server(other, "run-a").kind == "robot_error"
    assert book.unacknowledged == 3
    assert book.acknowledge(mine.id) == 1 and book.unacknowledged == 2
    assert book.acknowledge(None) == 2 and book.unacknowledged == 0


def test_repeated_refusal_counts_instead_of_piling_up():
    book = AlertBook()
    assert book.add("refusal", "Run refused: busy", T0, robot="lru1") is not None
    assert book.add("refusal", "Run refused: busy", T0 + timedelta(seconds=5), robot="lru1") is None
    assert book.alerts[0].count == 2
    assert (
        book.add("refusal", "Run refused: busy", T0 + timedelta(minutes=5), robot="lru1")
        is not None
    )


# -- themes ----------------------------------------------------------------------------------------


def test_shipped_themes_load_and_set_every_status_colour():
    themes, problems = load_themes([SHIPPED_DIR])
    assert problems == []
    assert {
        "missionctl-dark",
        "missionctl-light",
        "missionctl-high-contrast",
        "missionctl-colorblind",
    } <= set(themes)
    for t in themes.values():
        assert set(STATUS_DEFAULTS) <= set(t.variables), t.name
    assert themes["missionctl-light"].dark is False


def test_broken_theme_files_are_skipped_with_file_and_line(tmp_path):
    good = (SHIPPED_DIR / "dark.yaml").read_text().replace("missionctl-dark", "mine")
    (tmp_path / "mine.yaml").write_text(good)
    (tmp_path / "bad-colour.yaml").write_text(
        good.replace("name: mine", "name: bad").replace(
            'status-failure: "#ff5f5f"', 'status-failure: "reddish"'
        )
    )
    (tmp_path / "missing.yaml").write_text(
        good.replace("name: mine", "name: missing").replace('  status-running: "#5fd7ff"\n', "")
    )
    (tmp_path / "syntax.yaml").write_text("name: x\nprimary: [unclosed\n")
    themes, problems = load_themes([tmp_path])
    assert set(themes) == {"mine"}
    text = "\n".join(problems)
    assert f"{tmp_path / 'bad-colour.yaml'}:" in text and "'reddish' is not a colour" in text
    assert "status-running" in text and "missing.yaml:" in text
    syntax = next(p for p in problems if "syntax.yaml" in p)
    assert syntax.startswith(f"{tmp_path / 'syntax.yaml'}:") and "theme skipped" in syntax
    # the line of the bad value
    bad_line = next(
        i
        for i, line in enumerate((tmp_path / "bad-colour.yaml").read_text().splitlines(), 1)
        if "reddish" in line
    )
    assert any(f"bad-colour.yaml:{bad_line}:" in p for p in problems)


def test_a_theme_file_that_is_not_a_mapping(tmp_path):
    p = tmp_path / "list.yaml"
    p.write_text("- a\n- b\n")
    theme, problems = load_theme_file(p)
    assert theme is None and problems == [
        f"{p}:1: expected a mapping (name, dark, primary, …, variables); theme skipped"
    ]


def test_theme_saved_in_toml_and_yaml_config_keeping_the_rest(tmp_path):
    toml = tmp_path / "config.toml"
    toml.write_text('theme = "missionctl-dark"\n\n[keymap]\n"mission.sync" = "S"\n')
    assert save_theme(toml, "missionctl-light") is None
    cfg = load_config(toml)
    assert (cfg.theme, cfg.keymap, cfg.problems) == ("missionctl-light", {"mission.sync": "S"}, [])
    fresh = tmp_path / "new" / "config.toml"
    assert save_theme(fresh, "missionctl-colorblind") is None
    assert load_config(fresh).theme == "missionctl-colorblind"
    yml = tmp_path / "config.yaml"
    yml.write_text("keymap:\n  mission.sync: S\n")
    assert save_theme(yml, "missionctl-high-contrast") is None
    cfg = load_config(yml)
    assert (cfg.theme, cfg.keymap) == ("missionctl-high-contrast", {"mission.sync": "S"})


def test_picker_says_no_retired_robot_offers_a_skill():
    """Seen in the demo: the picker said lru1 offers identify_stone after lru1 was retired."""
    m = mars_model()
    m.mission.robots["lru2"] = m.mission.robots["lru2"].model_copy(update={"retired": "broken"})
    assert also_offered_by(m, "identify_stone", "lru1") == "only lru1 offers it"
    assert also_offered_by(m, "recharge", "lru1") == "also offered by: ardea"
