"""The console's textual-free core: summaries, presence, why actions do not apply,
event application, config, default parameters of a new skill."""

from __future__ import annotations

from console_state import MARS_FLEET, T0, TUTORIAL, Builder, fleet, mars_mid_execution

from backend.core import events as ev
from backend.core.model import Policies, Status
from backend.core.ops import AddSkill
from console.config import load_config
from console.state.defaults import default_params
from console.state.model import CONNECTED, RECONNECTING, ConsoleModel
from console.state.text import fmt_duration, param_summary


def model_of(b: Builder, online=MARS_FLEET) -> ConsoleModel:
    m = ConsoleModel(connection=CONNECTED)
    m.load(b.snapshot(), b.library, fleet(online))
    return m


def test_param_summary_shows_bindings_and_non_defaults_only():
    b = Builder()
    lib = b.library
    assert param_summary(b.mission.find("lru1-1")[2], lib) == "goal@POI-A"
    assert param_summary(b.mission.find("lru1-2")[2], lib) == "area@ROI-east max_duration=240s"
    assert param_summary(b.mission.find("lander-1")[2], lib) == "box=wifi_box_1 slot=2"
    assert param_summary(b.mission.find("lru2-5")[2], lib) == "goal=(2,0)"
    s = b.mission.find("lru2-5")[2].model_copy(
        update={"policies": Policies(retries=2, pause_out_of_comms=True, recharge_below=0.2)}
    )
    assert param_summary(s, lib) == "goal=(2,0) retry×2 pause-out-of-comms recharge<20%"


def test_presence_and_durations():
    m = model_of(mars_mid_execution())
    assert m.presence_text("lru1") == "online"
    assert m.presence_text("ardea") == f"offline since {T0:%H:%M:%S}"
    assert (
        fmt_duration(132) == "2m12s" and fmt_duration(5) == "5s" and fmt_duration(7300) == "2h01m"
    )


def test_robot_order_puts_static_robots_last():
    assert model_of(Builder()).robot_order() == ["lru1", "lru2", "ardea", "lander"]


def test_why_not_names_robot_skill_and_reason():
    m = model_of(mars_mid_execution())
    assert m.why_not("delete", "lru1", "lru1-2") == (
        "lru1-2 is running on lru1: only idle skills can be deleted; "
        "stop the robot (the skill goes back to its queue), then unsynchronize it"
    )
    assert "succeeded on lru1: finished skills are the execution log" in m.why_not(
        "delete", "lru1", "lru1-1"
    )
    assert m.why_not("delete", "lru1", "lru1-4") is None
    assert m.why_not("move_up", "lru1", "lru1-4") == "lru1-4 is already first in lru1's plan"
    assert m.why_not("sync", "lru1", "lru1-3").startswith("lru1-3 is queued on lru1")
    assert m.why_not("sync", "ardea", "ardea-4").startswith("ardea-4 is queued")
    assert m.why_not("unsync", "lru1", "lru1-3") is None
    assert m.why_not("retry", "ardea", "ardea-2") == "ardea is executing ardea-3: stop it first"
    assert m.why_not("run", "lru1", None) == "lru1 is already executing lru1-2 (running)"
    assert m.why_not("pause", "lru1", None) is None
    # ardea is offline (paused): a run waits for it in its uplink, as the server queues it
    assert m.why_not("run", "ardea", None) is None
    assert m.why_not("run_all", None, None) is None  # ardea's run waits for it
    m.robots["ardea"] = m.robots["ardea"].model_copy(update={"online": True})
    m.mission.tasks["ardea"][2].status = Status.RUNNING  # ardea-3 resumed: none to run
    assert m.why_not("run_all", None, None).startswith(
        "run applies to no robot: lru1 is already executing lru1-2"
    )
    assert m.why_not("pause_all", None, None) is None  # lru1 runs
    assert m.why_not("barrier", None, None, ["lru1-4"]).startswith("mark one idle skill")
    assert (
        m.why_not("barrier", None, None, ["lru1-4", "lru1-5"])
        == "lru1-4 and lru1-5 both belong to lru1: a barrier takes one skill per robot"
    )
    assert m.why_not("barrier", None, None, ["lru1-4", "lru2-5"]) is None
    assert m.why_not("unbarrier", "lru1", "lru1-3").startswith("barrier b1: lru1-3 is queued")
    m.connection = RECONNECTING
    assert m.why_not("add", "lru1", "lru1-4").startswith(
        "not connected to the mission server (reconnecting)"
    )
    assert m.why_not("save", "lru1", None) is None


def test_read_only_reason_matches_the_brief():
    m = model_of(mars_mid_execution())
    assert m.read_only_reason("lru1-2") == (
        "lru1-2 is running on lru1: only idle skills can be edited; "
        "stop the robot (the skill goes back to its queue), then unsynchronize it"
    )
    assert m.read_only_reason("lru1-3").endswith(
        "lru1-3 is idle_synchronized on lru1: only idle skills can be edited; "
        "unsynchronize it first"
    )
    assert m.read_only_reason("lru1-4") is None


def test_apply_reports_changed_columns_and_keeps_indexes():
    b = Builder(TUTORIAL)
    m = model_of(b, {"lru1": True, "lru2": True})
    applied = b.engine.submit(AddSkill(robot="lru2", skill="recharge"))
    assert m.apply(applied.batch()) == {"lru2"}
    assert m.owner("lru2-3") == "lru2"
    assert m.apply(applied.batch()) == set()  # already applied
    batch = ev.EventBatch(
        revision=m.mission.revision + 1,
        events=[ev.SkillStatusChanged(id="lru1-1", status="idle_synchronized")],
    )
    assert m.apply(batch) == {"lru1"}
    assert m.find("lru1-1")[2].status == Status.IDLE_SYNCHRONIZED
    assert m.robot_state("lru1") == (None, 1)


def test_the_owner_index_follows_adds_moves_and_deletes_as_a_rebuild_would():
    from backend.core.ops import DeleteSkills, MoveSkill

    b = Builder(TUTORIAL)
    m = model_of(b, {"lru1": True, "lru2": True})
    ops = [
        AddSkill(robot="lru2", skill="recharge"),
        AddSkill(robot="lru1", skill="recharge", at=0),
        MoveSkill(id="lru1-1", index=2),
        DeleteSkills(ids=["lru2-1"]),
        AddSkill(robot="lru2", skill="recharge"),
    ]
    added = []
    for op in ops:
        applied = b.engine.submit(op)
        m.apply(applied.batch())
        added += [applied.value["id"]] if isinstance(op, AddSkill) else []
        kept = dict(m._owner)
        m.reindex()
        assert kept == m._owner, op
    assert m.owner("lru2-1") is None
    assert [m.owner(sid) for sid in added] == ["lru2", "lru1", "lru2"]


def test_default_params_make_a_valid_new_skill():
    from backend.core.library import check_params

    b = Builder()
    m = model_of(b)
    for robot in ("lru1", "lru2", "ardea", "lander"):
        rtype = b.mission.robots[robot].type
        for skill in b.library.skills_of(rtype):
            params, bindings = default_params(b.library.skills[skill].params, m, robot)
            _, problems = check_params(
                b.library,
                rtype,
                skill,
                params,
                bindings,
                markers=b.mission.markers,
                robots=set(b.mission.robots),
            )
            assert not problems, (robot, skill, problems)


def test_config_keymap_theme_and_problems(tmp_path):
    p = tmp_path / "config.toml"
    p.write_text(
        'theme = "textual-light"\nbogus = 1\n[keymap]\n"mission.sync" = "S"\n"mission.nope" = "x"\n'
    )
    cfg = load_config(p, known_ids={"mission.sync"})
    assert cfg.theme == "textual-light" and cfg.keymap == {"mission.sync": "S"}
    assert any("unknown binding id 'mission.nope'" in x for x in cfg.problems)
    assert any("unknown setting 'bogus'" in x for x in cfg.problems)
    y = tmp_path / "config.yaml"
    y.write_text("keymap:\n  mission.add: A\n")
    assert load_config(y).keymap == {"mission.add": "A"}
    broken = tmp_path / "broken.toml"
    broken.write_text("theme = ")
    assert "cannot read it" in load_config(broken).problems[0]


def test_a_barrier_skill_changing_also_changes_its_partners_columns():
    from backend.core.ops import Report

    b = mars_mid_execution()
    m = model_of(b)
    # lru2-3 waits at b1 for lru1; lru1 finishes its current skill, then reaches lru1-3 (b1)
    done = m.apply(
        b.engine.submit(Report(robot="lru1", seq=100, id="lru1-2", status="success")).batch()
    )
    assert done == {"lru1"}  # not a barrier skill: only its own column
    ready = m.apply(
        b.engine.submit(Report(robot="lru1", seq=101, id="lru1-3", status="synchwaiting")).batch()
    )
    assert ready == {"lru1", "lru2"}  # lru2's column says what it waits for: redrawn too
