"""Input typed or configured in the console is read within the file limits
(backend.core.limits): an alias bomb is refused, never expanded."""

from __future__ import annotations

from console_state import DATA, Builder, inject, make_app, wait_until

from console.config import load_config

BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{n}: &{n} [{', '.join(['*' + p] * 9)}]\n"
    for p, n in zip("abcdefghi", "bcdefghij", strict=True)
)  # 9^10 leaves: 3.5 billion strings if expanded


async def test_an_alias_bomb_in_a_yaml_parameter_is_refused_with_its_line():
    b = Builder(DATA / "every_type.yaml")
    app = make_app()
    async with app.run_test(size=(130, 60)) as pilot:
        await inject(app, pilot, b, online={"rover1": True, "rover2": True})
        app.mission_screen.schedule.select("rover1-1")
        editor = app.mission_screen.editor
        await wait_until(pilot, lambda: editor.skill_id == "rover1-1")
        await pilot.pause()
        editor.query_one("#f-camera").text = BOMB
        _label, params, _bindings, problems = editor.collect()
        assert "camera" not in params
        assert problems["camera"].startswith("not valid YAML (line "), problems
        assert "limit" in problems["camera"], problems


def test_an_alias_bomb_in_the_config_is_a_problem_not_a_hang(tmp_path):
    p = tmp_path / "config.yaml"
    p.write_text("keymap:\n  mission.add: A\n" + BOMB)
    cfg = load_config(p)
    assert cfg.keymap == {}  # defaults
    assert cfg.problems and "config.yaml:" in cfg.problems[0] and "limit" in cfg.problems[0]
