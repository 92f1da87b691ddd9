"""The map's parameter chooser: when several parameters of the selected skill
fit the selected marker (b) or the cursor (p), a list asks which one; the
same operation as with a single fitting parameter follows. Operations go to a
rules engine (EngineBackend), whose events come back to the console."""

from __future__ import annotations

import math

from console_state import DATA, Builder, account_known, engine_app, inject, screen_text, wait_until
from map_state import map_message
from textual.widgets import OptionList

from backend.core.ops import EditSkill
from console.screens.dialogs import ChoiceScreen
from console.screens.map import MapScreen

TRANSPORT = DATA / "transport.yaml"  # lru1-2: transport(from @POI-B, to (2, 0), via, relay, speed)
SIZE = (120, 40)


async def open_map(app, pilot, b: Builder, skill: str) -> MapScreen:
    await inject(app, pilot, b, online={"lru1": True})
    app.post_message(map_message())
    app.mission_screen.schedule.select(skill)
    await pilot.press("f3")
    await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), 10, "map")
    return app.screen


async def chooser(app, pilot) -> OptionList:
    await wait_until(
        pilot, lambda: isinstance(app.screen, ChoiceScreen), 10, "the parameter chooser"
    )
    await pilot.pause()
    return app.screen.query_one(OptionList)


def rows(ol: OptionList) -> dict[str, str]:
    return {o.id: str(o.prompt) for o in ol.options}


def skill(app, sid: str = "lru1-2"):
    return app.model.find(sid)[2]


async def test_bind_asks_which_pose_parameter_and_binds_the_chosen_one():
    app, backend = engine_app(Builder(TRANSPORT))
    async with app.run_test(size=SIZE) as pilot:
        screen = await open_map(app, pilot, backend.b, "lru1-2")
        screen.select_marker("POI-A")
        await pilot.press("b")
        ol = await chooser(app, pilot)
        assert "Bind POI-A to which parameter of lru1-2?" in screen_text(app)
        # the poses first; via (a position) takes a pose marker's x, y, z as the
        # server does; relay (position markers only) and speed do not
        shown = rows(ol)
        assert list(shown) == ["from", "to", "via"]
        assert shown["from"].split() == ["from", "pose", "@POI-B"]
        assert shown["to"].split() == ["to", "pose", "(2,0)"]
        assert shown["via"].split() == ["via", "position", "not", "set"]
        assert ol.highlighted == 0
        await pilot.press("down", "enter")
        await wait_until(
            pilot, lambda: skill(app).bindings.get("to") == "POI-A", 10, "to bound to POI-A"
        )
        assert backend.ops == [EditSkill(id="lru1-2", bindings={"to": "POI-A"})]
        assert skill(app).bindings == {"from": "POI-B", "to": "POI-A"}
        assert skill(app).params["to"]["x"] == 42.0
        assert isinstance(app.screen, MapScreen)
        await wait_until(
            pilot,
            lambda: "lru1-2: to bound to marker POI-A" in screen.message,
            10,
            "the status line",
        )

        # POI-B already fills from: the list starts on to; escape sends nothing
        screen.select_marker("POI-B")
        await pilot.press("b")
        ol = await chooser(app, pilot)
        assert ol.highlighted == 1
        await pilot.press("escape")
        await wait_until(pilot, lambda: app.screen is screen, 10, "back on the map")
        await pilot.pause()
        assert len(backend.ops) == 1
        assert screen.message == "bind cancelled: lru1-2 unchanged"
        assert skill(app).bindings == {"from": "POI-B", "to": "POI-A"}


async def test_bind_a_position_marker_offers_its_kind_first_then_poses_and_marker_parameters():
    app, backend = engine_app(Builder(TRANSPORT))
    async with app.run_test(size=SIZE) as pilot:
        screen = await open_map(app, pilot, backend.b, "lru1-2")
        screen.select_marker("DEPOT")
        await pilot.press("b")
        ol = await chooser(app, pilot)
        shown = rows(ol)
        assert list(shown) == ["via", "from", "to", "relay"]
        assert shown["via"].split() == ["via", "position", "not", "set"]
        assert shown["relay"].split() == ["relay", "marker", "not", "set"]
        await pilot.press("down", "down", "down", "enter")  # relay takes the marker's name
        await wait_until(
            pilot, lambda: skill(app).params.get("relay") == "DEPOT", 10, "relay = DEPOT"
        )
        assert backend.ops == [EditSkill(id="lru1-2", params={"relay": "DEPOT"})]
        assert "via" not in skill(app).bindings


async def test_a_pose_marker_binds_a_position_parameter_like_the_server_allows():
    app, backend = engine_app(Builder(DATA / "transport.yaml"))
    async with app.run_test(size=SIZE) as pilot:
        screen = await open_map(app, pilot, backend.b, "lru1-2")
        screen.select_marker("POI-A")
        await pilot.press("b")
        await chooser(app, pilot)
        await pilot.press("down", "down", "enter")  # via
        await wait_until(
            pilot, lambda: skill(app).bindings.get("via") == "POI-A", 10, "via bound to POI-A"
        )
        assert backend.ops == [EditSkill(id="lru1-2", bindings={"via": "POI-A"})]
        assert skill(app).params["via"] == {"x": 42.0, "y": 18.0, "z": 0.0}  # the pose's position


async def test_one_fitting_parameter_binds_without_asking():
    app, backend = engine_app(Builder(TRANSPORT))
    async with app.run_test(size=SIZE) as pilot:
        screen = await open_map(app, pilot, backend.b, "lru1-1")  # drive_to: goal only
        screen.select_marker("POI-A")
        await pilot.press("b")
        await wait_until(
            pilot, lambda: skill(app, "lru1-1").bindings.get("goal") == "POI-A", 10, "goal bound"
        )
        # its label named the marker it was bound to: it names the new one
        assert backend.ops == [
            EditSkill(id="lru1-1", bindings={"goal": "POI-A"}, label="drive to POI-A")
        ]
        assert not any(isinstance(s, ChoiceScreen) for s in app.screen_stack)


async def test_pick_asks_which_parameter_and_sets_the_chosen_one_to_the_cursor():
    app, backend = engine_app(Builder(TRANSPORT))
    async with app.run_test(size=SIZE) as pilot:
        screen = await open_map(app, pilot, backend.b, "lru1-2")
        screen.view.set_cursor(12.0, -6.0)
        await pilot.press("right_square_bracket", "right_square_bracket")  # heading -30°
        await pilot.press("p")
        ol = await chooser(app, pilot)
        assert "Set which parameter of lru1-2 to the cursor (12, -6)?" in screen_text(app)
        assert list(rows(ol)) == ["from", "to", "via"]
        await pilot.press("down", "enter")
        await wait_until(pilot, lambda: skill(app).params["to"]["x"] == 12.0, 10, "to picked")
        to = skill(app).params["to"]
        assert to["y"] == -6.0 and math.isclose(
            to["yaw"], math.radians(-30) % (2 * math.pi), abs_tol=1e-3
        )
        assert skill(app).bindings == {"from": "POI-B"}  # from untouched
        assert [op.params for op in backend.ops] == [{"to": to}]
        await wait_until(
            pilot,
            lambda: "lru1-2: to = (12, -6) heading 330°" in screen.message,
            10,
            "the status line",
        )

        # a position parameter takes no heading
        await pilot.press("p")
        await chooser(app, pilot)
        await pilot.press("down", "down", "enter")
        await wait_until(pilot, lambda: "via" in skill(app).params, 10, "via picked")
        assert backend.ops[-1] == EditSkill(
            id="lru1-2", params={"via": {"x": 12.0, "y": -6.0, "z": 0.0}}
        )

        # escape: nothing sent
        await pilot.press("p")
        await chooser(app, pilot)
        await pilot.press("escape")
        await wait_until(pilot, lambda: app.screen is screen, 10, "back on the map")
        await pilot.pause()
        assert len(backend.ops) == 2 and screen.message == "pick cancelled: lru1-2 unchanged"


async def test_the_map_rules_come_before_the_chooser():
    b = Builder(TRANSPORT)
    b.sync("lru1", "lru1-2")  # synchronized: no longer editable
    app, backend = engine_app(b)
    async with app.run_test(size=SIZE) as pilot:
        screen = await open_map(app, pilot, b, "lru1-2")
        screen.select_marker("POI-A")
        for key in ("b", "p"):
            await pilot.press(key)
            await pilot.pause()
            assert app.screen is screen and screen.message.startswith("lru1-2: ")
            assert "only idle skills can be edited" in screen.message
        assert backend.ops == []


async def test_a_skill_that_became_read_only_while_choosing_gets_nothing():
    app, backend = engine_app(Builder(TRANSPORT))
    async with app.run_test(size=SIZE) as pilot:
        screen = await open_map(app, pilot, backend.b, "lru1-2")
        screen.select_marker("POI-A")
        await pilot.press("b")
        await chooser(app, pilot)
        app.post_message(account_known("read-only: logged in as observer watch"))
        await wait_until(pilot, lambda: app.model.read_only, 10, "the observer account")
        await pilot.press("enter")
        await wait_until(pilot, lambda: app.screen is screen, 10, "back on the map")
        await pilot.pause()
        assert backend.ops == []
        assert screen.message == "lru1-2: logged in as observer watch"
