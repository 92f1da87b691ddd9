"""Saving and loading files from the console: the path prompt shows the full
path, completes, remembers recent files and asks before replacing a file or
writing into the shipped examples' folder (console/state/files.py and the
prompt); quitting asks while something is under way."""

from __future__ import annotations

from pathlib import Path

from console_state import (
    MARS,
    TUTORIAL,
    Builder,
    engine_app,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    wait_exit,
    wait_until,
)

from console.config import ConsoleConfig
from console.screens.dialogs import ChoiceScreen, ConfirmScreen, PathPrompt, QuitScreen
from console.state.files import (
    SHIPPED_MISSIONS,
    RecentFiles,
    complete,
    completions,
    default_save_path,
    path_note,
    save_risks,
)

WIDE = (120, 40)

# -- the rules (no terminal) -------------------------------------------------------------


def test_default_save_path_is_never_the_shipped_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    # started from missions/: the save goes to the home folder, not over the example
    p = default_save_path("Mars sample return", None, [], SHIPPED_MISSIONS)
    assert p == tmp_path / "mars_sample_return.yaml"
    # elsewhere: the working folder; after a save or load: that file; else a recent file's folder
    assert default_save_path("M", None, [], tmp_path / "work") == tmp_path / "work" / "m.yaml"
    assert default_save_path("M", "/data/x.yaml", [], tmp_path) == Path("/data/x.yaml")
    assert default_save_path("M", None, ["/data/y.yaml"], tmp_path) == Path("/data/m.yaml")


def test_save_risks_name_the_replaced_files_and_the_shipped_folder(tmp_path):
    new = tmp_path / "new.yaml"
    assert save_risks(new) == []
    old = tmp_path / "old.yaml"
    old.write_text("x: 1\n")
    lib = tmp_path / "old.library.yaml"
    lib.write_text("y: 2\n")
    risks = save_risks(old, [lib])
    assert len(risks) == 2 and all("exists and would be replaced" in r for r in risks)
    assert "5 bytes" in risks[0]
    shipped = save_risks(SHIPPED_MISSIONS / "mars_sample_return.yaml")
    assert any("exists" in r for r in shipped)
    assert any("shipped with missionctl" in r for r in shipped)
    assert any("shipped" in r for r in save_risks(SHIPPED_MISSIONS / "brand_new.yaml"))


def test_path_note_completion_and_recent_files(tmp_path):
    (tmp_path / "plans").mkdir()
    (tmp_path / "plan_a.yaml").write_text("")
    (tmp_path / "plan_b.yaml").write_text("")
    (tmp_path / "notes.txt").write_text("")
    note, severity = path_note("plan_a.yaml", must_exist=False, cwd=tmp_path)
    assert str(tmp_path / "plan_a.yaml") in note and "asked before it is replaced" in note
    assert severity == "warning"
    assert path_note("fresh.yaml", must_exist=False, cwd=tmp_path)[0].endswith("(new file)")
    assert "no such file" in path_note("fresh.yaml", must_exist=True, cwd=tmp_path)[0]
    assert "does not exist" in path_note("nowhere/x.yaml", must_exist=False, cwd=tmp_path)[0]
    found = completions("pla", tmp_path, (".yaml",))
    assert found == ["plan_a.yaml", "plan_b.yaml", "plans/"]
    assert complete("pla", tmp_path, (".yaml",)) == "plan"
    assert complete("plan_a", tmp_path) == "plan_a.yaml"
    assert completions("no", tmp_path, (".yaml",)) == []  # notes.txt is not YAML
    store = tmp_path / "state" / "recent.json"
    recent = RecentFiles(store, limit=2)
    for name in ("a", "b", "a", "c"):
        recent.add(f"/m/{name}.yaml")
    assert recent.files == ["/m/c.yaml", "/m/a.yaml"]
    assert RecentFiles(store).files == ["/m/c.yaml", "/m/a.yaml"]  # remembered
    store.write_text("{not json")
    assert RecentFiles(store).files == []  # a broken file is no error


# -- the prompt (run_test) ------------------------------------------------------------------


async def test_save_asks_before_replacing_a_file_then_remembers_it(tmp_path):
    target = tmp_path / "plan.yaml"
    target.write_text("precious: true\n")
    b = Builder(TUTORIAL)
    app, _ = engine_app(b)
    app.config = ConsoleConfig(recent_path=tmp_path / "recent.json")
    app.recent = RecentFiles(app.config.recent_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        await pilot.press("ctrl+s")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="path prompt")
        prompt = app.screen
        prompt.query_one("#path").value = str(target)
        await pilot.pause()
        assert "exists: you will be asked before it is replaced" in screen_text(app)
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="question")
        await pilot.pause()
        question = app.screen.question  # (a long temporary path wraps on screen)
        assert f"{target} (15 bytes" in question and "exists and would be replaced" in question
        assert "Write there anyway?" in screen_text(app)
        await pilot.press("enter")  # the question starts on Cancel: enter twice writes nothing
        await wait_until(pilot, lambda: app.screen is prompt, what="back at the prompt")
        assert target.read_text() == "precious: true\n"
        assert "nothing written" in screen_text(app)
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="again")
        await pilot.press("y")
        await wait_until(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="save as")
        await pilot.press("down", "enter")  # a plan: every skill idle
        await wait_until(pilot, lambda: "Tutorial" in target.read_text(), what="replaced")
        assert "status:" not in target.read_text()
        await wait_until(pilot, lambda: "saved plan.yaml" in app.mission_screen.message, what="ok")
        assert str(target) in app.recent.files
        assert RecentFiles(tmp_path / "recent.json").files[0] == str(target)
        # the next save starts there, and lists it among the recent files
        await pilot.press("ctrl+s")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="prompt again")
        await pilot.pause()
        assert app.screen.query_one("#path").value.endswith("plan.yaml")
        assert "recent files:" in screen_text(app)


async def test_started_from_the_shipped_folder_a_save_never_replaces_the_example(
    tmp_path, monkeypatch
):
    monkeypatch.chdir(SHIPPED_MISSIONS)
    monkeypatch.setenv("HOME", str(tmp_path))
    shipped = SHIPPED_MISSIONS / "mars_sample_return.yaml"
    before = shipped.read_bytes()
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b)
        await pilot.press("ctrl+s")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="path prompt")
        await pilot.pause()
        # ctrl+s + enter: the default is in the home folder, shown in full
        assert app.screen.query_one("#path").value == "~/mars_sample_return.yaml"
        assert "~/mars_sample_return.yaml (new file)" in screen_text(app)
        # typing the example's own name: asked, naming both reasons
        app.screen.query_one("#path").value = "mars_sample_return.yaml"
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="question")
        await pilot.pause()
        question = app.screen.question
        assert "mars_sample_return.yaml" in question and "exists and would be replaced" in question
        assert "shipped with missionctl" in question
        await pilot.press("n")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="back")
        await pilot.press("escape")
        await wait_until(pilot, lambda: "not saved" in app.mission_screen.message, what="said")
    assert shipped.read_bytes() == before


async def test_tab_completes_and_recent_files_are_chosen_with_the_arrow_keys(tmp_path):
    (tmp_path / "survey_north.yaml").write_text("")
    (tmp_path / "survey_south.yaml").write_text("")
    b = Builder(TUTORIAL)
    app, _ = engine_app(b)
    app.recent.add(str(TUTORIAL))
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        await pilot.press("ctrl+o")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="load prompt")
        await pilot.pause()
        assert "tutorial.yaml" in screen_text(app)  # a recent file, listed
        field = app.screen.query_one("#path")
        field.value = str(tmp_path / "surv")
        await pilot.press("tab")
        assert field.value == str(tmp_path / "survey_")
        await pilot.pause()
        text = screen_text(app)
        assert "survey_north.yaml" in text and "survey_south.yaml" in text
        await pilot.press("down", "down", "enter")  # the second completion: chosen and loaded
        await wait_until(
            pilot, lambda: "survey_south.yaml" in app.mission_screen.message, what="tried"
        )
        assert "cannot load survey_south.yaml" in app.mission_screen.message  # an empty file


# -- quitting ------------------------------------------------------------------------------


async def test_quit_asks_while_robots_execute_and_says_what_quitting_stops():
    app = make_app(quitting_stops="Quitting ends the demo: its robots stop.")
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, QuitScreen), what="question")
        await pilot.pause()
        text = screen_text(app)
        assert "lru1 is running (lru1-2)" in text
        assert "lru2 is waiting at barrier (lru2-3)" in text
        assert "Quitting ends the demo" in text
        assert "Save, then quit" not in text  # nothing edited since the state was loaded
        await pilot.press("enter")  # starts on Stay
        await wait_until(pilot, lambda: not isinstance(app.screen, QuitScreen), what="stayed")
        assert app.return_code is None
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, QuitScreen), what="again")
        await pilot.press("q")
        await wait_exit(app)


async def test_quit_with_yes_never_asks():
    app = make_app(ask_before_quit=False)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        await pilot.press("ctrl+q")
        await wait_exit(app)


async def test_quit_offers_to_save_an_edited_plan_first(tmp_path):
    b = Builder(TUTORIAL)
    app, _ = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        app.mission_screen.schedule.select("lru2-2")
        await pilot.pause()
        await pilot.press("d")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="delete?")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.model.unsaved, what="an unsaved edit")
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, QuitScreen), what="question")
        await pilot.pause()
        assert "the plan has changes not saved to a file" in screen_text(app)
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="save prompt")
        target = tmp_path / "kept.yaml"
        app.screen.query_one("#path").value = str(target)
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="save as")
        await pilot.press("enter")
        await wait_exit(app)
    assert "lru2-2" not in target.read_text() and "lru2-1" in target.read_text()
